"""Attitude sensors: star tracker, gyros, earth sensor, magnetometer, sun sensor, wheel tachometers, GPS.

Every sensor returns its sample and a validity flag (the "data bad/good" flag of seed 003
§3.2.3.1). SI units inside: rad, rad/s, tesla, metres. Quaternions are scalar-first ``q_ib``
(body → inertial, DESIGN.md).

Determinism: noise never comes from numba's own generator (its state is global per thread and
shared by every kernel, so it would couple batch variants). The caller draws standard normals
from a ``numpy.random.Generator`` — one Generator per batch variant, from
:func:`variant_generators` (``SeedSequence(seed).spawn``) — and passes them in: the ``*_1``
kernels take one pre-drawn row, the vectorised functions take the Generator. The same seed and
variant index therefore give the same noise whatever the batch size or the order of variants.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from sim_core import quaternion as qt

__all__ = [
    "variant_generators",
    "rotation_noise_quaternion",
    "star_tracker",
    "star_tracker_1",
    "GaussMarkovDrift",
    "gauss_markov_drift",
    "gyro",
    "gyro_1",
    "earth_sensor",
    "magnetometer",
    "in_earth_shadow",
    "sun_sensor",
    "wheel_tachometer",
    "wheel_tachometer_1",
    "gps_receiver",
]

ARCSEC = np.pi / (180.0 * 3600.0)  # rad per arcsecond
EARTH_RADIUS_M = 6_378_137.0  # WGS-84 equatorial radius (shadow cylinder radius)


def _positive(value: float | np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ValueError(f"{name}: must be finite and non-negative, got {value!r}")
    return arr


def _vectors(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected shape (..., 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return v


def variant_generators(seed: int, n_variants: int) -> list[np.random.Generator]:
    """One independent noise Generator per batch variant (SeedSequence spawn; seed 000 §7 variants)."""
    if n_variants < 1:
        raise ValueError(f"n_variants: must be ≥ 1, got {n_variants}")
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n_variants)]


# --- star tracker: Λ^m = Λ ∘ Λ^n (seed 000 §4) ------------------------------------------------


def rotation_noise_quaternion(theta_b: np.ndarray) -> np.ndarray:
    """Noise quaternion Λ^n = (cos |θ|/2, θ/|θ| sin |θ|/2) of a body rotation vector θ (seed 000 §4)."""
    theta = _vectors(theta_b, "theta_b")
    norm = np.linalg.norm(theta, axis=-1, keepdims=True)
    half = 0.5 * norm
    sinc = np.where(norm > 0.0, np.sin(half) / np.where(norm > 0.0, norm, 1.0), 0.5)
    return np.concatenate([np.cos(half), sinc * theta], axis=-1)


def star_tracker(
    q_ib: np.ndarray,
    omega_b_rad_s: np.ndarray,
    sigma_rad: float | np.ndarray,
    max_rate_rad_s: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Measured attitude Λ^m = Λ ∘ Λ^n, σ per body axis, invalid above the tracking rate (seed 000 §4).

    Returns (q_meas_ib (..., 4), valid (...)). ``sigma_rad`` is a scalar or (σx, σy, σz).
    """
    q = qt.normalize(q_ib)
    omega = _vectors(omega_b_rad_s, "omega_b_rad_s")
    sigma = _positive(sigma_rad, "sigma_rad") * np.ones(3)
    _positive(max_rate_rad_s, "max_rate_rad_s")
    theta = sigma * rng.standard_normal(q.shape[:-1] + (3,))
    q_meas = qt.normalize(qt.multiply(q, rotation_noise_quaternion(theta)))
    valid = np.linalg.norm(omega, axis=-1) <= max_rate_rad_s
    return q_meas, valid


@njit(cache=True)
def star_tracker_1(
    q_ib: np.ndarray, omega_b: np.ndarray, sigma3: np.ndarray, max_rate: float, normal3: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Compiled star tracker sample Λ^m = Λ ∘ Λ^n from three pre-drawn standard normals (seed 000 §4)."""
    t0 = sigma3[0] * normal3[0]
    t1 = sigma3[1] * normal3[1]
    t2 = sigma3[2] * normal3[2]
    norm = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    qn = np.empty(4)
    qn[0] = np.cos(0.5 * norm)
    s = np.sin(0.5 * norm) / norm if norm > 0.0 else 0.5
    qn[1] = s * t0
    qn[2] = s * t1
    qn[3] = s * t2
    qm = qt.normalize_1(qt.multiply_1(q_ib, qn))
    if qm[0] < 0.0:
        qm = -qm
    rate = np.sqrt(omega_b[0] ** 2 + omega_b[1] ** 2 + omega_b[2] ** 2)
    return qm, rate <= max_rate


# --- gyros: ω_g = ω + b + d + n_g, ḋ = −D d + n_d (seed 002 eq 13) ------------------------------


class GaussMarkovDrift:
    """Exact discretisation of the first-order Markov drift ḋ = −d/τ + n_d (seed 002 eq 13).

    ``density`` is the spectral density of n_d in rad/s/√s, so the stationary standard deviation
    is density·√(τ/2); over a step T the drift decays by φ = exp(−T/τ) and gains white noise of
    standard deviation density·√(τ(1 − φ²)/2).
    """

    def __init__(self, tau_s: float | np.ndarray, density_rad_s_sqrt_s: float | np.ndarray, dt_s: float):
        tau = _positive(tau_s, "tau_s") * np.ones(3)
        if np.any(tau == 0.0):
            raise ValueError("tau_s: correlation time must be > 0")
        if not dt_s > 0.0:
            raise ValueError(f"dt_s: must be > 0, got {dt_s}")
        density = _positive(density_rad_s_sqrt_s, "density_rad_s_sqrt_s") * np.ones(3)
        self.decay = np.exp(-dt_s / tau)
        self.stationary_std = density * np.sqrt(0.5 * tau)
        self.step_std = self.stationary_std * np.sqrt(1.0 - self.decay**2)


def gauss_markov_drift(model: GaussMarkovDrift, n_steps: int, drift0: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Drift history d_0 … d_{n−1} (n, 3) of the Markov model starting at ``drift0`` (seed 002 eq 13)."""
    d = np.empty((n_steps, 3))
    d[0] = _vectors(drift0, "drift0")
    w = model.step_std * rng.standard_normal((max(n_steps - 1, 0), 3))
    for k in range(1, n_steps):
        d[k] = model.decay * d[k - 1] + w[k - 1]
    return d


def gyro(
    omega_b_rad_s: np.ndarray,
    bias_rad_s: np.ndarray,
    drift: GaussMarkovDrift,
    noise_std_rad_s: float | np.ndarray,
    range_rad_s: float,
    rng: np.random.Generator,
    drift0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gyro series ω_g = ω + b + d + n_g over samples at the drift model's step (seed 002 eq 13).

    ``omega_b_rad_s`` is (n, 3), one row per sample. ``drift0`` defaults to a draw from the
    stationary distribution. Returns (omega_meas (n, 3), drift (n, 3), valid (n,)); a sample is
    invalid when an axis exceeds the measuring range, where the output saturates.
    """
    omega = _vectors(omega_b_rad_s, "omega_b_rad_s")
    if omega.ndim != 2:
        raise ValueError(f"omega_b_rad_s: expected shape (n, 3), got {omega.shape}")
    bias = _vectors(bias_rad_s, "bias_rad_s")
    sigma = _positive(noise_std_rad_s, "noise_std_rad_s") * np.ones(3)
    _positive(range_rad_s, "range_rad_s")
    d0 = drift.stationary_std * rng.standard_normal(3) if drift0 is None else drift0
    d = gauss_markov_drift(drift, omega.shape[0], d0, rng)
    meas = omega + bias + d + sigma * rng.standard_normal(omega.shape)
    valid = np.all(np.abs(omega) <= range_rad_s, axis=-1)
    meas = np.clip(meas, -range_rad_s, range_rad_s)
    return meas, d, valid


@njit(cache=True)
def gyro_1(
    omega_b: np.ndarray,
    bias_b: np.ndarray,
    drift_b: np.ndarray,
    noise_std3: np.ndarray,
    decay3: np.ndarray,
    step_std3: np.ndarray,
    range_rad_s: float,
    normal6: np.ndarray,
) -> tuple[np.ndarray, bool]:
    """Compiled gyro sample ω + b + d + n_g; advances the drift d in place by one step (seed 002 eq 13).

    ``normal6``: pre-drawn standard normals, [0:3] for n_g and [3:6] for the drift increment;
    ``decay3``/``step_std3`` come from :class:`GaussMarkovDrift`.
    """
    meas = np.empty(3)
    valid = True
    for i in range(3):
        meas[i] = omega_b[i] + bias_b[i] + drift_b[i] + noise_std3[i] * normal6[i]
        drift_b[i] = decay3[i] * drift_b[i] + step_std3[i] * normal6[3 + i]
        if abs(omega_b[i]) > range_rad_s:
            valid = False
        meas[i] = min(max(meas[i], -range_rad_s), range_rad_s)
    return meas, valid
