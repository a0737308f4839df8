"""Onboard control laws: seed 000's digital law (7)–(8), quaternion PD, B-dot, magnetic unloading, MRP feedback.

Every law is a numba kernel (``*_step``) on float64 arrays for the engine's inner loop, next to a
vectorised numpy API for tests and tools. Torques are body torques M^r (N·m, body axes) to be
distributed by :mod:`sim_core.allocation`; dipoles are A·m² in body axes; fields in tesla.

Timing assumption of the digital law (seed 000 eq 3): the torque computed from the data of t_k is
held over [t_k, t_{k+1}), T_u = t_{k+1} − t_k, with no further computational delay. The stability
test also covers a one-period delay, should an engine apply the torque one period late.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy.optimize import brentq

from sim_core.quaternion import conjugate_rotate_1, dot3_1, multiply_1

__all__ = [
    "SOMOV_INERTIA_KG_M2",
    "G_K",
    "G_P",
    "G_B",
    "G_C",
    "DigitalLawGains",
    "lead_lag_coefficients",
    "error_quaternion",
    "mismatch_vector",
    "error_matrix",
    "digital_law",
    "gyroscopic_torque",
    "closed_loop_matrix",
    "loop_response",
    "loop_margins",
    "wheel_torque_command",
    "quaternion_pd",
    "bdot_dipole",
    "unloading_dipole",
    "mrp_feedback",
    "error_matrix_1",
    "digital_law_step",
    "gyroscopic_torque_1",
    "wheel_torque_command_1",
    "quaternion_pd_step",
    "bdot_dipole_step",
    "unloading_dipole_step",
    "MrpWheels",
    "MrpGains",
    "mrp_feedback_step",
    "program_in_body_1",
    "mrp_tracking_step",
    "rate_brake_torque_1",
]

# Inertia of a ~300 kg land-survey mini-satellite (seed 000 gives no J). A 300 kg bus about
# 1.0 × 1.0 × 1.3 m with a telescope along x has radii of gyration of 0.29–0.34 m, i.e.
# J = m r² ≈ diag(35, 30, 25) kg·m²; this is also the peer Basilisk spacecraft of DESIGN.md, so the
# two simulators fly the same body.
SOMOV_INERTIA_KG_M2 = np.diag([35.0, 30.0, 25.0])

# Layout of the gains vector of digital_law_step (DigitalLawGains.as_array).
G_K, G_P, G_B, G_C = range(4)


def lead_lag_coefficients(tau1_s: float, tau2_s: float, t_u_s: float) -> tuple[float, float, float, float]:
    """a, b, p, c of seed 000 §4 from τ1, τ2, T_u: the Tustin image of k(1 + τ1 s)/(1 + τ2 s).

    With s = d_u (z − 1)/(z + 1), d_u = 2/T_u, the lead-lag becomes k p (z − a)/(z − b), and
    g_{k+1} = b g_k + c ε_k, m̃_k = k(g_k + p ε_k) realises it with c = p(b − a); k is the static gain.
    """
    for name, value in (("tau1_s", tau1_s), ("tau2_s", tau2_s), ("t_u_s", t_u_s)):
        if not value > 0.0:
            raise ValueError(f"{name}: must be positive")
    d_u = 2.0 / t_u_s
    a = (d_u * tau1_s - 1.0) / (d_u * tau1_s + 1.0)
    b = (d_u * tau2_s - 1.0) / (d_u * tau2_s + 1.0)
    p = (1.0 - b) / (1.0 - a)
    return a, b, p, p * (b - a)


@dataclass(frozen=True)
class DigitalLawGains:
    """Gains of seed 000's law (8) for T_u = 2 s (seed 000 §5; the seed gives no k, τ1, τ2).

    Per axis the loop is a double integrator (J cancelled by eq 7) with ZOH at T_u and a lead-lag.
    Design: crossover ω_c = 0.2 rad/s, a decade under ω_c's practical ceiling for T_u = 2 s (ZOH lag
    ω_c T_u/2 = 11.5°; Nyquist π/T_u = 1.57 rad/s); lead ratio τ1/τ2 = 16 gives 62° of lead at ω_c.
    Then τ1 = √16/ω_c = 20 s, τ2 = 1.25 s, k = ω_c²/√16 = 0.01 s⁻²: gain margin 13.4 dB, phase
    margin 50° (5.1 dB, 27° should the torque come one period late). The static stiffness J k sets
    the error under slowly varying disturbances: the 20° roll's gravity-gradient torque ≈ 1e-5 N·m
    on J_y = 30 kg·m² leaves 1e-5/(J_y k) ≈ 7″ (18″ with the softer k = 4e-3, τ1 = 30 s, τ2 = 2.5 s
    tried first, measured in somov-ge4-scan); the 3″ star-tracker noise then adds < 1″ RMS.
    """

    k_per_s2: float = 0.01
    tau1_s: float = 20.0
    tau2_s: float = 1.25
    t_u_s: float = 2.0

    def __post_init__(self) -> None:
        if not self.k_per_s2 > 0.0:
            raise ValueError("k_per_s2: must be positive")
        lead_lag_coefficients(self.tau1_s, self.tau2_s, self.t_u_s)

    def as_array(self) -> np.ndarray:
        """Gains vector [k, p, b, c] for :func:`digital_law_step` (seed 000 eq 8)."""
        _, b, p, c = lead_lag_coefficients(self.tau1_s, self.tau2_s, self.t_u_s)
        return np.array([self.k_per_s2, p, b, c])


def _as_field(x: np.ndarray, name: str, last: int) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape[-1:] != (last,):
        raise ValueError(f"{name}: expected shape (..., {last}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr


def _as_inertia(inertia_kg_m2: np.ndarray) -> np.ndarray:
    j = np.asarray(inertia_kg_m2, dtype=np.float64)
    if j.shape != (3, 3) or not np.allclose(j, j.T) or np.any(np.linalg.eigvalsh(j) <= 0.0):
        raise ValueError("inertia_kg_m2: expected a symmetric positive-definite 3 × 3 matrix")
    return np.ascontiguousarray(j)


def error_quaternion(q_p: np.ndarray, q_ib: np.ndarray) -> np.ndarray:
    """Error quaternion E = Λ̃^p ∘ Λ (seed 000 §4; the tilde lost in §2), shape (..., 4)."""
    p = _as_field(q_p, "q_p", 4)
    q = _as_field(q_ib, "q_ib", 4)
    p0, pv = p[..., :1], -p[..., 1:]
    q0, qv = q[..., :1], q[..., 1:]
    s = p0 * q0 - np.sum(pv * qv, axis=-1, keepdims=True)
    return np.concatenate([s, p0 * qv + q0 * pv + np.cross(pv, qv)], axis=-1)


def mismatch_vector(e: np.ndarray) -> np.ndarray:
    """Mismatch ε = −2 e0 e of an error quaternion (seed 000 §4); ≈ −(error rotation vector)."""
    e = _as_field(e, "e", 4)
    torque_nm: npt.NDArray[np.float64] = -2.0 * e[..., :1] * e[..., 1:]
    return torque_nm


@njit(cache=True)
def error_matrix_1(e: np.ndarray) -> np.ndarray:
    """C_e = I − 2[e×]Q_eᵗ, Q_e = I e0 + [e×] (seed 000 §2): program-frame → body components.

    Expanded as (1 − 2|e|²) I + 2 e eᵗ − 2 e0 [e×], element by element for the compiled loop.
    """
    e0, e1, e2, e3 = e[0], e[1], e[2], e[3]
    d = 1.0 - 2.0 * (e1 * e1 + e2 * e2 + e3 * e3)
    c = np.empty((3, 3))
    c[0, 0], c[1, 1], c[2, 2] = d + 2.0 * e1 * e1, d + 2.0 * e2 * e2, d + 2.0 * e3 * e3
    c[0, 1], c[1, 0] = 2.0 * (e1 * e2 + e0 * e3), 2.0 * (e1 * e2 - e0 * e3)
    c[0, 2], c[2, 0] = 2.0 * (e1 * e3 - e0 * e2), 2.0 * (e1 * e3 + e0 * e2)
    c[1, 2], c[2, 1] = 2.0 * (e2 * e3 + e0 * e1), 2.0 * (e2 * e3 - e0 * e1)
    return c


@njit(cache=True)
def _mv3(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """3 × 3 matrix times 3-vector without a BLAS call (small-size speed in compiled loops)."""
    r = np.empty(3)
    for i in range(3):
        r[i] = m[i, 0] * v[0] + m[i, 1] * v[1] + m[i, 2] * v[2]
    return r


def error_matrix(e: np.ndarray) -> np.ndarray:
    """C_e of error quaternions (..., 4) → (..., 3, 3) (seed 000 §2)."""
    e = _as_field(e, "e", 4)
    flat = e.reshape(-1, 4)
    return np.array([error_matrix_1(row) for row in flat]).reshape(e.shape[:-1] + (3, 3))


@njit(cache=True)
def digital_law_step(
    q_ib: np.ndarray,
    omega_f_b: np.ndarray,
    q_p: np.ndarray,
    omega_p_p: np.ndarray,
    omega_dot_p_p: np.ndarray,
    g: np.ndarray,
    inertia: np.ndarray,
    gains: np.ndarray,
) -> np.ndarray:
    """M^r_k = J(C_e ω̇^p + C_e ω^p × ω^f + m̃_k), m̃_k = k(g_k + p ε_k), g ← b g + c ε (seed 000 eqs 7–8).

    ``q_ib``: filtered attitude; ``omega_f_b``: filtered body rate (rad/s, body); ``omega_p_p``,
    ``omega_dot_p_p``: program rate and acceleration in program axes; ``g`` (3,) is updated in place.
    """
    p0, p1, p2, p3 = q_p[0], -q_p[1], -q_p[2], -q_p[3]
    q0, q1, q2, q3 = q_ib[0], q_ib[1], q_ib[2], q_ib[3]
    e = np.empty(4)  # E = Λ̃^p ∘ Λ, the Hamilton product of multiply_1 written out
    e[0] = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    e[1] = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    e[2] = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    e[3] = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    c_e = error_matrix_1(e)
    k, p, b, c = gains[G_K], gains[G_P], gains[G_B], gains[G_C]
    wx = c_e[0, 0] * omega_p_p[0] + c_e[0, 1] * omega_p_p[1] + c_e[0, 2] * omega_p_p[2]  # C_e ω^p
    wy = c_e[1, 0] * omega_p_p[0] + c_e[1, 1] * omega_p_p[1] + c_e[1, 2] * omega_p_p[2]
    wz = c_e[2, 0] * omega_p_p[0] + c_e[2, 1] * omega_p_p[1] + c_e[2, 2] * omega_p_p[2]
    accel = np.empty(3)  # C_e ω̇^p + C_e ω^p × ω^f + m̃
    accel[0] = wy * omega_f_b[2] - wz * omega_f_b[1]
    accel[1] = wz * omega_f_b[0] - wx * omega_f_b[2]
    accel[2] = wx * omega_f_b[1] - wy * omega_f_b[0]
    for i in range(3):
        eps = -2.0 * e[0] * e[i + 1]
        accel[i] += c_e[i, 0] * omega_dot_p_p[0] + c_e[i, 1] * omega_dot_p_p[1] + c_e[i, 2] * omega_dot_p_p[2]
        accel[i] += k * (g[i] + p * eps)
        g[i] = b * g[i] + c * eps
    torque = np.empty(3)
    for i in range(3):
        torque[i] = inertia[i, 0] * accel[0] + inertia[i, 1] * accel[1] + inertia[i, 2] * accel[2]
    return torque


def digital_law(
    q_ib: np.ndarray,
    omega_f_b_rad_s: np.ndarray,
    q_p: np.ndarray,
    omega_p_rad_s: np.ndarray,
    omega_dot_p_rad_s2: np.ndarray,
    g: np.ndarray,
    inertia_kg_m2: np.ndarray = SOMOV_INERTIA_KG_M2,
    gains: DigitalLawGains = DigitalLawGains(),
) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised seed 000 eqs (7)–(8): returns (M^r in N·m (..., 3), next lead-lag state g (..., 3))."""
    fields = [
        _as_field(q_ib, "q_ib", 4),
        _as_field(omega_f_b_rad_s, "omega_f_b_rad_s", 3),
        _as_field(q_p, "q_p", 4),
        _as_field(omega_p_rad_s, "omega_p_rad_s", 3),
        _as_field(omega_dot_p_rad_s2, "omega_dot_p_rad_s2", 3),
        _as_field(g, "g", 3),
    ]
    shape = np.broadcast_shapes(*(f.shape[:-1] for f in fields))
    flat = [np.broadcast_to(f, shape + f.shape[-1:]).reshape(-1, f.shape[-1]).copy() for f in fields]
    j, gv = _as_inertia(inertia_kg_m2), gains.as_array()
    torque = np.empty((flat[0].shape[0], 3))
    for i in range(torque.shape[0]):
        torque[i] = digital_law_step(flat[0][i], flat[1][i], flat[2][i], flat[3][i], flat[4][i], flat[5][i], j, gv)
    return torque.reshape(shape + (3,)), flat[5].reshape(shape + (3,))


@njit(cache=True)
def gyroscopic_torque_1(omega_b: np.ndarray, inertia: np.ndarray, h_cluster_b: np.ndarray) -> np.ndarray:
    """ω × G, G = Jω + ℋ (seed 000 eq 1, F^ω = −ω × G): add it to M^r of eq (7) to cancel the coupling.

    Eq (7) as printed leaves this term to the feedback, which then holds a static error
    (ω × G)/(J k); ``h_cluster_b`` is the wheels' momentum in body axes, A h (N·m·s).
    """
    g = np.empty(3)
    for i in range(3):
        g[i] = inertia[i, 0] * omega_b[0] + inertia[i, 1] * omega_b[1] + inertia[i, 2] * omega_b[2] + h_cluster_b[i]
    return np.cross(omega_b, g)


def gyroscopic_torque(
    omega_b_rad_s: np.ndarray, h_cluster_b_nms: np.ndarray, inertia_kg_m2: np.ndarray = SOMOV_INERTIA_KG_M2
) -> np.ndarray:
    """Vectorised ω × (Jω + ℋ) in N·m (seed 000 eq 1), shape (..., 3)."""
    w = _as_field(omega_b_rad_s, "omega_b_rad_s", 3)
    h = _as_field(h_cluster_b_nms, "h_cluster_b_nms", 3)
    j = _as_inertia(inertia_kg_m2)
    return np.cross(w, w @ j.T + h)


def closed_loop_matrix(gains: DigitalLawGains = DigitalLawGains(), delay_periods: int = 0) -> np.ndarray:
    """Per-axis linearised loop of seed 000 eqs (3), (7)–(8): state (φ, φ̇, g[, u_held]) from t_k to t_{k+1}.

    Eq (7) cancels J, so each error angle obeys φ̈ = m̃ held over T_u (ZOH); ε = −φ to first order.
    """
    if delay_periods not in (0, 1):
        raise ValueError("delay_periods: 0 (torque applied at once) or 1 (one period late)")
    t = gains.t_u_s
    k, p, b, c = gains.as_array()
    law = np.array([-k * p, 0.0, k])  # m̃ = k(g + p ε), ε = −φ
    n = 3 + delay_periods
    phi = np.zeros((n, n))
    phi[0, :2] = 1.0, t
    phi[1, 1] = 1.0
    phi[2, 0], phi[2, 2] = -c, b
    if delay_periods == 0:
        phi[0, :3] += 0.5 * t * t * law
        phi[1, :3] += t * law
    else:
        phi[0, 3], phi[1, 3] = 0.5 * t * t, t
        phi[3, :3] = law
    return phi


def loop_response(
    omega_rad_s: np.ndarray, gains: DigitalLawGains = DigitalLawGains(), delay_periods: int = 0
) -> np.ndarray:
    """Open-loop frequency response L(e^{jωT}) = C(z) P(z) z^{−d} of the linearised loop (seed 000 eqs 3, 8)."""
    t = gains.t_u_s
    k, p, b, _ = gains.as_array()
    a = lead_lag_coefficients(gains.tau1_s, gains.tau2_s, t)[0]
    z = np.exp(1j * np.asarray(omega_rad_s, dtype=float) * t)
    response: npt.NDArray[np.complex128] = (
        k * p * (z - a) / (z - b) * t * t * (z + 1.0) / (2.0 * (z - 1.0) ** 2) * z ** (-delay_periods)
    )
    return response


def loop_margins(gains: DigitalLawGains = DigitalLawGains(), delay_periods: int = 0) -> tuple[float, float, float]:
    """(gain margin, phase margin in rad, crossover in rad/s) of the linearised digital loop (seed 000 eqs 3, 8)."""
    nyquist = np.pi / gains.t_u_s
    grid = np.linspace(1e-5, nyquist * (1.0 - 1e-9), 20001)
    resp = loop_response(grid, gains, delay_periods)
    crossings = np.flatnonzero(np.diff(np.sign(np.abs(resp) - 1.0)))
    if crossings.size == 0:
        raise ValueError("k_per_s2: the loop gain stays above 1 up to the Nyquist rate; lower k or T_u")
    i = crossings[0]
    w_c = brentq(lambda w: abs(loop_response(w, gains, delay_periods)) - 1.0, grid[i], grid[i + 1])
    phase_margin = (np.angle(loop_response(w_c, gains, delay_periods)) + 2.0 * np.pi) % (2.0 * np.pi) - np.pi
    imag = resp.imag
    cross = [j for j in np.flatnonzero(np.diff(np.sign(imag))) if resp[j].real < 0.0]
    if not cross:
        return np.inf, float(phase_margin), float(w_c)
    j = cross[0]
    w_180 = brentq(lambda w: loop_response(w, gains, delay_periods).imag, grid[j], grid[j + 1])
    return float(-1.0 / loop_response(w_180, gains, delay_periods).real), float(phase_margin), float(w_c)


@njit(cache=True)
def wheel_torque_command_1(m_nm: float, quantum_nm: float, m_max_nm: float) -> float:
    """Sat(Qntr(m, m°_r), m^m_r) of one wheel torque (seed 000 eq 3); Zh holds it over T_u."""
    q = m_nm
    if quantum_nm > 0.0:
        q = np.sign(m_nm) * quantum_nm * np.floor(abs(m_nm) / quantum_nm + 0.5)
    return min(max(q, -m_max_nm), m_max_nm)


def wheel_torque_command(m_nm: np.ndarray, quantum_nm: float, m_max_nm: float) -> np.ndarray:
    """Vectorised seed 000 eq (3): quantise to m°_r (0 = none), saturate at ±m^m_r, N·m."""
    if not quantum_nm >= 0.0:
        raise ValueError("quantum_nm: must be zero (no quantisation) or positive")
    if not m_max_nm > 0.0:
        raise ValueError("m_max_nm: must be positive")
    m = np.asarray(m_nm, dtype=np.float64)
    if not np.all(np.isfinite(m)):
        raise ValueError("m_nm: contains NaN or infinite values")
    q = m if quantum_nm == 0.0 else np.sign(m) * quantum_nm * np.floor(np.abs(m) / quantum_nm + 0.5)
    return np.clip(q, -m_max_nm, m_max_nm)


@njit(cache=True)
def quaternion_pd_step(
    q_ib: np.ndarray, omega_b: np.ndarray, q_d: np.ndarray, omega_d_d: np.ndarray, kp_nm: float, kd_nms: float
) -> np.ndarray:
    """u = −K_p q_e − K_d ω_e, Q_e = Q_d* ∘ Q (seed 002 eqs 17–18), short way (q_e0 ≥ 0); ω_e = ω − C_e ω_d."""
    qdc = np.empty(4)
    qdc[0] = q_d[0]
    qdc[1:] = -q_d[1:]
    e = multiply_1(qdc, q_ib)
    if e[0] < 0.0:
        e = -e
    omega_e = omega_b - _mv3(error_matrix_1(e), omega_d_d)
    torque_nm: npt.NDArray[np.float64] = -kp_nm * e[1:] - kd_nms * omega_e
    return torque_nm


def quaternion_pd(
    q_ib: np.ndarray, omega_b_rad_s: np.ndarray, q_d: np.ndarray, omega_d_rad_s: np.ndarray, kp_nm: float, kd_nms: float
) -> np.ndarray:
    """Vectorised seed 002 eq (18) body torque (..., 3) in N·m."""
    fields = [
        _as_field(q_ib, "q_ib", 4),
        _as_field(omega_b_rad_s, "omega_b_rad_s", 3),
        _as_field(q_d, "q_d", 4),
        _as_field(omega_d_rad_s, "omega_d_rad_s", 3),
    ]
    if not (kp_nm >= 0.0 and kd_nms >= 0.0):
        raise ValueError("kp_nm, kd_nms: gains must be non-negative")
    shape = np.broadcast_shapes(*(f.shape[:-1] for f in fields))
    flat = [np.ascontiguousarray(np.broadcast_to(f, shape + f.shape[-1:]).reshape(-1, f.shape[-1])) for f in fields]
    out = np.array([quaternion_pd_step(a, b, c, d, kp_nm, kd_nms) for a, b, c, d in zip(*flat)])
    return out.reshape(shape + (3,))


@njit(cache=True)
def _limit_dipole(dipole: np.ndarray, l_max: float) -> np.ndarray:
    """Scale the whole dipole so that |l_i| ≤ l^m (direction kept: the law's sign properties hold)."""
    peak = np.max(np.abs(dipole))
    if peak > l_max:
        dipole_am2: npt.NDArray[np.float64] = dipole * (l_max / peak)
        return dipole_am2
    return dipole


@njit(cache=True)
def bdot_dipole_step(
    b_now_b_t: np.ndarray, b_prev_b_t: np.ndarray, dt_s: float, gain: float, l_max_am2: float
) -> np.ndarray:
    """B-dot dipole L = −k Ḃ, Ḃ ≈ (B_k − B_{k−1})/Δt from magnetometer samples (seed 003 eq 30), |l_i| ≤ l^m.

    Seed 003 prints M = −k B under the name B-dot; the law it names (its ref. 25) uses Ḃ.
    """
    return _limit_dipole(-gain * (b_now_b_t - b_prev_b_t) / dt_s, l_max_am2)


def bdot_dipole(
    b_now_b_t: np.ndarray, b_prev_b_t: np.ndarray, dt_s: float, gain_am2_s_per_t: float, l_max_am2: float
) -> np.ndarray:
    """Vectorised seed 003 eq (30) with magnetometer differences: dipole (..., 3) in A·m²."""
    now, prev = _as_field(b_now_b_t, "b_now_b_t", 3), _as_field(b_prev_b_t, "b_prev_b_t", 3)
    if not dt_s > 0.0:
        raise ValueError("dt_s: magnetometer sampling interval must be positive")
    if not (gain_am2_s_per_t > 0.0 and l_max_am2 > 0.0):
        raise ValueError("gain_am2_s_per_t, l_max_am2: must be positive")
    shape = np.broadcast_shapes(now.shape, prev.shape)
    now, prev = (np.broadcast_to(v, shape).reshape(-1, 3).copy() for v in (now, prev))
    out = np.array([bdot_dipole_step(a, b, dt_s, gain_am2_s_per_t, l_max_am2) for a, b in zip(now, prev)])
    return out.reshape(shape)


@njit(cache=True)
def unloading_dipole_step(
    b_b_t: np.ndarray, h_wheels_b_nms: np.ndarray, h_target_b_nms: np.ndarray, gain_per_s: float, l_max_am2: float
) -> np.ndarray:
    """Unloading dipole L = B × T / B², T = −k(H − H*) (seed 003 eq 29), |l_i| ≤ l^m; torque L × B ⊥ B."""
    b2 = dot3_1(b_b_t, b_b_t)
    if b2 == 0.0:
        return np.zeros(3)
    dipole = np.cross(b_b_t, -gain_per_s * (h_wheels_b_nms - h_target_b_nms))
    return _limit_dipole(dipole / b2, l_max_am2)


def unloading_dipole(
    b_b_t: np.ndarray,
    h_wheels_b_nms: np.ndarray,
    h_target_b_nms: np.ndarray,
    gain_per_s: float,
    l_max_am2: float,
) -> np.ndarray:
    """Vectorised seed 003 eq (29) for momentum unloading: dipole (..., 3) in A·m²."""
    fields = [
        _as_field(b_b_t, "b_b_t", 3),
        _as_field(h_wheels_b_nms, "h_wheels_b_nms", 3),
        _as_field(h_target_b_nms, "h_target_b_nms", 3),
    ]
    if not (gain_per_s > 0.0 and l_max_am2 > 0.0):
        raise ValueError("gain_per_s, l_max_am2: must be positive")
    shape = np.broadcast_shapes(*(f.shape for f in fields))
    flat = [np.broadcast_to(f, shape).reshape(-1, 3).copy() for f in fields]
    out = np.array([unloading_dipole_step(a, b, c, gain_per_s, l_max_am2) for a, b, c in zip(*flat)])
    return out.reshape(shape)


class MrpWheels(NamedTuple):
    """The wheels whose momentum Basilisk's mrpFeedback sums: spin axes g (3, n_w) in body axes, J_s (kg·m²),
    speeds Ω (rad/s) and which of them are available (RWAvailabilityMsg)."""

    gs_b: np.ndarray
    js_kg_m2: np.ndarray
    wheel_speed_rad_s: np.ndarray
    available: np.ndarray


class MrpGains(NamedTuple):
    """Basilisk mrpFeedback gains K (N·m), P (N·m·s) and its law type (0: v = ω_RN, 1: v = ω_BN)."""

    k_nm: float
    p_nms: float
    law_type: int


@njit(cache=True)
def mrp_feedback_step(
    sigma_br: np.ndarray,
    omega_br_b: np.ndarray,
    omega_rn_b: np.ndarray,
    domega_rn_b: np.ndarray,
    inertia: np.ndarray,
    wheels: MrpWheels,
    gains: MrpGains,
) -> np.ndarray:
    """Basilisk mrpFeedback with Ki < 0 (no integral): L_r = −Kσ − Pδω + v × (Iω + Σ J_s(ωᵀg + Ω)g) − I(ω × ω_r − ω̇_r).

    v = ω_RN (law_type 0, Basilisk's default) or ω_BN (law_type 1); wheels outside ``available``
    are left out of the momentum sum, as Basilisk's RWAvailabilityMsg does; no known torque.
    """
    gs_b, js_kg_m2, wheel_speed_rad_s, available = wheels
    omega = omega_br_b + omega_rn_b
    h = _mv3(inertia, omega)
    for i in range(gs_b.shape[1]):
        if available[i]:
            spin = js_kg_m2[i] * (
                omega[0] * gs_b[0, i] + omega[1] * gs_b[1, i] + omega[2] * gs_b[2, i] + wheel_speed_rad_s[i]
            )
            for r in range(3):
                h[r] += spin * gs_b[r, i]
    gyro = np.cross(omega_rn_b if gains.law_type == 0 else omega, h)
    feed = _mv3(inertia, np.cross(omega, omega_rn_b) - domega_rn_b)
    torque_nm: npt.NDArray[np.float64] = -gains.k_nm * sigma_br - gains.p_nms * omega_br_b + gyro - feed
    return torque_nm


def mrp_feedback(
    sigma_br: np.ndarray,
    omega_br_b_rad_s: np.ndarray,
    omega_rn_b_rad_s: np.ndarray,
    domega_rn_b_rad_s2: np.ndarray,
    inertia_kg_m2: np.ndarray,
    gs_b: np.ndarray,
    js_kg_m2: np.ndarray,
    wheel_speed_rad_s: np.ndarray,
    available: np.ndarray,
    k_nm: float,
    p_nms: float,
    law_type: int = 0,
) -> np.ndarray:
    """Vectorised Basilisk-equivalent MRP feedback (the peer benchmark's controller): L_r (..., 3) in N·m."""
    gs = np.ascontiguousarray(np.asarray(gs_b, dtype=np.float64))
    if gs.ndim != 2 or gs.shape[0] != 3:
        raise ValueError(f"gs_b: expected shape (3, n_wheels), got {gs.shape}")
    n = gs.shape[1]
    js = _as_field(js_kg_m2, "js_kg_m2", n)
    if law_type not in (0, 1):
        raise ValueError("law_type: 0 (v = ω_RN) or 1 (v = ω_BN)")
    if not (k_nm > 0.0 and p_nms > 0.0):
        raise ValueError("k_nm, p_nms: gains must be positive")
    fields = [
        _as_field(sigma_br, "sigma_br", 3),
        _as_field(omega_br_b_rad_s, "omega_br_b_rad_s", 3),
        _as_field(omega_rn_b_rad_s, "omega_rn_b_rad_s", 3),
        _as_field(domega_rn_b_rad_s2, "domega_rn_b_rad_s2", 3),
        _as_field(wheel_speed_rad_s, "wheel_speed_rad_s", n),
        np.asarray(available, dtype=np.bool_),
    ]
    if fields[5].shape[-1:] != (n,):
        raise ValueError(f"available: expected shape (..., {n}), got {fields[5].shape}")
    shape = np.broadcast_shapes(*(f.shape[:-1] for f in fields))
    batch = int(np.prod(shape))
    flat = [np.broadcast_to(f, shape + f.shape[-1:]).reshape(batch, f.shape[-1]).copy() for f in fields]
    j = _as_inertia(inertia_kg_m2)
    gains = MrpGains(float(k_nm), float(p_nms), int(law_type))
    out = np.array(
        [
            mrp_feedback_step(s, wbr, wrn, dwrn, j, MrpWheels(gs, js, ws, av), gains)
            for s, wbr, wrn, dwrn, ws, av in zip(*flat)
        ]
    )
    return out.reshape(shape + (3,))


@njit(cache=True)
def program_in_body_1(q_p: np.ndarray, q_ib: np.ndarray, v_p: np.ndarray) -> np.ndarray:
    """A program-axes vector (ω^p, ω̇^p) in body axes: Ẽ ∘ v ∘ E with E = Λ̃^p ∘ Λ (seed 000 §4)."""
    e = multiply_1(np.array([q_p[0], -q_p[1], -q_p[2], -q_p[3]]), q_ib)
    return conjugate_rotate_1(e, v_p)


@njit(cache=True)
def mrp_tracking_step(
    q_ib: np.ndarray,
    omega_b: np.ndarray,
    q_p: np.ndarray,
    omega_p: np.ndarray,
    omega_dot_p: np.ndarray,
    inertia: np.ndarray,
    wheels: MrpWheels,
    gains: MrpGains,
) -> np.ndarray:
    """:func:`mrp_feedback_step` on a quaternion program: σ_BR = ε/(1 + e0) of E = Λ̃^p ∘ Λ (short way),
    ω_RN and ω̇_RN carried into body axes by E, δω = ω − ω_RN."""
    qpc = q_p.copy()
    qpc[1:] = -qpc[1:]
    e = multiply_1(qpc, q_ib)
    if e[0] < 0.0:
        e = -e
    sigma = e[1:] / (1.0 + e[0])
    w_rn_b = conjugate_rotate_1(e, omega_p)
    wd_rn_b = conjugate_rotate_1(e, omega_dot_p)
    return mrp_feedback_step(sigma, omega_b - w_rn_b, w_rn_b, wd_rn_b, inertia, wheels, gains)


@njit(cache=True)
def rate_brake_torque_1(inertia: np.ndarray, omega_b: np.ndarray, tau_s: float) -> np.ndarray:
    """Wheel rate brake −J ω / τ (N·m): the body rate decays with time constant τ (seed 001 rate damping)."""
    brake: np.ndarray = -(inertia @ omega_b) / tau_s
    return brake
