"""Per-axis steady-state Kalman filters of attitude angle and rate: seed 003's body-rate estimator
(eqs 15–19) and seed 000 §4's recurrent discrete filtering of E, ε, ω at T_q.

Model (seed 003 eq 15), per axis: ω̇ = w, α̇ = ω, z = α + v, with w and v white of spectral
densities q and r; ξ = q/r is the filterability index.

Seed 003 eq (17) is garbled in print ("k22 = √(2ξ)√ξ"); the steady-state Riccati solution of
this model — and the only reading that gives eq (19)'s d = √2/2 — is k12 = √ξ, k22 = √2 ξ^{1/4}.

The multisensor unit of seed 003 §3.2.1.2.4 (eq 20 and the KF after it) is the same estimator
with z = IMU attitude − star-tracker attitude and (q₁, r₁): :func:`body_rate_step_1` serves both.

Seed 000 §4 does not print its filter. Our choice: the same model sampled at T_q, i.e. a
per-axis discrete steady-state Kalman (α–β) filter on the mismatch ε_s (gains from the discrete
algebraic Riccati equation, solved here by structured doubling), and a first-order recursive
smoother on the measured rate ω_s with the time constant T of eq (19). The control law reads the
filter state at every T_u = n·T_q.

State layout of the seed-000 filter (one variant): ``state9 = [ε^f (3), ε̇^f (3), ω^f (3)]``.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.linalg import expm

from sim_core import quaternion as qt

__all__ = [
    "continuous_gains",
    "time_constant_and_damping",
    "discrete_gains",
    "body_rate_discretisation",
    "body_rate_step_1",
    "mismatch",
    "error_quaternion_from_mismatch",
    "mismatch_filter_step_1",
    "error_quaternion_from_mismatch_1",
    "filtered_attitude_1",
    "mismatch_1",
]

_SDA_TOLERANCE = 1e-14  # relative change of the Riccati iterate at which doubling stops
_SDA_MAX_ITERATIONS = 64  # each doubling squares the horizon: 2^64 steps is "infinite"


def _check_densities(q: float, r: float) -> None:
    if not (np.isfinite(q) and q > 0.0):
        raise ValueError(f"q: disturbance spectral density must be > 0, got {q}")
    if not (np.isfinite(r) and r > 0.0):
        raise ValueError(f"r: measurement spectral density must be > 0, got {r}")


def continuous_gains(q: float, r: float) -> tuple[float, float]:
    """Steady-state gains (k12, k22) = (√ξ, √2 ξ^{1/4}), ξ = q/r (seed 003 eq 17, as corrected above)."""
    _check_densities(q, r)
    xi = q / r
    return float(np.sqrt(xi)), float(np.sqrt(2.0) * xi**0.25)


def time_constant_and_damping(k12: float, k22: float) -> tuple[float, float]:
    """Time constant T = 1/√k12 = ξ^{-1/4} and damping d = k22/(2√k12) = 0.707 (seed 003 eq 19)."""
    if not (k12 > 0.0 and k22 > 0.0):
        raise ValueError(f"k12, k22: gains must be > 0, got {k12}, {k22}")
    return float(1.0 / np.sqrt(k12)), float(k22 / (2.0 * np.sqrt(k12)))


def discrete_gains(q: float, r: float, dt_s: float) -> tuple[float, float]:
    """Steady-state a-priori Kalman gains (k_α, k_ω) of seed 003 eq 15 sampled every dt (seed 000 §4 filter).

    F = [[1, dt], [0, 1]], Q_d = q [[dt³/3, dt²/2], [dt²/2, dt]], R_d = r/dt (a sample average of
    white noise of density r); the discrete Riccati equation is solved by structured doubling.
    As dt → 0, (k_α, k_ω)/dt → (k22, k12) of eq 17.
    """
    _check_densities(q, r)
    if not (np.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError(f"dt_s: must be > 0, got {dt_s}")
    a = np.array([[1.0, 0.0], [dt_s, 1.0]])  # Fᵀ: the filter Riccati is the control one of (Fᵀ, Hᵀ)
    g = np.array([[dt_s / r, 0.0], [0.0, 0.0]])  # Hᵀ R_d⁻¹ H
    h = q * np.array([[dt_s**3 / 3.0, dt_s**2 / 2.0], [dt_s**2 / 2.0, dt_s]])
    eye = np.eye(2)
    for _ in range(_SDA_MAX_ITERATIONS):
        w = np.linalg.inv(eye + g @ h)
        a, g, h_next = a @ w @ a, g + a @ w @ g @ a.T, h + a.T @ h @ w @ a
        done = np.max(np.abs(h_next - h)) <= _SDA_TOLERANCE * np.max(np.abs(h_next))
        h = h_next
        if done:
            break
    p = h  # steady-state a-priori covariance
    k = p[:, 0] / (p[0, 0] + r / dt_s)
    return float(k[0]), float(k[1])


def body_rate_discretisation(k12: float, k22: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation (Φ, Γ) of the estimator ODE (seed 003 eq 16) over dt.

    x = (α̂, ω̂): ẋ = A x + b z, A = [[−k22, 1], [−k12, 0]], b = (k22, k12); x⁺ = Φ x + Γ z.
    """
    time_constant_and_damping(k12, k22)
    if not dt_s > 0.0:
        raise ValueError(f"dt_s: must be > 0, got {dt_s}")
    m = np.zeros((3, 3))
    m[:2, :2] = [[-k22, 1.0], [-k12, 0.0]]
    m[:2, 2] = [k22, k12]
    e = expm(m * dt_s)
    return e[:2, :2].copy(), e[:2, 2].copy()


@njit(cache=True)
def body_rate_step_1(alpha: np.ndarray, omega: np.ndarray, z: np.ndarray, phi: np.ndarray, gamma: np.ndarray) -> None:
    """Advance the three channels of the body-rate estimator by one step, in place (seed 003 eq 16)."""
    for i in range(alpha.shape[0]):
        a = phi[0, 0] * alpha[i] + phi[0, 1] * omega[i] + gamma[0] * z[i]
        omega[i] = phi[1, 0] * alpha[i] + phi[1, 1] * omega[i] + gamma[1] * z[i]
        alpha[i] = a


def mismatch(q_prog_ib: np.ndarray, q_meas_ib: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Error quaternion E = Λ̃^p ∘ Λ^m and mismatch ε = −2 e0 e (seed 000 §4)."""
    e = qt.multiply(qt.conjugate(qt.normalize(q_prog_ib)), qt.normalize(q_meas_ib))
    return e, -2.0 * e[..., :1] * e[..., 1:]


def error_quaternion_from_mismatch(eps: np.ndarray) -> np.ndarray:
    """E^f from a filtered mismatch ε^f: |ε| = sin θ, E = (cos θ/2, −ε/|ε| sin θ/2), θ ≤ 90° (seed 000 §4)."""
    eps = np.asarray(eps, dtype=float)
    s = np.linalg.norm(eps, axis=-1, keepdims=True)
    if np.any(s > 1.0):
        raise ValueError("eps: |ε| = sin θ cannot exceed 1")
    half = 0.5 * np.arcsin(s)
    unit = np.where(s > 0.0, eps / np.where(s > 0.0, s, 1.0), 0.0)
    return np.concatenate([np.cos(half), -np.sin(half) * unit], axis=-1)


@njit(cache=True)
def error_quaternion_from_mismatch_1(eps: np.ndarray) -> np.ndarray:
    """Compiled E^f from ε^f (seed 000 §4); |ε| is clipped at 1."""
    s = min(np.sqrt(eps[0] ** 2 + eps[1] ** 2 + eps[2] ** 2), 1.0)
    half = 0.5 * np.arcsin(s)
    e = np.empty(4)
    e[0] = np.cos(half)
    k = -np.sin(half) / s if s > 0.0 else 0.0
    e[1] = k * eps[0]
    e[2] = k * eps[1]
    e[3] = k * eps[2]
    return e


@njit(cache=True)
def mismatch_filter_step_1(
    state9: np.ndarray,
    q_prog_ib: np.ndarray,
    q_meas_ib: np.ndarray,
    omega_meas_b: np.ndarray,
    valid: bool,
    k_alpha: float,
    k_omega: float,
    smoothing: float,
    dt: float,
) -> None:
    """One T_q step of seed 000 §4's recurrent filtering of ε_s and ω_s, in place on state9.

    Smooth ω^f ← ω^f + smoothing (ω_s − ω^f), smoothing = 1 − exp(−T_q/T); predict
    ε⁻ = ε^f + dt ε̇^f; if the star-tracker sample is valid, correct with r = ε_s − ε⁻ by the
    discrete gains (k_α, k_ω).
    """
    for i in range(3):
        state9[6 + i] += smoothing * (omega_meas_b[i] - state9[6 + i])
        state9[i] += dt * state9[3 + i]
    if not valid:
        return
    e = qt.multiply_1(np.array([q_prog_ib[0], -q_prog_ib[1], -q_prog_ib[2], -q_prog_ib[3]]), q_meas_ib)
    for i in range(3):
        res = -2.0 * e[0] * e[1 + i] - state9[i]
        state9[i] += k_alpha * res
        state9[3 + i] += k_omega * res


@njit(cache=True)
def filtered_attitude_1(state9: np.ndarray, q_prog_ib: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Filtered attitude Λ^f = Λ^p ∘ E^f(ε^f) and rate ω^f read from state9 at a T_u instant (seed 000 §4).

    Lets a control law that takes an attitude estimate consume the filtered mismatch: it
    recomputes E^f = Λ̃^p ∘ Λ^f exactly.
    """
    e = error_quaternion_from_mismatch_1(state9[0:3])
    q = qt.normalize_1(qt.multiply_1(q_prog_ib, e))
    return q, state9[6:9].copy()


@njit(cache=True)
def mismatch_1(q_prog_ib: np.ndarray, q_meas_ib: np.ndarray) -> np.ndarray:
    """Compiled mismatch ε = −2 e0 e of E = Λ̃^p ∘ Λ^m (seed 000 §4)."""
    e = qt.multiply_1(np.array([q_prog_ib[0], -q_prog_ib[1], -q_prog_ib[2], -q_prog_ib[3]]), q_meas_ib)
    out: np.ndarray = -2.0 * e[0] * e[1:]
    return out
