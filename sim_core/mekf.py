"""Multiplicative extended Kalman filter (MEKF): gyros + star tracker → attitude ``q_ib`` and gyro bias.

The operational estimator of issue 3 (a refinement of seed 003 §3.2.1.2.4's multisensor unit:
the gyro integral is corrected by the star tracker and the gyro bias is estimated).

State: ``q_ib`` (4,), ``bias_b`` (3,) in rad/s, covariance ``p_cov`` (6, 6) of the error state
x = (δθ, Δb): the true attitude is q = q̂ ∘ δq(δθ) (body-frame error, right-multiplied to match
Λ̇ = ½ Λ ∘ ω of seed 000 eq 1) and Δb = b − b̂. Gyro model ω_g = ω + b + n_v, ḃ = n_u
(Farrenkopf): seed 002 eq 13's constant bias plus a Markov drift whose correlation time is long
against the filter's time constant behaves as this random walk (:func:`process_noise_from_gyro`).
Error dynamics δθ̇ = −[ω̂×]δθ − Δb − n_v, Δḃ = n_u, ω̂ = ω_g − b̂.

Units of the kernels: dt in s, σ_v (angle random walk) in rad/√s, σ_u (bias random walk) in
rad/s^{3/2}, measurement σ in rad. The ``*_1`` kernels work in place on plain float64 arrays
(contiguous views of the engine's batch arrays, e.g. ``q[i]`` of an (N, 4) array);
:func:`mekf_run` is the friendly driver over a whole series.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_core import quaternion as qt

__all__ = [
    "process_noise_from_gyro",
    "initial_covariance",
    "mekf_propagate_1",
    "mekf_update_1",
    "mekf_vector_update_1",
    "mekf_run",
]


def process_noise_from_gyro(
    noise_std_rad_s: float, dt_s: float, drift_density_rad_s_sqrt_s: float
) -> tuple[float, float]:
    """(σ_v, σ_u) of the MEKF from seed 002 eq 13's per-sample noise n_g and drift density n_d.

    A white sample of standard deviation σ_g held over dt adds σ_g² dt² of attitude variance, the
    same as angle random walk σ_v = σ_g √dt; the drift driving density is the bias random walk σ_u.
    """
    if not dt_s > 0.0:
        raise ValueError(f"dt_s: must be > 0, got {dt_s}")
    if noise_std_rad_s < 0.0 or drift_density_rad_s_sqrt_s < 0.0:
        raise ValueError("noise_std_rad_s, drift_density_rad_s_sqrt_s: must be non-negative")
    return noise_std_rad_s * np.sqrt(dt_s), float(drift_density_rad_s_sqrt_s)


def initial_covariance(sigma_attitude_rad: float, sigma_bias_rad_s: float) -> np.ndarray:
    """Initial covariance diag(σ_θ² I, σ_b² I) of the error state (δθ, Δb) (seed 003 §3.2.1.2.4 MSU errors)."""
    if not (sigma_attitude_rad > 0.0 and sigma_bias_rad_s > 0.0):
        raise ValueError("sigma_attitude_rad, sigma_bias_rad_s: must be > 0")
    return np.diag([sigma_attitude_rad**2] * 3 + [sigma_bias_rad_s**2] * 3)


@njit(cache=True)
def _sandwich6(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """M P Mᵀ for 6×6 matrices with explicit loops (cheaper than BLAS calls at this size)."""
    tmp = np.zeros((6, 6))
    for i in range(6):
        for k in range(6):
            a = m[i, k]
            if a != 0.0:
                for j in range(6):
                    tmp[i, j] += a * p[k, j]
    out = np.empty((6, 6))
    for i in range(6):
        for j in range(i, 6):
            s = 0.0
            for k in range(6):
                s += tmp[i, k] * m[j, k]
            out[i, j] = s
            out[j, i] = s
    return out


@njit(cache=True)
def mekf_propagate_1(
    q_ib: np.ndarray,
    bias_b: np.ndarray,
    p_cov: np.ndarray,
    omega_meas_b: np.ndarray,
    dt: float,
    sigma_v: float,
    sigma_u: float,
) -> None:
    """Propagate the MEKF in place over dt with a held gyro sample (seed 000 eq 1 kinematics, Farrenkopf noise).

    Φ = [[A, B], [0, I]] with A = exp(−[ω̂×]dt) = R(δq)ᵀ and B = −(I dt − [ω̂×]dt²/2 + [ω̂×]²dt³/6);
    only the blocks that change are computed: P11 = [A B] P [A B]ᵀ, P12 = [A B] P[:, 3:].
    """
    w0 = omega_meas_b[0] - bias_b[0]
    w1 = omega_meas_b[1] - bias_b[1]
    w2 = omega_meas_b[2] - bias_b[2]
    n = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    c = np.cos(0.5 * n * dt)
    s = np.sin(0.5 * n * dt) / n if n > 0.0 else 0.5 * dt
    e0, x, y, z = c, s * w0, s * w1, s * w2
    a0, a1, a2, a3 = q_ib[0], q_ib[1], q_ib[2], q_ib[3]
    r0 = a0 * e0 - a1 * x - a2 * y - a3 * z
    r1 = a0 * x + a1 * e0 + a2 * z - a3 * y
    r2 = a0 * y - a1 * z + a2 * e0 + a3 * x
    r3 = a0 * z + a1 * y - a2 * x + a3 * e0
    inv = 1.0 / np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    q_ib[0], q_ib[1], q_ib[2], q_ib[3] = r0 * inv, r1 * inv, r2 * inv, r3 * inv
    top = np.empty((3, 6))  # [A B]
    top[0, 0] = 1 - 2 * (y * y + z * z)
    top[0, 1] = 2 * (x * y + e0 * z)
    top[0, 2] = 2 * (x * z - e0 * y)
    top[1, 0] = 2 * (x * y - e0 * z)
    top[1, 1] = 1 - 2 * (x * x + z * z)
    top[1, 2] = 2 * (y * z + e0 * x)
    top[2, 0] = 2 * (x * z + e0 * y)
    top[2, 1] = 2 * (y * z - e0 * x)
    top[2, 2] = 1 - 2 * (x * x + y * y)
    h2, h3 = 0.5 * dt * dt, dt**3 / 6.0
    ww = (w0 * w0, w1 * w1, w2 * w2)
    wv = (w0, w1, w2)
    top[0, 4], top[0, 5] = -(h2 * w2 + h3 * w0 * w1), -(-h2 * w1 + h3 * w0 * w2)
    top[1, 3], top[1, 5] = -(-h2 * w2 + h3 * w1 * w0), -(h2 * w0 + h3 * w1 * w2)
    top[2, 3], top[2, 4] = -(h2 * w1 + h3 * w2 * w0), -(-h2 * w0 + h3 * w2 * w1)
    for i in range(3):
        top[i, 3 + i] = -(dt + h3 * (wv[i] * wv[i] - ww[0] - ww[1] - ww[2]))
    tp = np.zeros((3, 6))
    for i in range(3):
        for k in range(6):
            a = top[i, k]
            for j in range(6):
                tp[i, j] += a * p_cov[k, j]
    qv = sigma_v * sigma_v * dt + sigma_u * sigma_u * dt**3 / 3.0
    qc = -0.5 * sigma_u * sigma_u * dt * dt
    qb = sigma_u * sigma_u * dt
    for i in range(3):
        for j in range(i, 3):
            acc = 0.0
            for k in range(6):
                acc += tp[i, k] * top[j, k]
            p_cov[i, j] = acc
            p_cov[j, i] = acc
        for j in range(3):
            p_cov[i, 3 + j] = tp[i, 3 + j]
            p_cov[3 + j, i] = tp[i, 3 + j]
        p_cov[i, i] += qv
        p_cov[i, 3 + i] += qc
        p_cov[3 + i, i] += qc
        p_cov[3 + i, 3 + i] += qb


@njit(cache=True)
def mekf_update_1(
    q_ib: np.ndarray, bias_b: np.ndarray, p_cov: np.ndarray, q_meas_ib: np.ndarray, sigma3: np.ndarray
) -> float:
    """Star-tracker update in place (measurement Λ^m = Λ ∘ Λ^n, seed 000 §4); returns the innovation NIS.

    Residual z = rotation vector of Λ̂̃ ∘ Λ^m, H = [I 0], Joseph-form covariance update
    P = (I − KH) P (I − KH)ᵀ + K R Kᵀ. The normalised innovation squared zᵀS⁻¹z is χ²(3) for a
    consistent filter (an FDIR residual).
    """
    a0, a1, a2, a3 = q_ib[0], -q_ib[1], -q_ib[2], -q_ib[3]
    b0, b1, b2, b3 = q_meas_ib[0], q_meas_ib[1], q_meas_ib[2], q_meas_ib[3]
    d0 = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    d1 = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    d2 = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    d3 = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    if d0 < 0.0:
        d0, d1, d2, d3 = -d0, -d1, -d2, -d3
    vn = np.sqrt(d1 * d1 + d2 * d2 + d3 * d3)
    scale = 2.0 * np.arctan2(vn, d0) / vn if vn > 0.0 else 2.0
    z = (scale * d1, scale * d2, scale * d3)
    s = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s[i, j] = p_cov[i, j]
        s[i, i] += sigma3[i] * sigma3[i]
    s_inv = _inverse3(s)
    k = np.zeros((6, 3))
    dx = np.zeros(6)
    for i in range(6):
        for j in range(3):
            acc = 0.0
            for m in range(3):
                acc += p_cov[i, m] * s_inv[m, j]
            k[i, j] = acc
            dx[i] += acc * z[j]
    _correct(q_ib, bias_b, dx)
    _joseph(p_cov, k, sigma3)
    nis = 0.0
    for i in range(3):
        for j in range(3):
            nis += z[i] * s_inv[i, j] * z[j]
    return nis


@njit(cache=True)
def _correct(q_ib: np.ndarray, bias_b: np.ndarray, dx: np.ndarray) -> None:
    """Apply the error-state estimate: q ← q ∘ (1, δθ/2) normalised with λ0 ≥ 0, b ← b + Δb."""
    e1, e2, e3 = 0.5 * dx[0], 0.5 * dx[1], 0.5 * dx[2]
    a0, a1, a2, a3 = q_ib[0], q_ib[1], q_ib[2], q_ib[3]
    r0 = a0 - a1 * e1 - a2 * e2 - a3 * e3
    r1 = a0 * e1 + a1 + a2 * e3 - a3 * e2
    r2 = a0 * e2 - a1 * e3 + a2 + a3 * e1
    r3 = a0 * e3 + a1 * e2 - a2 * e1 + a3
    inv = 1.0 / np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    if r0 < 0.0:
        inv = -inv
    q_ib[0], q_ib[1], q_ib[2], q_ib[3] = r0 * inv, r1 * inv, r2 * inv, r3 * inv
    for i in range(3):
        bias_b[i] += dx[3 + i]


@njit(cache=True)
def _joseph(p_cov: np.ndarray, k: np.ndarray, sigma3: np.ndarray) -> None:
    """P ← (I − KH) P (I − KH)ᵀ + K R Kᵀ in place for H = [I 0], R = diag(σ²)."""
    a = np.empty((6, 6))  # (I − KH) P
    for i in range(6):
        for j in range(6):
            a[i, j] = p_cov[i, j] - k[i, 0] * p_cov[0, j] - k[i, 1] * p_cov[1, j] - k[i, 2] * p_cov[2, j]
    r0, r1, r2 = sigma3[0] ** 2, sigma3[1] ** 2, sigma3[2] ** 2
    for i in range(6):
        for j in range(i, 6):
            v = a[i, j] - a[i, 0] * k[j, 0] - a[i, 1] * k[j, 1] - a[i, 2] * k[j, 2]
            v += k[i, 0] * r0 * k[j, 0] + k[i, 1] * r1 * k[j, 1] + k[i, 2] * r2 * k[j, 2]
            p_cov[i, j] = v
            p_cov[j, i] = v


@njit(cache=True)
def mekf_vector_update_1(
    q_ib: np.ndarray, bias_b: np.ndarray, p_cov: np.ndarray, v_meas_b: np.ndarray, v_ref_i: np.ndarray, sigma: float
) -> float:
    """Unit-vector update in place (sun sensor, magnetometer direction; seed 003 §3.2.1.2.1 VMD); returns NIS.

    Predicted b̂ = Λ̂̃ ∘ r ∘ Λ̂; with q = q̂ ∘ δq the measurement is b = b̂ + [b̂×]δθ + v, so
    H = [[b̂×], 0] and R = σ² I (Shuster's measurement model, rank-2 in effect).
    """
    rn = np.sqrt(v_ref_i[0] ** 2 + v_ref_i[1] ** 2 + v_ref_i[2] ** 2)
    mn = np.sqrt(v_meas_b[0] ** 2 + v_meas_b[1] ** 2 + v_meas_b[2] ** 2)
    bh = qt.conjugate_rotate_1(q_ib, v_ref_i / rn)
    z = v_meas_b / mn - bh
    h = np.zeros((3, 6))
    h[0, 1], h[0, 2] = -bh[2], bh[1]
    h[1, 0], h[1, 2] = bh[2], -bh[0]
    h[2, 0], h[2, 1] = -bh[1], bh[0]
    ph = p_cov @ h.T  # (6, 3)
    s = h @ ph
    for i in range(3):
        s[i, i] += sigma * sigma
    s_inv = _inverse3(s)
    k = ph @ s_inv
    dx = k @ z
    corr = np.array([1.0, 0.5 * dx[0], 0.5 * dx[1], 0.5 * dx[2]])
    q_new = qt.normalize_1(qt.multiply_1(q_ib, corr))
    if q_new[0] < 0.0:
        q_new = -q_new
    q_ib[:] = q_new
    for i in range(3):
        bias_b[i] += dx[3 + i]
    ikh = np.eye(6) - k @ h
    p_new = _sandwich6(ikh, p_cov) + sigma * sigma * (k @ k.T)
    for i in range(6):
        for j in range(6):
            p_cov[i, j] = 0.5 * (p_new[i, j] + p_new[j, i])
    return float(z @ s_inv @ z)


@njit(cache=True)
def _inverse3(s: np.ndarray) -> np.ndarray:
    """Inverse of a 3×3 matrix by cofactors."""
    inv = np.empty((3, 3))
    inv[0, 0] = s[1, 1] * s[2, 2] - s[1, 2] * s[2, 1]
    inv[0, 1] = s[0, 2] * s[2, 1] - s[0, 1] * s[2, 2]
    inv[0, 2] = s[0, 1] * s[1, 2] - s[0, 2] * s[1, 1]
    inv[1, 0] = s[1, 2] * s[2, 0] - s[1, 0] * s[2, 2]
    inv[1, 1] = s[0, 0] * s[2, 2] - s[0, 2] * s[2, 0]
    inv[1, 2] = s[0, 2] * s[1, 0] - s[0, 0] * s[1, 2]
    inv[2, 0] = s[1, 0] * s[2, 1] - s[1, 1] * s[2, 0]
    inv[2, 1] = s[0, 1] * s[2, 0] - s[0, 0] * s[2, 1]
    inv[2, 2] = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
    det = s[0, 0] * inv[0, 0] + s[0, 1] * inv[1, 0] + s[0, 2] * inv[2, 0]
    inverse: npt.NDArray[np.float64] = inv / det
    return inverse


@njit(cache=True)
def _run(
    q0: np.ndarray,
    b0: np.ndarray,
    p0: np.ndarray,
    omega_meas: np.ndarray,
    q_meas: np.ndarray,
    q_valid: np.ndarray,
    dt: float,
    sigma_v: float,
    sigma_u: float,
    sigma3: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = omega_meas.shape[0]
    q_hist = np.empty((n, 4))
    b_hist = np.empty((n, 3))
    p_hist = np.empty((n, 6, 6))
    q, b, p = q0.copy(), b0.copy(), p0.copy()
    for k in range(n):
        if k > 0:
            mekf_propagate_1(q, b, p, omega_meas[k - 1], dt, sigma_v, sigma_u)
        if q_valid[k]:
            mekf_update_1(q, b, p, q_meas[k], sigma3)
        q_hist[k] = q
        b_hist[k] = b
        p_hist[k] = p
    return q_hist, b_hist, p_hist


def mekf_run(
    q0_ib: np.ndarray,
    bias0_rad_s: np.ndarray,
    p0: np.ndarray,
    omega_meas_b_rad_s: np.ndarray,
    q_meas_ib: np.ndarray,
    q_valid: np.ndarray,
    dt_s: float,
    sigma_v: float,
    sigma_u: float,
    sigma_meas_rad: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run the MEKF over a series sampled every dt: propagate with gyros, update where the star tracker is valid.

    Row k of the result is the estimate at t_k after the measurement of t_k. Returns
    (q_ib (n, 4), bias_b (n, 3), p_cov (n, 6, 6)).
    """
    omega = np.ascontiguousarray(omega_meas_b_rad_s, dtype=float)
    qm = np.ascontiguousarray(q_meas_ib, dtype=float)
    valid = np.ascontiguousarray(q_valid, dtype=np.bool_)
    n = omega.shape[0]
    if omega.shape != (n, 3) or qm.shape != (n, 4) or valid.shape != (n,):
        raise ValueError("omega_meas_b_rad_s, q_meas_ib, q_valid: expected shapes (n, 3), (n, 4), (n,)")
    p0 = np.ascontiguousarray(p0, dtype=float)
    if p0.shape != (6, 6):
        raise ValueError(f"p0: expected shape (6, 6), got {p0.shape}")
    if not dt_s > 0.0:
        raise ValueError(f"dt_s: must be > 0, got {dt_s}")
    sigma3 = np.asarray(sigma_meas_rad, dtype=float) * np.ones(3)
    if np.any(sigma3 <= 0.0):
        raise ValueError("sigma_meas_rad: must be > 0")
    q0 = qt.normalize(q0_ib)
    b0 = np.asarray(bias0_rad_s, dtype=float).reshape(3).copy()
    return _run(q0, b0, p0, omega, qm, valid, float(dt_s), float(sigma_v), float(sigma_u), sigma3)
