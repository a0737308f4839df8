"""Gyro + earth-sensor attitude observer of seed 002 eq (15): roll φ, pitch θ, yaw ψ about the orbit frame.

    φ̂̇ = ω_o ψ̂ + ω_gx + K_φ (φ_m − φ̂)
    θ̂̇ = ω_o + ω_gy + K_θ (θ_m − θ̂)
    ψ̂̇ = −ω_o φ̂ + ω_gz + K_ψ (φ_m − φ̂)

Small-angle kinematics of seed 002's orbit frame (x roll, y pitch, z yaw, orbital rate ω_o about
y as the seed writes it). Yaw is not measured: it is observed through the orbital coupling with
roll (gyrocompassing), so the yaw channel is driven by the roll residual, as printed.
Linear with inputs held over a step, so we discretise it exactly (zero-order hold):
x̂⁺ = Φ x̂ + Γ u with u = (ω_gx, ω_gy, ω_gz, φ_m, θ_m, ω_o).
The observer error e = x̂ − x obeys ė = A e: θ decays at K_θ, and (φ, ψ) have the characteristic
polynomial s² + K_φ s + ω_o (ω_o + K_ψ).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.linalg import expm

__all__ = ["observer_matrix", "observer_discretisation", "observer_step_1", "design_rates"]


def _gains(gains_1_s: np.ndarray, orbit_rate_rad_s: float) -> np.ndarray:
    k = np.asarray(gains_1_s, dtype=float)
    if k.shape != (3,) or not np.all(np.isfinite(k)) or np.any(k <= 0.0):
        raise ValueError(f"gains_1_s: expected three positive gains (K_φ, K_θ, K_ψ), got {gains_1_s!r}")
    if not (np.isfinite(orbit_rate_rad_s) and orbit_rate_rad_s > 0.0):
        raise ValueError(f"orbit_rate_rad_s: must be > 0, got {orbit_rate_rad_s}")
    return k


def observer_matrix(gains_1_s: np.ndarray, orbit_rate_rad_s: float) -> np.ndarray:
    """Error-dynamics matrix A of the observer, ė = A e with e = (φ̂−φ, θ̂−θ, ψ̂−ψ) (seed 002 eq 15)."""
    kp, kt, ky = _gains(gains_1_s, orbit_rate_rad_s)
    wo = orbit_rate_rad_s
    return np.array([[-kp, 0.0, wo], [0.0, -kt, 0.0], [-wo - ky, 0.0, 0.0]])


def design_rates(gains_1_s: np.ndarray, orbit_rate_rad_s: float) -> np.ndarray:
    """Error eigenvalues (1/s): −K_θ and the roots of s² + K_φ s + ω_o(ω_o + K_ψ) (seed 002 eq 15)."""
    kp, kt, ky = _gains(gains_1_s, orbit_rate_rad_s)
    roots = np.roots([1.0, kp, orbit_rate_rad_s * (orbit_rate_rad_s + ky)])
    return np.concatenate([[-kt + 0j], roots])


def observer_discretisation(
    gains_1_s: np.ndarray, orbit_rate_rad_s: float, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH (Φ (3, 3), Γ (3, 6)) of seed 002 eq (15) over dt, inputs u = (ω_g, φ_m, θ_m, ω_o)."""
    kp, kt, ky = _gains(gains_1_s, orbit_rate_rad_s)
    if not (np.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError(f"dt_s: must be > 0, got {dt_s}")
    m = np.zeros((9, 9))
    m[:3, :3] = observer_matrix(gains_1_s, orbit_rate_rad_s)
    m[:3, 3:6] = np.eye(3)  # gyro rates
    m[0, 6], m[2, 6] = kp, ky  # measured roll drives the roll and yaw channels
    m[1, 7] = kt  # measured pitch
    m[1, 8] = 1.0  # θ̇ gains ω_o
    e = expm(m * dt_s)
    return e[:3, :3].copy(), e[:3, 3:].copy()


@njit(cache=True)
def observer_step_1(
    angles3: np.ndarray,
    phi: np.ndarray,
    gamma: np.ndarray,
    omega_gyro_b: np.ndarray,
    roll_meas: float,
    pitch_meas: float,
    orbit_rate: float,
) -> None:
    """Advance (φ̂, θ̂, ψ̂) in place by one held-input step of seed 002 eq (15)."""
    u = np.empty(6)
    u[0], u[1], u[2] = omega_gyro_b[0], omega_gyro_b[1], omega_gyro_b[2]
    u[3], u[4], u[5] = roll_meas, pitch_meas, orbit_rate
    new = np.zeros(3)
    for i in range(3):
        for j in range(3):
            new[i] += phi[i, j] * angles3[j]
        for j in range(6):
            new[i] += gamma[i, j] * u[j]
    angles3[:] = new
