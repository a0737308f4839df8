"""Attitude sensors: star tracker, gyros, earth sensor, magnetometer, sun sensor, wheel tachometers, GPS.

Every sensor returns its sample and a validity flag (the "data bad/good" flag of seed 003
§3.2.3.1). SI units inside: rad, rad/s, tesla, metres. Quaternions are scalar-first ``q_ib``
(body → inertial, DESIGN.md).

Determinism: the ``*_1`` kernels never draw noise themselves; they take pre-drawn standard
normals, so the caller owns the random stream of each batch variant. Two ways keep a variant's
noise independent of the batch size, the thread count and the order of variants: draw from a
``numpy.random.Generator`` per variant (:func:`variant_generators`, ``SeedSequence(seed).spawn``;
the vectorised functions here take such a Generator), or — inside a compiled loop — seed numba's
per-thread ``np.random`` with the variant's own seed at the start of that variant's run and fly
each variant start to finish on one thread (what ``sim_core.closed_loop`` does).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_core import quaternion as qt

__all__ = [
    "ARCSEC",
    "EARTH_RADIUS_M",
    "variant_generators",
    "rotation_noise_quaternion",
    "star_tracker",
    "star_tracker_1",
    "star_tracker_blinded",
    "star_tracker_blinded_1",
    "GaussMarkovDrift",
    "gauss_markov_drift",
    "gyro",
    "gyro_1",
    "nadir_roll_pitch",
    "nadir_roll_pitch_1",
    "nadir_from_roll_pitch_1",
    "earth_sensor",
    "earth_sensor_1",
    "magnetometer",
    "magnetometer_1",
    "in_earth_shadow",
    "sun_sensor",
    "sun_sensor_1",
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
    n0 = np.cos(0.5 * norm)
    k = np.sin(0.5 * norm) / norm if norm > 0.0 else 0.5
    n1, n2, n3 = k * t0, k * t1, k * t2
    a0, a1, a2, a3 = q_ib[0], q_ib[1], q_ib[2], q_ib[3]
    r0 = a0 * n0 - a1 * n1 - a2 * n2 - a3 * n3
    r1 = a0 * n1 + a1 * n0 + a2 * n3 - a3 * n2
    r2 = a0 * n2 - a1 * n3 + a2 * n0 + a3 * n1
    r3 = a0 * n3 + a1 * n2 - a2 * n1 + a3 * n0
    inv = 1.0 / np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    if r0 < 0.0:
        inv = -inv
    qm = np.empty(4)
    qm[0], qm[1], qm[2], qm[3] = r0 * inv, r1 * inv, r2 * inv, r3 * inv
    rate = np.sqrt(omega_b[0] ** 2 + omega_b[1] ** 2 + omega_b[2] ** 2)
    return qm, rate <= max_rate


def star_tracker_blinded(
    q_ib: np.ndarray, sun_i: np.ndarray, r_i_m: np.ndarray, boresight_b: np.ndarray, exclusion_rad: float
) -> np.ndarray:
    """True where the lit Sun lies inside the star tracker's exclusion cone (data flagged bad, seed 003 §3.2.3.1)."""
    s_i = _vectors(sun_i, "sun_i")
    bore = _vectors(boresight_b, "boresight_b")
    _positive(exclusion_rad, "exclusion_rad")
    bore_i = qt.rotate(qt.normalize(q_ib), bore / np.linalg.norm(bore))
    cos_sep = np.sum(bore_i * s_i, axis=-1) / np.linalg.norm(s_i, axis=-1)
    blinded: npt.NDArray[np.bool_] = (cos_sep > np.cos(exclusion_rad)) & ~in_earth_shadow(r_i_m, s_i)
    return blinded


@njit(cache=True)
def star_tracker_blinded_1(
    q_ib: np.ndarray, sun_i: np.ndarray, r_i: np.ndarray, boresight_b: np.ndarray, cos_exclusion: float
) -> bool:
    """Compiled test of a lit Sun inside the star tracker's exclusion cone (seed 003 §3.2.3.1 data flag)."""
    bore_i = qt.rotate_1(q_ib, boresight_b)
    sn = np.sqrt(sun_i[0] ** 2 + sun_i[1] ** 2 + sun_i[2] ** 2)
    along = (r_i[0] * sun_i[0] + r_i[1] * sun_i[1] + r_i[2] * sun_i[2]) / sn
    p = r_i - along * sun_i / sn
    shadow = along < 0.0 and np.sqrt(p[0] ** 2 + p[1] ** 2 + p[2] ** 2) < EARTH_RADIUS_M
    cos_sep = (bore_i[0] * sun_i[0] + bore_i[1] * sun_i[1] + bore_i[2] * sun_i[2]) / sn
    return cos_sep > cos_exclusion and not shadow


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


def gauss_markov_drift(
    model: GaussMarkovDrift, n_steps: int, drift0: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
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


# --- earth (horizon) sensor: φ_e = φ + φ_b + φ_n, θ_e = θ + θ_b + θ_n (seed 002 eq 14) ----------


def nadir_roll_pitch(q_ib: np.ndarray, r_i_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roll φ2 and pitch φ3 (rad) a horizon sensor sees: the nadir −r̂ in body axes (seed 002 eq 14 inputs).

    With the DESIGN.md orbit frame (x^o to nadir) and C^o = [φ2]_2 [φ3]_3 [φ1]_1 the nadir in body
    axes is n_b = (cos φ3 cos φ2, −sin φ3, cos φ3 sin φ2): roll = atan2(n_z, n_x), pitch = −asin n_y,
    independent of yaw, velocity and the orbit frame's other axes.
    """
    r = _vectors(r_i_m, "r_i_m")
    n_b = qt.rotate(qt.conjugate(qt.normalize(q_ib)), -r / np.linalg.norm(r, axis=-1, keepdims=True))
    return np.arctan2(n_b[..., 2], n_b[..., 0]), np.arcsin(np.clip(-n_b[..., 1], -1.0, 1.0))


@njit(cache=True)
def nadir_roll_pitch_1(q_ib: np.ndarray, r_i: np.ndarray) -> tuple[float, float]:
    """Compiled roll and pitch of the nadir direction in body axes (seed 002 eq 14 inputs)."""
    rn = np.sqrt(r_i[0] ** 2 + r_i[1] ** 2 + r_i[2] ** 2)
    n_b = qt.conjugate_rotate_1(q_ib, -r_i / rn)
    return np.arctan2(n_b[2], n_b[0]), np.arcsin(min(max(-n_b[1], -1.0), 1.0))


@njit(cache=True)
def nadir_from_roll_pitch_1(roll: float, pitch: float) -> np.ndarray:
    """Nadir unit vector in body axes from earth-sensor roll and pitch, n_b = (cos θ cos φ, −sin θ, cos θ sin φ)
    (the inverse of :func:`nadir_roll_pitch_1`, seed 002 eq 14)."""
    nadir = np.empty(3)
    nadir[0] = np.cos(pitch) * np.cos(roll)
    nadir[1] = -np.sin(pitch)
    nadir[2] = np.cos(pitch) * np.sin(roll)
    return nadir


def earth_sensor(
    roll_rad: np.ndarray,
    pitch_rad: np.ndarray,
    bias_rad: np.ndarray,
    noise_std_rad: float | np.ndarray,
    range_rad: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Measured (roll, pitch) = true + constant bias + white noise, invalid outside ±range (seed 002 eq 14).

    Returns (angles (..., 2), valid (...)); ``bias_rad`` is (φ_b, θ_b).
    """
    angles = np.stack(np.broadcast_arrays(np.asarray(roll_rad, float), np.asarray(pitch_rad, float)), axis=-1)
    bias = np.asarray(bias_rad, dtype=float)
    if bias.shape != (2,):
        raise ValueError(f"bias_rad: expected (roll, pitch) shape (2,), got {bias.shape}")
    sigma = _positive(noise_std_rad, "noise_std_rad") * np.ones(2)
    _positive(range_rad, "range_rad")
    meas = angles + bias + sigma * rng.standard_normal(angles.shape)
    return meas, np.all(np.abs(angles) <= range_rad, axis=-1)


@njit(cache=True)
def earth_sensor_1(
    roll: float, pitch: float, bias2: np.ndarray, noise_std2: np.ndarray, range_rad: float, normal2: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Compiled earth-sensor sample (roll, pitch) + bias + noise from pre-drawn normals (seed 002 eq 14)."""
    meas = np.empty(2)
    meas[0] = roll + bias2[0] + noise_std2[0] * normal2[0]
    meas[1] = pitch + bias2[1] + noise_std2[1] * normal2[1]
    return meas, abs(roll) <= range_rad and abs(pitch) <= range_rad


# --- magnetometer: B_b = Λ̃ ∘ B_i ∘ Λ + bias + noise (seed 003 §3.2.1.2.1, MAG) ------------------


def magnetometer(
    q_ib: np.ndarray,
    b_i_t: np.ndarray,
    bias_b_t: np.ndarray,
    noise_std_t: float,
    range_t: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Field in body axes B_b = Λ̃∘B_i∘Λ + bias + noise (T); invalid when an axis saturates (seed 003 MAG)."""
    q = qt.normalize(q_ib)
    b_i = _vectors(b_i_t, "b_i_t")
    bias = _vectors(bias_b_t, "bias_b_t")
    sigma = float(_positive(noise_std_t, "noise_std_t"))
    _positive(range_t, "range_t")
    b_b = (
        qt.rotate(qt.conjugate(q), b_i)
        + bias
        + sigma * rng.standard_normal(np.broadcast_shapes(q.shape[:-1] + (3,), b_i.shape))
    )
    valid = np.all(np.abs(b_b) <= range_t, axis=-1)
    return np.clip(b_b, -range_t, range_t), valid


@njit(cache=True)
def magnetometer_1(
    q_ib: np.ndarray, b_i: np.ndarray, bias_b: np.ndarray, noise_std: float, range_t: float, normal3: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Compiled magnetometer sample Λ̃∘B_i∘Λ + bias + noise, saturating at ±range (seed 003 MAG)."""
    b_b = qt.conjugate_rotate_1(q_ib, b_i)
    valid = True
    for i in range(3):
        b_b[i] += bias_b[i] + noise_std * normal3[i]
        if abs(b_b[i]) > range_t:
            valid = False
            b_b[i] = min(max(b_b[i], -range_t), range_t)
    return b_b, valid


# --- sun sensor: eclipse-aware unit Sun vector in body axes (seed 003 §3.2.1.2.1, SS) ------------


def in_earth_shadow(r_i_m: np.ndarray, sun_i: np.ndarray) -> np.ndarray:
    """True where r_i is in Earth's cylindrical shadow, the eclipse of seed 003 §1 (sun sensor data bad).

    Cylindrical model: behind the Earth (⟨r, ŝ⟩ < 0) and within one Earth radius of the Sun line.
    """
    r = _vectors(r_i_m, "r_i_m")
    s = _vectors(sun_i, "sun_i")
    s = s / np.linalg.norm(s, axis=-1, keepdims=True)
    along = np.sum(r * s, axis=-1)
    perp = np.linalg.norm(r - along[..., None] * s, axis=-1)
    shadowed: npt.NDArray[np.bool_] = (along < 0.0) & (perp < EARTH_RADIUS_M)
    return shadowed


def sun_sensor(
    q_ib: np.ndarray,
    sun_i: np.ndarray,
    r_i_m: np.ndarray,
    boresight_b: np.ndarray,
    half_fov_rad: float,
    noise_std_rad: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Unit Sun vector in body axes with angular noise; invalid in eclipse or outside the field of view (seed 003)."""
    q = qt.normalize(q_ib)
    s_i = _vectors(sun_i, "sun_i")
    bore = _vectors(boresight_b, "boresight_b")
    bore = bore / np.linalg.norm(bore)
    sigma = float(_positive(noise_std_rad, "noise_std_rad"))
    _positive(half_fov_rad, "half_fov_rad")
    s_b = qt.rotate(qt.conjugate(q), s_i / np.linalg.norm(s_i, axis=-1, keepdims=True))
    theta = sigma * rng.standard_normal(s_b.shape)
    s_b = qt.rotate(rotation_noise_quaternion(theta), s_b)
    visible = np.sum(s_b * bore, axis=-1) >= np.cos(half_fov_rad)
    return s_b, visible & ~in_earth_shadow(r_i_m, s_i)


@njit(cache=True)
def sun_sensor_1(
    q_ib: np.ndarray,
    sun_i: np.ndarray,
    r_i: np.ndarray,
    boresight_b: np.ndarray,
    cos_half_fov: float,
    noise_std: float,
    normal3: np.ndarray,
) -> tuple[np.ndarray, bool]:
    """Compiled sun-sensor sample: noisy unit Sun vector in body axes and its eclipse/FOV validity (seed 003 SS)."""
    sn = np.sqrt(sun_i[0] ** 2 + sun_i[1] ** 2 + sun_i[2] ** 2)
    s = sun_i / sn
    s_b = qt.conjugate_rotate_1(q_ib, s)
    t = noise_std * normal3
    tn = np.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2)
    qn = np.empty(4)
    qn[0] = np.cos(0.5 * tn)
    k = np.sin(0.5 * tn) / tn if tn > 0.0 else 0.5
    qn[1:] = k * t
    s_b = qt.rotate_1(qn, s_b)
    along = r_i[0] * s[0] + r_i[1] * s[1] + r_i[2] * s[2]
    p = r_i - along * s
    shadow = along < 0.0 and np.sqrt(p[0] ** 2 + p[1] ** 2 + p[2] ** 2) < EARTH_RADIUS_M
    visible = s_b[0] * boresight_b[0] + s_b[1] * boresight_b[1] + s_b[2] * boresight_b[2] >= cos_half_fov
    return s_b, visible and not shadow


# --- wheel tachometers: speed quantisation (seed 003 §3.2.3.1 conversion to physical units) ------


def wheel_tachometer(
    speed_rad_s: np.ndarray, resolution_rad_s: float, max_speed_rad_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Quantised wheel speed round(Ω/q)·q with q the resolution; invalid beyond the speed range (seed 003 §3.2.3.1)."""
    speed = np.asarray(speed_rad_s, dtype=float)
    if not np.all(np.isfinite(speed)):
        raise ValueError("speed_rad_s: contains NaN or infinite values")
    if not resolution_rad_s > 0.0:
        raise ValueError(f"resolution_rad_s: must be > 0, got {resolution_rad_s}")
    _positive(max_speed_rad_s, "max_speed_rad_s")
    return np.round(speed / resolution_rad_s) * resolution_rad_s, np.abs(speed) <= max_speed_rad_s


@njit(cache=True)
def wheel_tachometer_1(speed: np.ndarray, resolution: float, max_speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Compiled quantised wheel speeds and per-wheel validity (seed 003 §3.2.3.1)."""
    out = np.empty_like(speed)
    valid = np.empty(speed.shape[0], dtype=np.bool_)
    for i in range(speed.shape[0]):
        out[i] = np.round(speed[i] / resolution) * resolution
        valid[i] = abs(speed[i]) <= max_speed
    return out, valid


# --- GPS receiver: position and velocity with white noise and dropouts (seed 003 §3.2.1.1) -------


def gps_receiver(
    r_m: np.ndarray,
    v_m_s: np.ndarray,
    sigma_r_m: float,
    sigma_v_m_s: float,
    dropout_probability: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GPS fix (r, v) with white noise; each fix is lost with the given probability (seed 003 §3.2.1.1)."""
    r = _vectors(r_m, "r_m")
    v = _vectors(v_m_s, "v_m_s")
    if r.shape != v.shape:
        raise ValueError(f"v_m_s: shape {v.shape} differs from r_m {r.shape}")
    sr = float(_positive(sigma_r_m, "sigma_r_m"))
    sv = float(_positive(sigma_v_m_s, "sigma_v_m_s"))
    if not 0.0 <= dropout_probability <= 1.0:
        raise ValueError(f"dropout_probability: must be in [0, 1], got {dropout_probability}")
    r_meas = r + sr * rng.standard_normal(r.shape)
    v_meas = v + sv * rng.standard_normal(v.shape)
    valid = rng.random(r.shape[:-1]) >= dropout_probability
    return r_meas, v_meas, valid
