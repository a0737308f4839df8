"""Reaction-wheel cluster: geometry, torque balance, friction, motor electrics and speed loop.

Geometry (seed 000 §2): the columns of A (3 × n_w) are the unit spin axes in body axes, so the
cluster momentum is H = A h with h = J_r Ω (Ω relative to the body). The General-Electric (GE)
scheme puts four wheels in the device frame as A^d (angle γ) and turns the device frame into the
body by A = [π/4]_1^t A^d; seed 000 writes [φ]_1 for the passive simple-turn matrix about x, so
[π/4]_1^t is the active rotation R_x(+π/4) of the columns.

Torque balance (seed 002 eq 1, 4): M_m = M_c + M_f + M_x + M_a + M_d. Seed 002 adds the friction
terms with a plus sign although they oppose the spin; we keep the physical sign and write every
resisting torque as a positive multiple of the spin direction that is *subtracted*:
M^f = m_f Sat(Ω/Ω°) + K_l Ω + K_a Ω √|Ω| (seed 000's saturated dry friction, seed 002's viscous
and aerodynamic terms, seed 003 eq 34's k_e Ω and M_df sgn Ω). Seed 000 eq (1) then reads
J_r (aᵗω̇ + Ω̇) = m − m^f. Noise M_x and imbalance M_d are added to the delivered motor torque; the
imbalance turns with the rotor angle φ = ∫Ω dt (seed 002's sin(Ωt) holds only at a constant speed).

Motor electrics (seed 002 eq 2–3): L di/dt + R i + K_e Ω = u, M = K_m i.
Speed integration (seed 002 eq 5, Ω = J_c⁻¹∫M dt) is row 3 of seed 000 eq (1) in ``spacecraft``.
Speed loop (seed 003 eq 35–37): M_w = −k_w(Ω − Ω_0) − k_T T_c with k_w = k_Ω + k_e, first order
with time constant T_w = J_r / k_w. T_c is the torque requested *on the body*, which the wheel
delivers by the opposite motor torque, hence −k_T T_c as in eq (35); seed 003's eq (36)–(37) carry
+T_c, a sign slip we do not copy. k_w already contains the motor's back-EMF damping k_e, so a wheel
run by the speed loop should not also get k_e as ``viscous_nm_s``.

Limits (seed 000 eq 2): |m_p| ≤ m^m and |h_p| ≤ h^m; a wheel at its momentum limit accepts no
torque that would drive it further.

Units: SI (N·m, N·m·s, rad/s, kg·m², A, V, Ω, H). All ``*_1`` functions are numba kernels on
per-wheel float64 arrays for the simulation loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from numba import njit
from numpy.typing import ArrayLike

__all__ = [
    "WheelParams",
    "MotorParams",
    "ge_device_axes",
    "ge_scheme_axes",
    "orthogonal_axes",
    "skew_3plus1_axes",
    "ge_normalized_momentum",
    "friction_torque",
    "friction_torque_1",
    "friction_torque_one_wheel",
    "friction_torque_terms",
    "limited_motor_torque",
    "limited_motor_torque_1",
    "limit_motor_torque_into",
    "imbalance_torque",
    "noise_torque",
    "delivered_torque_1",
    "advance_rotor_phase_1",
    "motor_current_derivative",
    "motor_current_derivative_1",
    "motor_current_step",
    "motor_current_step_1",
    "driven_motor_torque_1",
    "motor_torque",
    "speed_loop_torque",
    "speed_loop_torque_1",
]


def _per_wheel(value: ArrayLike, n: int, name: str, lower: float, strict: bool, allow_inf: bool) -> np.ndarray:
    """Broadcast a scalar or per-wheel array to shape (n,) and check its range, naming the field."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected a scalar or shape ({n},), got {arr.shape}")
    if np.any(np.isnan(arr)) or (not allow_inf and not np.all(np.isfinite(arr))):
        raise ValueError(f"{name}: contains NaN or infinite values")
    bad = arr <= lower if strict else arr < lower
    if np.any(bad):
        relation = ">" if strict else "≥"
        raise ValueError(f"{name}: every value must be {relation} {lower}, got {arr}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class WheelParams:
    """Per-wheel parameters of the cluster (seed 000 eq 1–2, seed 002 eq 1–4); scalars broadcast."""

    inertia_kg_m2: np.ndarray
    max_torque_nm: np.ndarray | float = np.inf
    max_momentum_nms: np.ndarray | float = np.inf
    coulomb_nm: np.ndarray | float = 0.0
    coulomb_sat_speed_rad_s: np.ndarray | float = 0.0
    viscous_nm_s: np.ndarray | float = 0.0
    aero_drag_nm_s15: np.ndarray | float = 0.0
    noise_nm: np.ndarray | float = 0.0
    imbalance_nm_s2: np.ndarray | float = 0.0
    n: int = field(init=False)

    def __post_init__(self) -> None:
        j = np.atleast_1d(np.asarray(self.inertia_kg_m2, dtype=float))
        if j.ndim != 1:
            raise ValueError(f"inertia_kg_m2: expected shape (n_wheels,), got {j.shape}")
        n = j.shape[0]
        object.__setattr__(self, "n", n)
        checks = {
            "inertia_kg_m2": (0.0, True, False),
            "max_torque_nm": (0.0, True, True),
            "max_momentum_nms": (0.0, True, True),
            "coulomb_nm": (0.0, False, False),
            "coulomb_sat_speed_rad_s": (0.0, False, False),
            "viscous_nm_s": (0.0, False, False),
            "aero_drag_nm_s15": (0.0, False, False),
            "noise_nm": (0.0, False, False),
            "imbalance_nm_s2": (0.0, False, False),
        }
        for name, (lower, strict, allow_inf) in checks.items():
            value = j if name == "inertia_kg_m2" else getattr(self, name)
            object.__setattr__(self, name, _per_wheel(value, n, name, lower, strict, allow_inf))

    @property
    def max_speed_rad_s(self) -> np.ndarray:
        """Relative speed limit Ω^m = h^m / J_r of each wheel (seed 000 eq 2)."""
        return self.max_momentum_nms / self.inertia_kg_m2

    def friction_table(self) -> np.ndarray:
        """Friction coefficients packed for kernels: rows m_f, Ω°, K_l, K_a; shape (4, n)."""
        return np.ascontiguousarray(
            np.stack([self.coulomb_nm, self.coulomb_sat_speed_rad_s, self.viscous_nm_s, self.aero_drag_nm_s15])
        )


@dataclass(frozen=True)
class MotorParams:
    """Armature of a voltage-driven wheel motor (seed 002 eq 2): L, R, torque and back-EMF constants."""

    inductance_h: float
    resistance_ohm: float
    torque_constant_nm_a: float
    back_emf_v_s: float

    def __post_init__(self) -> None:
        for name in ("inductance_h", "resistance_ohm", "torque_constant_nm_a", "back_emf_v_s"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name}: must be a finite positive number, got {value}")
            object.__setattr__(self, name, value)


# --- geometry -------------------------------------------------------------------------------


def _check_angle(gamma_rad: float) -> float:
    gamma = float(gamma_rad)
    if not np.isfinite(gamma) or not 0.0 < gamma < 0.5 * np.pi:
        raise ValueError(f"gamma_rad: must lie in (0, π/2), got {gamma_rad}")
    return gamma


def ge_device_axes(gamma_rad: float) -> np.ndarray:
    """GE-scheme matrix A^d (3 × 4) in the cluster device frame (seed 000 eq 1)."""
    g = _check_angle(gamma_rad)
    c, s = np.cos(g), np.sin(g)
    return np.array([[c, c, c, c], [s, -s, 0.0, 0.0], [0.0, 0.0, s, -s]])


def ge_scheme_axes(gamma_rad: float) -> np.ndarray:
    """Body-frame wheel axes A = [π/4]_1^t A^d of the GE scheme (seed 000 eq 1), shape (3, 4)."""
    c, s = np.cos(0.25 * np.pi), np.sin(0.25 * np.pi)
    turn_t = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])  # [π/4]_1 is passive: transpose is R_x(+π/4)
    axes_b: npt.NDArray[np.float64] = turn_t @ ge_device_axes(gamma_rad)
    return axes_b


def orthogonal_axes() -> np.ndarray:
    """Three wheels along body x, y, z (seed 003 Fig. 24), shape (3, 3)."""
    return np.eye(3)


def skew_3plus1_axes() -> np.ndarray:
    """Three orthogonal wheels plus a fourth skewed along (1, 1, 1)/√3 (seed 003 §3.2.2.3), shape (3, 4)."""
    return np.column_stack([np.eye(3), np.full(3, 1.0 / np.sqrt(3.0))])


def ge_normalized_momentum(h_nms: ArrayLike, max_momentum_nms: float, gamma_rad: float) -> np.ndarray:
    """Normalised GE cluster momentum {x, y, z} = A^d h / h^m written out as seed 000 eq (4)."""
    h = np.asarray(h_nms, dtype=float)
    if h.shape[-1:] != (4,) or not np.all(np.isfinite(h)):
        raise ValueError(f"h_nms: expected finite shape (..., 4), got {h.shape}")
    if not np.isfinite(max_momentum_nms) or max_momentum_nms <= 0.0:
        raise ValueError(f"max_momentum_nms: must be finite and positive, got {max_momentum_nms}")
    g = _check_angle(gamma_rad)
    hn = h / max_momentum_nms
    x1 = np.cos(g) * (hn[..., 0] + hn[..., 1])
    x2 = np.cos(g) * (hn[..., 2] + hn[..., 3])
    y = np.sin(g) * (hn[..., 0] - hn[..., 1])
    z = np.sin(g) * (hn[..., 2] - hn[..., 3])
    return np.stack([x1 + x2, y, z], axis=-1)


# --- kernels ---------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def friction_torque_terms(speed_rad_s: float, m_f: float, sat_speed: float, k_l: float, k_a: float) -> float:
    """Resisting torque m_f Sat(Ω/Ω°) + K_l Ω + K_a Ω√|Ω| of one wheel from its coefficients (seed 000 eq 1,
    seed 002 eq 4). Scalars only: a kernel handed an array is reference-counted at each call, and inside the
    RK4 derivative those counts (atomic, not pruned across its branches) cost the step 4x its arithmetic."""
    w = speed_rad_s
    dry = min(1.0, max(-1.0, w / sat_speed)) if sat_speed > 0.0 else 1.0 if w > 0.0 else -1.0 if w < 0.0 else 0.0
    torque = m_f * dry + k_l * w
    if k_a != 0.0:  # aerodynamic drag off costs no square root (adding its ±0 changes no bit)
        torque += k_a * w * np.sqrt(abs(w))
    return float(torque)


@njit(cache=True)
def friction_torque_one_wheel(speed_rad_s: float, friction: np.ndarray, p: int) -> float:
    """Resisting torque of wheel p (:func:`friction_torque_terms` on column p of the rows m_f, Ω°, K_l, K_a)."""
    return friction_torque_terms(speed_rad_s, friction[0, p], friction[1, p], friction[2, p], friction[3, p])


@njit(cache=True)
def friction_torque_1(speed_rad_s: np.ndarray, friction: np.ndarray) -> np.ndarray:
    """Resisting friction torque of every wheel (seed 000 eq 1 m^f, seed 002 eq 4), compiled kernel."""
    n = speed_rad_s.shape[0]
    out = np.empty(n)
    for p in range(n):
        out[p] = friction_torque_one_wheel(speed_rad_s[p], friction, p)
    return out


@njit(cache=True)
def limited_motor_torque_1(
    torque_cmd_nm: np.ndarray,
    speed_rad_s: np.ndarray,
    inertia_kg_m2: np.ndarray,
    max_torque_nm: np.ndarray,
    max_momentum_nms: np.ndarray,
) -> np.ndarray:
    """Motor torque within |m_p| ≤ m^m, none beyond |h_p| ≤ h^m (seed 000 eq 2), per wheel."""
    out = torque_cmd_nm.copy()
    limit_motor_torque_into(out, speed_rad_s, inertia_kg_m2, max_torque_nm, max_momentum_nms)
    return out


@njit(cache=True)
def limit_motor_torque_into(
    torque_nm: np.ndarray,
    speed_rad_s: np.ndarray,
    inertia_kg_m2: np.ndarray,
    max_torque_nm: np.ndarray,
    max_momentum_nms: np.ndarray,
) -> None:
    """Seed 000 eq (2) applied in place: |m_p| ≤ m^m, and no torque driving |h_p| beyond h^m."""
    for p in range(torque_nm.shape[0]):
        m = min(max_torque_nm[p], max(-max_torque_nm[p], torque_nm[p]))
        h = inertia_kg_m2[p] * speed_rad_s[p]
        if (h >= max_momentum_nms[p] and m > 0.0) or (h <= -max_momentum_nms[p] and m < 0.0):
            m = 0.0
        torque_nm[p] = m


@njit(cache=True)
def delivered_torque_1(
    motor_torque_nm: np.ndarray,
    speed_rad_s: np.ndarray,
    phase_rad: np.ndarray,
    noise_nm: np.ndarray,
    imbalance_nm_s2: np.ndarray,
    white_noise: np.ndarray,
) -> np.ndarray:
    """Motor torque plus noise K_x W/|W_max| and imbalance K_d Ω² sin φ, φ = ∫Ω dt (seed 002 eq 1, 4).

    ``white_noise`` holds samples W/|W_max| in [−1, 1] drawn by the caller (one per wheel); ``phase_rad`` the
    rotor angles φ_p carried by :func:`advance_rotor_phase_1`.
    """
    n = motor_torque_nm.shape[0]
    out = np.empty(n)
    for p in range(n):
        w = speed_rad_s[p]
        out[p] = motor_torque_nm[p] + noise_nm[p] * white_noise[p] + imbalance_nm_s2[p] * w * w * np.sin(phase_rad[p])
    return out


@njit(cache=True)
def advance_rotor_phase_1(phase_rad: np.ndarray, speed_rad_s: np.ndarray, dt_s: float) -> None:
    """Rotor angle φ_p += Ω_p dt in place, wrapped to [0, 2π): the phase of seed 002 eq 4's imbalance.

    Seed 002 writes sin(Ωt), whose frequency d(Ωt)/dt = Ω + Ω̇ t chirps when the speed changes; the rotor
    angle φ = ∫Ω dt turns at Ω at every instant (and equals Ωt at a constant speed from φ(0) = 0).
    """
    for p in range(phase_rad.shape[0]):
        phase_rad[p] = (phase_rad[p] + speed_rad_s[p] * dt_s) % (2.0 * np.pi)


@njit(cache=True)
def motor_current_derivative_1(
    current_a: np.ndarray,
    voltage_v: np.ndarray,
    speed_rad_s: np.ndarray,
    inductance_h: float,
    resistance_ohm: float,
    back_emf_v_s: float,
) -> np.ndarray:
    """Armature di/dt = (u − R i − K_e Ω) / L per wheel (seed 002 eq 2)."""
    return (voltage_v - resistance_ohm * current_a - back_emf_v_s * speed_rad_s) / inductance_h


@njit(cache=True)
def motor_current_step_1(
    current_a: np.ndarray,
    voltage_v: np.ndarray,
    speed_rad_s: np.ndarray,
    dt: float,
    inductance_h: float,
    resistance_ohm: float,
    back_emf_v_s: float,
) -> np.ndarray:
    """Exact armature current after dt with u and Ω held: i_∞ + (i − i_∞) e^{−R dt/L} (seed 002 eq 2–3).

    The electrical time constant L/R (≈ ms) is far below the 0.1 s plant step, so the current is
    advanced by this zero-order-hold solution instead of an explicit integrator (stable for any dt).
    """
    decay = np.exp(-resistance_ohm * dt / inductance_h)
    i_inf = (voltage_v - back_emf_v_s * speed_rad_s) / resistance_ohm
    current_next_a: npt.NDArray[np.float64] = i_inf + (current_a - i_inf) * decay
    return current_next_a


@njit(cache=True)
def driven_motor_torque_1(
    current_a: np.ndarray,
    torque_cmd_nm: np.ndarray,
    speed_rad_s: np.ndarray,
    dt: float,
    inductance_h: float,
    resistance_ohm: float,
    torque_constant_nm_a: float,
    back_emf_v_s: float,
    max_voltage_v: float,
) -> np.ndarray:
    """Motor torque K_m i after dt of a voltage-limited driver (seed 002 eq 2–3); advances ``current_a`` in place.

    The driver feeds forward the current the command needs and the back-EMF, u = R M_c/K_m + K_e Ω, clipped to
    ±max_voltage_v; so the motor delivers M_c while |u| fits, and at most K_m (V_max − K_e Ω)/R (for Ω > 0) when
    the back-EMF eats the supply."""
    n = torque_cmd_nm.shape[0]
    voltage = np.empty(n)
    for p in range(n):
        u = resistance_ohm * torque_cmd_nm[p] / torque_constant_nm_a + back_emf_v_s * speed_rad_s[p]
        voltage[p] = min(max(u, -max_voltage_v), max_voltage_v)
    current_a[:] = motor_current_step_1(current_a, voltage, speed_rad_s, dt, inductance_h, resistance_ohm, back_emf_v_s)
    out: np.ndarray = torque_constant_nm_a * current_a
    return out


@njit(cache=True)
def speed_loop_torque_1(
    speed_rad_s: np.ndarray,
    speed_set_rad_s: np.ndarray,
    torque_request_nm: np.ndarray,
    loop_gain_nm_s: np.ndarray,
    torque_gain: np.ndarray,
) -> np.ndarray:
    """Speed-loop motor torque −(k_Ω + k_e)(Ω − Ω_0) − k_T T_c (seed 003 eq 35), per wheel.

    Seed 003 writes the request with the body-reaction sign (a positive T_c is a torque on the
    body); the wheel motor torque is its opposite, hence the minus sign.
    """
    motor_torque_nm: npt.NDArray[np.float64] = (
        -loop_gain_nm_s * (speed_rad_s - speed_set_rad_s) - torque_gain * torque_request_nm
    )
    return motor_torque_nm


# --- friendly numpy API (tests, tools) ----------------------------------------------------------


def _speeds(speed_rad_s: ArrayLike, n: int, name: str = "speed_rad_s") -> np.ndarray:
    w = np.ascontiguousarray(np.atleast_1d(np.asarray(speed_rad_s, dtype=float)))
    if w.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return w


def friction_torque(wheels: WheelParams, speed_rad_s: ArrayLike) -> np.ndarray:
    """Resisting friction torque per wheel, N·m (seed 000 eq 1 m^f, seed 002 eq 4 M_f + M_a)."""
    return friction_torque_1(_speeds(speed_rad_s, wheels.n), wheels.friction_table())


def imbalance_torque(wheels: WheelParams, speed_rad_s: ArrayLike, phase_rad: ArrayLike) -> np.ndarray:
    """Dynamic-imbalance torque K_d Ω² sin φ per wheel at rotor angles φ = ∫Ω dt, N·m (seed 002 eq 4 M_d)."""
    w = _speeds(speed_rad_s, wheels.n)
    phase = _speeds(phase_rad, wheels.n, "phase_rad")
    torque_nm: npt.NDArray[np.float64] = wheels.imbalance_nm_s2 * w * w * np.sin(phase)
    return torque_nm


def noise_torque(wheels: WheelParams, rng: np.random.Generator) -> np.ndarray:
    """Noise torque K_x W/|W_max| with W uniform in [−1, 1] per wheel, N·m (seed 002 eq 4 M_x)."""
    return wheels.noise_nm * rng.uniform(-1.0, 1.0, wheels.n)


def limited_motor_torque(wheels: WheelParams, torque_cmd_nm: ArrayLike, speed_rad_s: ArrayLike) -> np.ndarray:
    """Commanded motor torque clipped to m^m and cut at the momentum limit h^m (seed 000 eq 2)."""
    m = _speeds(torque_cmd_nm, wheels.n, "torque_cmd_nm")
    w = _speeds(speed_rad_s, wheels.n)
    limits = np.asarray(wheels.max_torque_nm), np.asarray(wheels.max_momentum_nms)  # (n,) after __post_init__
    return limited_motor_torque_1(m, w, wheels.inertia_kg_m2, *limits)


def _finite_arrays(**named: ArrayLike) -> list[np.ndarray]:
    """1-D float arrays of the named inputs, each checked finite (ValueError names the field)."""
    out = []
    for name, value in named.items():
        arr = np.ascontiguousarray(np.atleast_1d(np.asarray(value, dtype=float)))
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name}: contains NaN or infinite values")
        out.append(arr)
    return out


def motor_current_derivative(
    motor: MotorParams, current_a: ArrayLike, voltage_v: ArrayLike, speed_rad_s: ArrayLike
) -> np.ndarray:
    """Armature current rate di/dt = (u − R i − K_e Ω)/L, A/s (seed 002 eq 2)."""
    i, u, w = _finite_arrays(current_a=current_a, voltage_v=voltage_v, speed_rad_s=speed_rad_s)
    return motor_current_derivative_1(i, u, w, motor.inductance_h, motor.resistance_ohm, motor.back_emf_v_s)


def motor_current_step(
    motor: MotorParams, current_a: ArrayLike, voltage_v: ArrayLike, speed_rad_s: ArrayLike, dt_s: float
) -> np.ndarray:
    """Armature current after dt_s with voltage and speed held, A (seed 002 eq 2–3, exact ZOH)."""
    i, u, w = _finite_arrays(current_a=current_a, voltage_v=voltage_v, speed_rad_s=speed_rad_s)
    if not np.isfinite(dt_s) or dt_s < 0.0:
        raise ValueError(f"dt_s: must be finite and non-negative, got {dt_s}")
    return motor_current_step_1(i, u, w, float(dt_s), motor.inductance_h, motor.resistance_ohm, motor.back_emf_v_s)


def motor_torque(motor: MotorParams, current_a: ArrayLike) -> np.ndarray:
    """Motor torque M = K_m i, N·m (seed 002 eq 2)."""
    return motor.torque_constant_nm_a * _finite_arrays(current_a=current_a)[0]


def speed_loop_torque(
    speed_rad_s: ArrayLike,
    speed_set_rad_s: ArrayLike,
    torque_request_nm: ArrayLike,
    loop_gain_nm_s: ArrayLike,
    torque_gain: ArrayLike = 1.0,
) -> np.ndarray:
    """Speed-loop motor torque −k_w(Ω − Ω_0) − k_T T_c, N·m (seed 003 eq 35, k_w = k_Ω + k_e)."""
    arrays = _finite_arrays(
        speed_rad_s=speed_rad_s, speed_set_rad_s=speed_set_rad_s, torque_request_nm=torque_request_nm
    )
    n = arrays[0].shape[0]
    for name, a in zip(("speed_set_rad_s", "torque_request_nm"), arrays[1:]):
        if a.shape != (n,):
            raise ValueError(f"{name}: expected shape ({n},), got {a.shape}")
    gain = _per_wheel(loop_gain_nm_s, n, "loop_gain_nm_s", 0.0, True, False)
    k_t = _per_wheel(torque_gain, n, "torque_gain", 0.0, False, False)
    return speed_loop_torque_1(arrays[0], arrays[1], arrays[2], gain, k_t)
