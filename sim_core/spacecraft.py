"""Coupled rigid–flexible–wheel spacecraft plant of seed 000 eq (1).

    Λ̇ = ½ Λ ∘ ω;   A^o {ω̇, q̈, Ω̇} = {F^ω, F^q, F^r}
    A^o = [[J, D_q, D_r], [D_qᵗ, A^q, 0], [D_rᵗ, 0, A^r]],  D_r = A diag(J_r),  A^r = diag(J_r)
    F^ω = −ω × G + M^o,  G = J ω + A h + D_q q̇,  h = J_r Ω
    F^q_j = −a^q_j (δ^q_j/π Ω^q_j q̇_j + (Ω^q_j)² q_j),   F^r = M − M^f(Ω)

J is the inertia of the whole spacecraft with the wheels locked (it contains the wheels' axial
inertia), Ω the wheel speeds relative to the body, so the wheel's absolute spin momentum is
J_r (a_pᵗ ω + Ω_p). δ^q is the logarithmic decrement of a mode (damping ratio δ/(2π)). M is the
motor torque delivered to each wheel, M^f the bearing/drag friction (see ``wheels``), M^o the
external torque in body axes (magnetic driver, gravity gradient, disturbances).

State layout (float64, the engine relies on it), n_q flex modes, n_w wheels:

    x = [Λ(4) q_ib scalar first | ω(3) rad/s body | q(n_q) | q̇(n_q) | Ω(n_w) rad/s]

A^o is constant, so ``PlantParams.pack`` inverts it once; each derivative is one small
mat-vec. Kernels take the packed ``PlantArrays`` named tuple.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from numba import njit
from numpy.typing import ArrayLike

from sim_core.quaternion import rotate_1
from sim_core.wheels import WheelParams, friction_torque_terms

__all__ = [
    "PlantParams",
    "PlantArrays",
    "state_size",
    "pack_state",
    "plant_derivative",
    "plant_derivative_1",
    "plant_derivative_into",
    "free_wheel_inertia_1",
    "angular_momentum_b",
    "angular_momentum_b_1",
    "angular_momentum_i",
    "wheel_momentum",
    "kinetic_energy",
    "kinetic_energy_1",
    "mechanical_energy",
    "mechanical_energy_1",
]

SYMMETRY_RTOL = 1e-9  # inertia matrices come from CAD/measurement: asymmetry above this is a typo


class PlantArrays(NamedTuple):
    """PlantParams packed into plain float64 arrays for the numba kernels."""

    inertia: np.ndarray  # J (3, 3)
    mass_inv: np.ndarray  # (A^o)^-1 (3+nq+nw, 3+nq+nw)
    wheel_axes: np.ndarray  # A (3, nw)
    wheel_inertia: np.ndarray  # J_r (nw,)
    friction: np.ndarray  # rows m_f, Ω°, K_l, K_a (4, nw)
    flex_coupling: np.ndarray  # D_q (3, nq)
    flex_mass: np.ndarray  # a^q (nq,)
    flex_freq: np.ndarray  # Ω^q (nq,)
    flex_decrement: np.ndarray  # δ^q (nq,)


def _finite(value: ArrayLike, name: str, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return np.ascontiguousarray(arr)


def _check_inertia(j: np.ndarray) -> None:
    scale = np.max(np.abs(j))
    if not np.allclose(j, j.T, rtol=0.0, atol=SYMMETRY_RTOL * scale):
        raise ValueError("inertia_kg_m2: matrix is not symmetric")
    moments = np.linalg.eigvalsh(j)
    if moments[0] <= 0.0:
        raise ValueError(f"inertia_kg_m2: not positive definite (principal moments {moments})")
    if moments[0] + moments[1] < moments[2] * (1.0 - SYMMETRY_RTOL):
        raise ValueError(f"inertia_kg_m2: principal moments {moments} violate the triangle inequality")


@dataclass(frozen=True)
class PlantParams:
    """Mass properties of seed 000 eq (1): inertia J, wheel axes A and wheels, flexible modes."""

    inertia_kg_m2: np.ndarray
    wheel_axes_b: np.ndarray
    wheels: WheelParams
    flex_coupling: np.ndarray | None = None
    flex_modal_mass: np.ndarray | None = None
    flex_freq_rad_s: np.ndarray | None = None
    flex_log_decrement: np.ndarray | None = None

    def __post_init__(self) -> None:
        j = _finite(self.inertia_kg_m2, "inertia_kg_m2", (3, 3))
        _check_inertia(j)
        if not isinstance(self.wheels, WheelParams):
            raise ValueError(f"wheels: expected WheelParams, got {type(self.wheels).__name__}")
        nw = self.wheels.n
        axes = _finite(self.wheel_axes_b, "wheel_axes_b", (3, nw))
        if nw and not np.allclose(np.linalg.norm(axes, axis=0), 1.0, atol=1e-12):
            raise ValueError("wheel_axes_b: every column must be a unit vector")
        object.__setattr__(self, "inertia_kg_m2", j)
        object.__setattr__(self, "wheel_axes_b", axes)
        self._set_flex_modes()
        if np.linalg.eigvalsh(self.mass_matrix())[0] <= 0.0:
            raise ValueError("inertia_kg_m2: mass matrix A^o not positive definite (wheel or flex coupling too large)")

    def _set_flex_modes(self) -> None:
        coupling = np.zeros((3, 0)) if self.flex_coupling is None else np.asarray(self.flex_coupling, float)
        if coupling.ndim != 2:
            raise ValueError(f"flex_coupling: expected shape (3, n_modes), got {coupling.shape}")
        nq = coupling.shape[1]
        object.__setattr__(self, "flex_coupling", _finite(coupling, "flex_coupling", (3, nq)))
        for name in ("flex_modal_mass", "flex_freq_rad_s", "flex_log_decrement"):
            value = getattr(self, name)
            if value is None and nq and name != "flex_log_decrement":
                raise ValueError(f"{name}: required for the {nq} flexible modes of flex_coupling")
            arr = _finite(np.zeros(nq) if value is None else value, name, (nq,))
            if np.any(arr < 0.0) or (name != "flex_log_decrement" and np.any(arr == 0.0)):
                raise ValueError(f"{name}: must be positive (log decrement: non-negative), got {arr}")
            object.__setattr__(self, name, arr)

    def _flex_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Flex coupling (3, n_q), modal masses, frequencies, log decrements (n_q,): arrays once __post_init__ ran."""
        c, m, f, d = self.flex_coupling, self.flex_modal_mass, self.flex_freq_rad_s, self.flex_log_decrement
        if c is None or m is None or f is None or d is None:
            raise RuntimeError("flex arrays unset: PlantParams.__post_init__ fills every one of them")
        return c, m, f, d

    @property
    def n_modes(self) -> int:
        """Number of flexible modes n_q."""
        return int(self._flex_arrays()[0].shape[1])

    @property
    def n_wheels(self) -> int:
        """Number of wheels n_w."""
        return self.wheels.n

    def mass_matrix(self) -> np.ndarray:
        """Constant mass matrix A^o of seed 000 eq (1), shape (3+n_q+n_w)²."""
        nq, nw = self.n_modes, self.n_wheels
        jr = self.wheels.inertia_kg_m2
        d_r = self.wheel_axes_b * jr
        coupling, modal_mass, _, _ = self._flex_arrays()
        m = np.zeros((3 + nq + nw, 3 + nq + nw))
        m[:3, :3] = self.inertia_kg_m2
        m[:3, 3 : 3 + nq] = coupling
        m[3 : 3 + nq, :3] = coupling.T
        m[:3, 3 + nq :] = d_r
        m[3 + nq :, :3] = d_r.T
        m[3 : 3 + nq, 3 : 3 + nq] = np.diag(modal_mass)
        m[3 + nq :, 3 + nq :] = np.diag(jr)
        return m

    def pack(self) -> PlantArrays:
        """Plain float64 arrays for the kernels, with (A^o)^-1 computed once."""
        coupling, modal_mass, freq, decrement = self._flex_arrays()
        return PlantArrays(
            inertia=self.inertia_kg_m2.copy(),
            mass_inv=np.ascontiguousarray(np.linalg.inv(self.mass_matrix())),
            wheel_axes=self.wheel_axes_b.copy(),
            wheel_inertia=self.wheels.inertia_kg_m2.copy(),
            friction=self.wheels.friction_table(),
            flex_coupling=coupling.copy(),
            flex_mass=modal_mass.copy(),
            flex_freq=freq.copy(),
            flex_decrement=decrement.copy(),
        )


def state_size(n_modes: int, n_wheels: int) -> int:
    """Length 7 + 2 n_q + n_w of the plant state x."""
    return 7 + 2 * n_modes + n_wheels


def pack_state(
    params: PlantParams,
    q_ib: ArrayLike,
    omega_b_rad_s: ArrayLike,
    wheel_speed_rad_s: ArrayLike | None = None,
    flex_q: ArrayLike | None = None,
    flex_qdot: ArrayLike | None = None,
) -> np.ndarray:
    """State x = [Λ, ω, q, q̇, Ω] from its parts, validated (layout of seed 000 eq 1)."""
    nq, nw = params.n_modes, params.n_wheels
    q = _finite(q_ib, "q_ib", (4,))
    if abs(np.linalg.norm(q) - 1.0) > 1e-9:
        raise ValueError(f"q_ib: not a unit quaternion (norm {np.linalg.norm(q)})")
    parts = [
        q,
        _finite(omega_b_rad_s, "omega_b_rad_s", (3,)),
        _finite(np.zeros(nq) if flex_q is None else flex_q, "flex_q", (nq,)),
        _finite(np.zeros(nq) if flex_qdot is None else flex_qdot, "flex_qdot", (nq,)),
        _finite(np.zeros(nw) if wheel_speed_rad_s is None else wheel_speed_rad_s, "wheel_speed_rad_s", (nw,)),
    ]
    return np.concatenate(parts)


# --- kernels ---------------------------------------------------------------------------------


@njit(cache=True)
def angular_momentum_b_1(x: np.ndarray, p: PlantArrays) -> np.ndarray:
    """Total angular momentum G = Jω + A J_r Ω + D_q q̇ in body axes, N·m·s (seed 000 eq 1)."""
    nq = p.flex_mass.shape[0]
    nw = p.wheel_inertia.shape[0]
    g = np.zeros(3)
    for i in range(3):
        acc = 0.0
        for k in range(3):
            acc += p.inertia[i, k] * x[4 + k]
        for j in range(nq):
            acc += p.flex_coupling[i, j] * x[7 + nq + j]
        for w in range(nw):
            acc += p.wheel_axes[i, w] * p.wheel_inertia[w] * x[7 + 2 * nq + w]
        g[i] = acc
    return g


@njit(cache=True)
def free_wheel_inertia_1(p: PlantArrays) -> np.ndarray:
    """Body inertia with the wheels free to spin, J − Σ_p J_r,p a_p a_pᵗ (seed 000 eq 1, row 1 with Ω̇ eliminated)."""
    j_eff = p.inertia.copy()
    for w in range(p.wheel_inertia.shape[0]):
        for i in range(3):
            for c in range(3):
                j_eff[i, c] -= p.wheel_axes[i, w] * p.wheel_inertia[w] * p.wheel_axes[c, w]
    return j_eff


@njit(cache=True, inline="always")
def plant_derivative_into(
    x: np.ndarray,
    wheel_motor_torque: np.ndarray,
    ext_torque_b: np.ndarray,
    p: PlantArrays,
    force: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write ẋ of seed 000 eq (1) into ``out`` using scratch ``force`` (3+n_q+n_w); no allocation.

    Inlined into its callers (RK4 calls it four times a step): a call would reference-count the 14 arrays it
    is handed each time, which cost the flight loop ≈ 370 ns per step, more than the derivative itself."""
    nq = p.flex_mass.shape[0]
    nw = p.wheel_inertia.shape[0]
    n = 3 + nq + nw
    wx, wy, wz = x[4], x[5], x[6]
    g0 = p.inertia[0, 0] * wx + p.inertia[0, 1] * wy + p.inertia[0, 2] * wz
    g1 = p.inertia[1, 0] * wx + p.inertia[1, 1] * wy + p.inertia[1, 2] * wz
    g2 = p.inertia[2, 0] * wx + p.inertia[2, 1] * wy + p.inertia[2, 2] * wz
    for j in range(nq):
        qd = x[7 + nq + j]
        g0 += p.flex_coupling[0, j] * qd
        g1 += p.flex_coupling[1, j] * qd
        g2 += p.flex_coupling[2, j] * qd
        om = p.flex_freq[j]
        force[3 + j] = -p.flex_mass[j] * (p.flex_decrement[j] / np.pi * om * qd + om * om * x[7 + j])
        out[7 + j] = qd
    for w in range(nw):
        speed = x[7 + 2 * nq + w]
        h = p.wheel_inertia[w] * speed
        g0 += p.wheel_axes[0, w] * h
        g1 += p.wheel_axes[1, w] * h
        g2 += p.wheel_axes[2, w] * h
        fr = friction_torque_terms(  # by element: no array reaches the kernel (see friction_torque_terms)
            speed, p.friction[0, w], p.friction[1, w], p.friction[2, w], p.friction[3, w]
        )
        force[3 + nq + w] = wheel_motor_torque[w] - fr
    force[0] = wz * g1 - wy * g2 + ext_torque_b[0]
    force[1] = wx * g2 - wz * g0 + ext_torque_b[1]
    force[2] = wy * g0 - wx * g1 + ext_torque_b[2]
    q0, q1, q2, q3 = x[0], x[1], x[2], x[3]
    out[0] = 0.5 * (-q1 * wx - q2 * wy - q3 * wz)
    out[1] = 0.5 * (q0 * wx + q2 * wz - q3 * wy)
    out[2] = 0.5 * (q0 * wy + q3 * wx - q1 * wz)
    out[3] = 0.5 * (q0 * wz + q1 * wy - q2 * wx)
    for r in range(n):
        acc = 0.0
        for c in range(n):
            acc += p.mass_inv[r, c] * force[c]
        if r < 3:
            out[4 + r] = acc
        else:
            out[4 + nq + r] = acc  # q̈ at 7+nq+(r−3), Ω̇ at 7+2nq+(r−3−nq): both 4+nq+r


@njit(cache=True)
def plant_derivative_1(
    x: np.ndarray, wheel_motor_torque: np.ndarray, ext_torque_b: np.ndarray, p: PlantArrays
) -> np.ndarray:
    """ẋ of seed 000 eq (1): Λ̇ = ½Λ∘ω and {ω̇, q̈, Ω̇} = (A^o)^-1 {F^ω, F^q, F^r} (compiled kernel)."""
    out = np.empty(x.shape[0])
    force = np.empty(p.mass_inv.shape[0])
    plant_derivative_into(x, wheel_motor_torque, ext_torque_b, p, force, out)
    return out


@njit(cache=True)
def kinetic_energy_1(x: np.ndarray, p: PlantArrays) -> float:
    """Kinetic energy ½ vᵀ A^o v, v = {ω, q̇, Ω}, J (seed 000 eq 1)."""
    nq = p.flex_mass.shape[0]
    nw = p.wheel_inertia.shape[0]
    g = angular_momentum_b_1(x, p)
    e = x[4] * g[0] + x[5] * g[1] + x[6] * g[2]
    for j in range(nq):
        qd = x[7 + nq + j]
        e += qd * p.flex_mass[j] * qd
        for i in range(3):
            e += qd * p.flex_coupling[i, j] * x[4 + i]
    for w in range(nw):
        om = x[7 + 2 * nq + w]
        axial = p.wheel_axes[0, w] * x[4] + p.wheel_axes[1, w] * x[5] + p.wheel_axes[2, w] * x[6]
        e += p.wheel_inertia[w] * om * (axial + om)
    return float(0.5 * e)


@njit(cache=True)
def mechanical_energy_1(x: np.ndarray, p: PlantArrays) -> float:
    """Kinetic plus modal strain energy ½ Σ a^q_j (Ω^q_j q_j)², J (seed 000 eq 1)."""
    nq = p.flex_mass.shape[0]
    e = kinetic_energy_1(x, p)
    for j in range(nq):
        e += 0.5 * p.flex_mass[j] * (p.flex_freq[j] * x[7 + j]) ** 2
    return e


# --- friendly numpy API -------------------------------------------------------------------------


def _state(x: ArrayLike, params: PlantParams) -> np.ndarray:
    n = state_size(params.n_modes, params.n_wheels)
    return _finite(x, "x", (n,))


def plant_derivative(
    x: ArrayLike, wheel_motor_torque_nm: ArrayLike | None, ext_torque_b_nm: ArrayLike | None, params: PlantParams
) -> np.ndarray:
    """ẋ of seed 000 eq (1) for one state (validated wrapper of ``plant_derivative_1``)."""
    m = _finite(
        np.zeros(params.n_wheels) if wheel_motor_torque_nm is None else wheel_motor_torque_nm,
        "wheel_motor_torque_nm",
        (params.n_wheels,),
    )
    t = _finite(np.zeros(3) if ext_torque_b_nm is None else ext_torque_b_nm, "ext_torque_b_nm", (3,))
    return plant_derivative_1(_state(x, params), m, t, params.pack())


def _rows(x: ArrayLike, params: PlantParams) -> tuple[np.ndarray, tuple[int, ...]]:
    """States of shape (..., n) as contiguous rows (m, n) plus the leading shape."""
    n = state_size(params.n_modes, params.n_wheels)
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != n:
        raise ValueError(f"x: expected shape (..., {n}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("x: contains NaN or infinite values")
    return np.ascontiguousarray(arr.reshape(-1, n)), arr.shape[:-1]


def angular_momentum_b(x: ArrayLike, params: PlantParams) -> np.ndarray:
    """Total angular momentum G in body axes, N·m·s, for states of shape (..., n) (seed 000 eq 1)."""
    rows, lead = _rows(x, params)
    p = params.pack()
    return np.array([angular_momentum_b_1(r, p) for r in rows]).reshape(lead + (3,))


def angular_momentum_i(x: ArrayLike, params: PlantParams) -> np.ndarray:
    """Total angular momentum Λ ∘ G ∘ Λ̃ in inertial axes, N·m·s (conserved without M^o), shape (..., 3)."""
    rows, lead = _rows(x, params)
    p = params.pack()
    return np.array([rotate_1(r[:4], angular_momentum_b_1(r, p)) for r in rows]).reshape(lead + (3,))


def wheel_momentum(x: ArrayLike, params: PlantParams) -> np.ndarray:
    """Relative wheel momenta h = J_r Ω, N·m·s, shape (..., n_w) (seed 000 eq 1); the cluster's is A h."""
    rows, lead = _rows(x, params)
    momentum_nms: npt.NDArray[np.float64] = (rows[:, 7 + 2 * params.n_modes :] * params.wheels.inertia_kg_m2).reshape(
        lead + (params.n_wheels,)
    )
    return momentum_nms


def kinetic_energy(x: ArrayLike, params: PlantParams) -> float | np.ndarray:
    """Kinetic energy ½ vᵀ A^o v, J, for states of shape (..., n) (seed 000 eq 1)."""
    rows, lead = _rows(x, params)
    p = params.pack()
    e = np.array([kinetic_energy_1(r, p) for r in rows]).reshape(lead)
    return float(e) if e.ndim == 0 else e


def mechanical_energy(x: ArrayLike, params: PlantParams) -> float | np.ndarray:
    """Kinetic plus modal strain energy, J, for states of shape (..., n) (seed 000 eq 1)."""
    rows, lead = _rows(x, params)
    p = params.pack()
    e = np.array([mechanical_energy_1(r, p) for r in rows]).reshape(lead)
    return float(e) if e.ndim == 0 else e
