"""Space environment along an orbit: geomagnetic field, Sun, eclipse and disturbance torques.

Seed 000 eq (1) needs the magnetic induction B for the magnetic driver (M^m = −L × B, in the BRF)
and the external disturbance torque M^d; seed 003 uses B for magnetorquers and B-dot. Models:

* Geomagnetic field: IGRF-14 with the coefficients ``ppigrf`` ships and reads, synthesised by our
  compiled kernel ``magnetic_igrf_1`` (≈ 1.3 µs a point, 50× faster than ppigrf's numpy synthesis,
  equal to it within 1e-9 nT); one coefficient date per hourly chunk (secular variation ≤ 0.01 nT
  per half hour). Or a centred tilted dipole from IGRF's degree-1 coefficients at the same date
  (``magnetic_dipole_1``; at LEO it departs from IGRF by up to ~20 %).
* Sun: skyfield with the DE421 ephemeris shipped by ``skyfield-data`` (offline), or the Astronomical
  Almanac's low-precision formula (≈ 0.01°, 1950–2050), mean equinox of date, rotated to GCRS by the
  IAU 1976 precession (``sun_position_1``).
* Eclipse: conical Earth shadow with the penumbral overlap of the solar and Earth disks
  (Montenbruck & Gill, *Satellite Orbits*, §3.4.2).
* Gravity-gradient torque 3μ/r³ r̂ × (J r̂) in body axes (Wertz, *Spacecraft Attitude Determination
  and Control*, eq 17-38).
* Aerodynamic torque: flat plates in free-molecular flow, F = −½ ρ C_D A cos θ |v| v for plates
  facing the flow, the atmosphere co-rotating with the Earth, density from the piecewise
  exponential model of Vallado (*Fundamentals of Astrodynamics*, Table 8-4).
* Solar-radiation-pressure torque: flat plates with absorbed, specular and diffuse fractions,
  P = 4.56e-6 N/m² at 1 AU (Wertz eq 17-52 / Montenbruck & Gill eq 3.73), scaled by the
  illuminated fraction.
"""

from __future__ import annotations

import datetime as dt
import functools
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_core import frames, quaternion
from sim_core.orbit import MU_EARTH_M3_S2
from sim_core.quaternion import dot3_floats

__all__ = [
    "IGRF_REFERENCE_RADIUS_M",
    "R_SUN_M",
    "AU_M",
    "SOLAR_PRESSURE_1AU_N_M2",
    "magnetic_field_ecef_t",
    "magnetic_field_eci_t",
    "magnetic_field_body_t",
    "dipole_coefficients_t",
    "igrf_coefficients_t",
    "sun_position_eci_m",
    "illumination_fraction",
    "atmosphere_density_kg_m3",
    "gravity_gradient_torque_nm",
    "aerodynamic_torque_nm",
    "solar_pressure_torque_nm",
    "magnetic_igrf_1",
    "magnetic_dipole_1",
    "magnetic_dipole_eci_1",
    "sun_position_1",
    "illumination_1",
    "atmosphere_density_1",
    "gravity_gradient_torque_1",
    "add_gravity_gradient_torque_into",
    "aerodynamic_torque_1",
    "solar_pressure_torque_1",
    "EARTH_ROTATION_RAD_S",
    "add_aerodynamic_torque_orbit_into",
    "add_solar_pressure_torque_orbit_into",
    "field_table_into",
]

IGRF_REFERENCE_RADIUS_M = 6371.2e3
R_SUN_M = 6.957e8  # IAU 2015 nominal solar radius
AU_M = 1.495978707e11
SOLAR_PRESSURE_1AU_N_M2 = 4.56e-6  # 1361 W/m² / c
EARTH_ROTATION_RAD_S = 7.292115e-5  # IERS mean angular velocity: the atmosphere co-rotates
_CHUNK_S = 3600.0  # one IGRF date per hour of data
_MODELS = ("igrf", "dipole")
_IGRF_NMAX = 13
# Schmidt recursion constants K[n, m] = √(n² − m²) (0 where m ≥ n), tabulated once for the kernel.
_SCHMIDT_K = np.sqrt(
    np.maximum(np.subtract.outer(np.arange(_IGRF_NMAX + 1) ** 2, np.arange(_IGRF_NMAX + 1) ** 2), 0).astype(float)
)
_R_EARTH_M = frames.WGS84_A_M

# Vallado Table 8-4: base altitude (m), base density (kg/m³), scale height (m).
_ATMOSPHERE_TABLE = np.array(
    [
        [0, 1.225, 7.249],
        [25, 3.899e-2, 6.349],
        [30, 1.774e-2, 6.682],
        [40, 3.972e-3, 7.554],
        [50, 1.057e-3, 8.382],
        [60, 3.206e-4, 7.714],
        [70, 8.770e-5, 6.549],
        [80, 1.905e-5, 5.799],
        [90, 3.396e-6, 5.382],
        [100, 5.297e-7, 5.877],
        [110, 9.661e-8, 7.263],
        [120, 2.438e-8, 9.473],
        [130, 8.484e-9, 12.636],
        [140, 3.845e-9, 16.149],
        [150, 2.070e-9, 22.523],
        [180, 5.464e-10, 29.740],
        [200, 2.789e-10, 37.105],
        [250, 7.248e-11, 45.546],
        [300, 2.418e-11, 53.628],
        [350, 9.518e-12, 53.298],
        [400, 3.725e-12, 58.515],
        [450, 1.585e-12, 60.828],
        [500, 6.967e-13, 63.822],
        [600, 1.454e-13, 71.835],
        [700, 3.614e-14, 88.667],
        [800, 1.170e-14, 124.64],
        [900, 5.245e-15, 181.05],
        [1000, 3.019e-15, 268.00],
    ]
) * np.array([1e3, 1.0, 1e3])


def _vectors(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected shape (..., 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return v


def _times(t: np.ndarray | float, name: str = "t_unix_s") -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return t


# --- geomagnetic field --------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def _igrf_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IGRF-14 as ppigrf reads it: epochs (Unix s), g[e, n, m] and h[e, n, m] (T), loaded once."""
    from ppigrf.ppigrf import read_shc, shc_fn

    g_frame, h_frame = read_shc(shc_fn)
    epochs = np.array([d.replace(tzinfo=dt.UTC).timestamp() for d in g_frame.index])
    size = 1 + max(n for n, _ in g_frame.columns)
    g, h = np.zeros((epochs.size, size, size)), np.zeros((epochs.size, size, size))
    for n, m in g_frame.columns:
        g[:, n, m] = g_frame[(n, m)].to_numpy() * 1e-9
        h[:, n, m] = h_frame[(n, m)].to_numpy() * 1e-9
    return epochs, g, h


def _check_igrf_span(t_unix_s: np.ndarray) -> None:
    epochs = _igrf_table()[0]
    if np.any(t_unix_s < epochs[0]) or np.any(t_unix_s > epochs[-1]):
        first, last = (dt.datetime.fromtimestamp(e, dt.UTC).date() for e in (epochs[0], epochs[-1]))
        raise ValueError(f"t_unix_s: IGRF-14 covers {first} to {last}")


def igrf_coefficients_t(t_unix_s: float) -> tuple[np.ndarray, np.ndarray]:
    """IGRF-14 Schmidt semi-normalised Gauss coefficients g[n, m], h[n, m] (T) at t, linear in time."""
    t = float(_times(t_unix_s))
    _check_igrf_span(np.array([t]))
    epochs, g, h = _igrf_table()
    k = int(np.clip(np.searchsorted(epochs, t, side="right") - 1, 0, epochs.size - 2))
    f = (t - epochs[k]) / (epochs[k + 1] - epochs[k])
    return (1.0 - f) * g[k] + f * g[k + 1], (1.0 - f) * h[k] + f * h[k + 1]


def dipole_coefficients_t(t_unix_s: float) -> np.ndarray:
    """IGRF-14 degree-1 Gauss coefficients as the ECEF vector g = (g11, h11, g10) in tesla at t."""
    g, h = igrf_coefficients_t(t_unix_s)
    return np.array([g[1, 1], h[1, 1], g[1, 0]])


def magnetic_field_ecef_t(r_ecef_m: np.ndarray, t_unix_s: np.ndarray | float, model: str = "igrf") -> np.ndarray:
    """Geomagnetic induction B (T) in ECEF at ECEF positions (IGRF-14 or tilted dipole), shape (N, 3)."""
    if model not in _MODELS:
        raise ValueError(f"model: expected one of {_MODELS}, got {model!r}")
    r = _vectors(r_ecef_m, "r_ecef_m").reshape(-1, 3)
    t = np.broadcast_to(_times(t_unix_s), r.shape[:1])
    if np.any(np.linalg.norm(r, axis=1) < 0.5 * frames.WGS84_A_M):
        raise ValueError("r_ecef_m: positions must lie outside the Earth's core (|r| > 3,189 km)")
    _check_igrf_span(t)
    out = np.empty_like(r)
    chunk = np.floor((t - t.min()) / _CHUNK_S)
    for c in np.unique(chunk):
        idx = np.flatnonzero(chunk == c)
        t_mid = float(0.5 * (t[idx].min() + t[idx].max()))
        if model == "dipole":
            out[idx] = _dipole_many(np.ascontiguousarray(r[idx]), dipole_coefficients_t(t_mid))
            continue
        g, h = igrf_coefficients_t(t_mid)
        out[idx] = _igrf_many(np.ascontiguousarray(r[idx]), g, h)
    return out


def magnetic_field_eci_t(r_eci_m: np.ndarray, t_unix_s: np.ndarray | float, model: str = "igrf") -> np.ndarray:
    """Geomagnetic induction B (T) in ECI at ECI positions along an orbit, shape (N, 3)."""
    r = _vectors(r_eci_m, "r_eci_m").reshape(-1, 3)
    t = np.broadcast_to(_times(t_unix_s), r.shape[:1])
    m = frames.eci_to_ecef_matrix(t)
    b_ecef = magnetic_field_ecef_t(np.einsum("nij,nj->ni", m, r), t, model)
    b_body_t: npt.NDArray[np.float64] = np.einsum("nji,nj->ni", m, b_ecef)
    return b_body_t


def magnetic_field_body_t(
    r_eci_m: np.ndarray, t_unix_s: np.ndarray | float, q_ib: np.ndarray, model: str = "igrf"
) -> np.ndarray:
    """Geomagnetic induction B (T) in body axes, b_B = Λ̃ ∘ B_I ∘ Λ (the B of seed 000 eq 1)."""
    q = quaternion.normalize(q_ib)
    return quaternion.rotate(quaternion.conjugate(q), magnetic_field_eci_t(r_eci_m, t_unix_s, model))


@njit(cache=True)
def magnetic_igrf_1(r_ecef_m: np.ndarray, g_t: np.ndarray, h_t: np.ndarray) -> np.ndarray:
    """IGRF spherical-harmonic synthesis B = −∇V in ECEF (T) at one ECEF position (compiled kernel).

    V = a Σₙ (a/r)ⁿ⁺¹ Σₘ (gₙᵐ cos mφ + hₙᵐ sin mφ) Pₙᵐ(cos θ) with Schmidt semi-normalised Pₙᵐ by the
    standard recursions (Langel 1987); geocentric r, colatitude θ, longitude φ.
    """
    nmax = min(g_t.shape[0] - 1, _IGRF_NMAX)
    r = np.sqrt(r_ecef_m[0] ** 2 + r_ecef_m[1] ** 2 + r_ecef_m[2] ** 2)
    rho = np.sqrt(r_ecef_m[0] ** 2 + r_ecef_m[1] ** 2)
    st, ct = max(rho / r, 1e-12), r_ecef_m[2] / r  # 1e-12: the pole's longitude limit, < 1e-5 m off
    phi = np.arctan2(r_ecef_m[1], r_ecef_m[0])
    p = np.zeros((nmax + 1, nmax + 1))
    dp = np.zeros((nmax + 1, nmax + 1))
    p[0, 0] = 1.0
    for n in range(1, nmax + 1):
        if n == 1:
            p[1, 1], dp[1, 1] = st, ct
        else:
            f = np.sqrt((2.0 * n - 1.0) / (2.0 * n))
            p[n, n] = f * st * p[n - 1, n - 1]
            dp[n, n] = f * (st * dp[n - 1, n - 1] + ct * p[n - 1, n - 1])
        for m in range(n):  # p[n-2, m] = 0 for m = n-1 (array zero-filled), and then K1 = 0 too
            k0, k1 = _SCHMIDT_K[n, m], _SCHMIDT_K[n - 1, m]
            p[n, m] = ((2.0 * n - 1.0) * ct * p[n - 1, m] - k1 * p[n - 2, m]) / k0
            dp[n, m] = ((2.0 * n - 1.0) * (ct * dp[n - 1, m] - st * p[n - 1, m]) - k1 * dp[n - 2, m]) / k0
    cp, sp = np.cos(phi), np.sin(phi)
    cos_m, sin_m = np.empty(nmax + 1), np.empty(nmax + 1)
    cos_m[0], sin_m[0] = 1.0, 0.0
    for m in range(1, nmax + 1):  # cos mφ, sin mφ by the angle-addition recursion
        cos_m[m] = cos_m[m - 1] * cp - sin_m[m - 1] * sp
        sin_m[m] = sin_m[m - 1] * cp + cos_m[m - 1] * sp
    b_r = b_t = b_p = 0.0
    ratio = IGRF_REFERENCE_RADIUS_M / r
    scale = ratio * ratio
    for n in range(1, nmax + 1):
        scale *= ratio  # (a/r)^(n+2)
        for m in range(n + 1):
            gh = g_t[n, m] * cos_m[m] + h_t[n, m] * sin_m[m]
            b_r += scale * (n + 1.0) * gh * p[n, m]
            b_t -= scale * gh * dp[n, m]
            b_p += scale * m * (g_t[n, m] * sin_m[m] - h_t[n, m] * cos_m[m]) * p[n, m] / st
    out = np.empty(3)
    out[0] = (b_r * st + b_t * ct) * cp - b_p * sp
    out[1] = (b_r * st + b_t * ct) * sp + b_p * cp
    out[2] = b_r * ct - b_t * st
    return out


@njit(cache=True)
def _igrf_many(r_ecef_m: np.ndarray, g_t: np.ndarray, h_t: np.ndarray) -> np.ndarray:
    out = np.empty_like(r_ecef_m)
    for k in range(r_ecef_m.shape[0]):
        out[k] = magnetic_igrf_1(r_ecef_m[k], g_t, h_t)
    return out


@njit(cache=True)
def magnetic_dipole_1(r_ecef_m: np.ndarray, g_t: np.ndarray) -> np.ndarray:
    """Centred tilted dipole B = (a/r)³ [3 (g·r̂) r̂ − g] in ECEF (T), g = (g11, h11, g10) (compiled)."""
    r = np.sqrt(r_ecef_m[0] ** 2 + r_ecef_m[1] ** 2 + r_ecef_m[2] ** 2)
    k = (IGRF_REFERENCE_RADIUS_M / r) ** 3
    gu3 = 3.0 * (g_t[0] * r_ecef_m[0] + g_t[1] * r_ecef_m[1] + g_t[2] * r_ecef_m[2]) / (r * r)
    b = np.empty(3)
    for i in range(3):
        b[i] = k * (gu3 * r_ecef_m[i] - g_t[i])
    return b


@njit(cache=True)
def magnetic_dipole_eci_1(
    r_eci_m: np.ndarray, t_ut1_unix_s: float, g_t: np.ndarray, c_pn: np.ndarray, w_pm: np.ndarray
) -> np.ndarray:
    """Tilted-dipole B (T) in ECI at an ECI position: ECI → ECEF (frozen C, W), dipole, back (compiled)."""
    era = frames.earth_rotation_angle_1(t_ut1_unix_s)
    b_ecef = magnetic_dipole_1(frames.eci_to_ecef_1(r_eci_m, c_pn, w_pm, era), g_t)
    return frames.ecef_to_eci_1(b_ecef, c_pn, w_pm, era)


@njit(cache=True)
def _dipole_many(r_ecef_m: np.ndarray, g_t: np.ndarray) -> np.ndarray:
    out = np.empty_like(r_ecef_m)
    for k in range(r_ecef_m.shape[0]):
        out[k] = magnetic_dipole_1(r_ecef_m[k], g_t)
    return out


# --- Sun ------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def _ephemeris() -> Any:  # a skyfield SpiceKernel (skyfield is untyped)
    """DE421 from skyfield-data (offline), loaded once."""
    from skyfield.api import load_file

    return load_file(str(frames.skyfield_data_path() / "de421.bsp"))


def sun_position_eci_m(t_unix_s: np.ndarray | float) -> np.ndarray:
    """Apparent geocentric Sun position (m) in GCRS from DE421 via skyfield, shape (..., 3)."""
    t = _times(t_unix_s)
    eph = _ephemeris()
    sky = frames.skyfield_time(np.atleast_1d(t).ravel())
    pos = eph["earth"].at(sky).observe(eph["sun"]).apparent().position.m
    return np.moveaxis(np.asarray(pos), 0, -1).reshape(t.shape + (3,))


@njit(cache=True)
def sun_position_1(t_unix_s: float) -> np.ndarray:
    """Low-precision Sun (Astronomical Almanac C5, ≈ 0.01°) in GCRS (m): mean of date → J2000 by IAU 1976 precession."""
    n = (t_unix_s - 946728000.0) / 86400.0  # days from J2000.0 (UTC ≈ TT to 69 s: 3e-5°)
    deg = np.pi / 180.0
    g = ((357.528 + 0.9856003 * n) % 360.0) * deg
    lam = ((280.460 + 0.9856474 * n) % 360.0) * deg + 1.915 * deg * np.sin(g) + 0.020 * deg * np.sin(2.0 * g)
    eps = (23.439 - 0.0000004 * n) * deg
    dist = AU_M * (1.00014 - 0.01671 * np.cos(g) - 0.00014 * np.cos(2.0 * g))
    u0, u1, u2 = np.cos(lam), np.cos(eps) * np.sin(lam), np.sin(eps) * np.sin(lam)
    big_t = n / 36525.0
    arcsec = deg / 3600.0
    zeta = (2306.2181 + (0.30188 + 0.017998 * big_t) * big_t) * big_t * arcsec
    z = (2306.2181 + (1.09468 + 0.018203 * big_t) * big_t) * big_t * arcsec
    theta = (2004.3109 - (0.42665 + 0.041833 * big_t) * big_t) * big_t * arcsec
    # r_date = P r_J2000 with P = R3(−z) R2(θ) R3(−ζ) (Lieske 1977): r_J2000 = Pᵗ r_date.
    cz, sz, ct, st, cs, ss = np.cos(z), np.sin(z), np.cos(theta), np.sin(theta), np.cos(zeta), np.sin(zeta)
    out = np.empty(3)
    out[0] = dist * ((cz * ct * cs - sz * ss) * u0 + (sz * ct * cs + cz * ss) * u1 + st * cs * u2)
    out[1] = dist * ((-cz * ct * ss - sz * cs) * u0 + (-sz * ct * ss + cz * cs) * u1 - st * ss * u2)
    out[2] = dist * (-cz * st * u0 - sz * st * u1 + ct * u2)
    return out


# --- eclipse --------------------------------------------------------------------------------------


@njit(cache=True)
def illumination_1(r_sat_eci_m: np.ndarray, r_sun_eci_m: np.ndarray) -> float:
    """Sunlit fraction ν ∈ [0, 1] of the solar disk seen from the spacecraft, conical shadow (M&G §3.4.2)."""
    d0, d1, d2 = r_sun_eci_m[0] - r_sat_eci_m[0], r_sun_eci_m[1] - r_sat_eci_m[1], r_sun_eci_m[2] - r_sat_eci_m[2]
    rs = np.sqrt(r_sat_eci_m[0] ** 2 + r_sat_eci_m[1] ** 2 + r_sat_eci_m[2] ** 2)
    dn = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    a = np.arcsin(min(1.0, R_SUN_M / dn))
    b = np.arcsin(min(1.0, _R_EARTH_M / rs))
    cos_c = -(r_sat_eci_m[0] * d0 + r_sat_eci_m[1] * d1 + r_sat_eci_m[2] * d2) / (rs * dn)
    if cos_c <= np.cos(a + b):
        return 1.0
    c = np.arccos(max(-1.0, min(1.0, cos_c)))
    if c >= a + b:
        return 1.0
    if c <= b - a:
        return 0.0
    if c <= a - b:
        return float(1.0 - (b * b) / (a * a))
    x = (c * c + a * a - b * b) / (2.0 * c)
    y = np.sqrt(max(0.0, a * a - x * x))
    area = a * a * np.arccos(max(-1.0, min(1.0, x / a))) + b * b * np.arccos(max(-1.0, min(1.0, (c - x) / b))) - c * y
    return float(1.0 - area / (np.pi * a * a))


def illumination_fraction(r_sat_eci_m: np.ndarray, r_sun_eci_m: np.ndarray) -> np.ndarray:
    """Sunlit fraction of the solar disk (0 umbra, 1 full Sun) along an orbit, conical shadow, shape (N,)."""
    r = _vectors(r_sat_eci_m, "r_sat_eci_m").reshape(-1, 3)
    s = np.ascontiguousarray(np.broadcast_to(_vectors(r_sun_eci_m, "r_sun_eci_m").reshape(-1, 3), r.shape))
    return _illumination_many(np.ascontiguousarray(r), s)


@njit(cache=True)
def _illumination_many(r_sat_eci_m: np.ndarray, r_sun_eci_m: np.ndarray) -> np.ndarray:
    out = np.empty(r_sat_eci_m.shape[0])
    for k in range(out.size):
        out[k] = illumination_1(r_sat_eci_m[k], r_sun_eci_m[k])
    return out


# --- atmosphere -----------------------------------------------------------------------------------


@njit(cache=True)
def atmosphere_density_1(alt_m: float) -> float:
    """Piecewise exponential density ρ0 exp(−(h − h0)/H) (kg/m³), Vallado Table 8-4 (top layer continues)."""
    k = 0
    for i in range(_ATMOSPHERE_TABLE.shape[0]):
        if alt_m >= _ATMOSPHERE_TABLE[i, 0]:
            k = i
    return float(_ATMOSPHERE_TABLE[k, 1] * np.exp(-(alt_m - _ATMOSPHERE_TABLE[k, 0]) / _ATMOSPHERE_TABLE[k, 2]))


def atmosphere_density_kg_m3(alt_m: np.ndarray | float) -> np.ndarray:
    """Exponential-model atmospheric density (Vallado Table 8-4) at ellipsoidal heights ≥ 0 m."""
    h = _times(alt_m, "alt_m")
    if np.any(h < 0.0):
        raise ValueError("alt_m: the exponential model starts at sea level (alt_m ≥ 0)")
    density_kg_m3: npt.NDArray[np.float64] = np.vectorize(atmosphere_density_1, otypes=[float])(h)
    return density_kg_m3


# --- disturbance torques --------------------------------------------------------------------------


@njit(cache=True)
def _gravity_gradient_components(r_b_m: np.ndarray, inertia_kg_m2: np.ndarray) -> tuple[float, float, float]:
    """Gravity-gradient torque 3μ/r³ r̂ × (J r̂) (N·m) as three floats, r = position in body axes (Wertz eq 17-38)."""
    r2 = r_b_m[0] ** 2 + r_b_m[1] ** 2 + r_b_m[2] ** 2
    k = 3.0 * MU_EARTH_M3_S2 / (r2 * r2 * np.sqrt(r2))  # 3μ/r⁵ with r (not r̂) in the products
    j = inertia_kg_m2
    j0 = j[0, 0] * r_b_m[0] + j[0, 1] * r_b_m[1] + j[0, 2] * r_b_m[2]
    j1 = j[1, 0] * r_b_m[0] + j[1, 1] * r_b_m[1] + j[1, 2] * r_b_m[2]
    j2 = j[2, 0] * r_b_m[0] + j[2, 1] * r_b_m[1] + j[2, 2] * r_b_m[2]
    return k * (r_b_m[1] * j2 - r_b_m[2] * j1), k * (r_b_m[2] * j0 - r_b_m[0] * j2), k * (r_b_m[0] * j1 - r_b_m[1] * j0)


@njit(cache=True)
def gravity_gradient_torque_1(r_b_m: np.ndarray, inertia_kg_m2: np.ndarray) -> np.ndarray:
    """Gravity-gradient torque 3μ/r³ r̂ × (J r̂) (N·m), r = position in body axes (Wertz eq 17-38)."""
    out = np.empty(3)
    out[0], out[1], out[2] = _gravity_gradient_components(r_b_m, inertia_kg_m2)
    return out


@njit(cache=True)
def add_gravity_gradient_torque_into(r_b_m: np.ndarray, inertia_kg_m2: np.ndarray, torque_nm: np.ndarray) -> None:
    """``torque_nm`` += :func:`gravity_gradient_torque_1` without allocating (the flight loop, every step)."""
    t0, t1, t2 = _gravity_gradient_components(r_b_m, inertia_kg_m2)
    torque_nm[0] += t0
    torque_nm[1] += t1
    torque_nm[2] += t2


@njit(cache=True)
def _gravity_gradient_many(r_b_m: np.ndarray, inertia_kg_m2: np.ndarray) -> np.ndarray:
    out = np.empty_like(r_b_m)
    for k in range(r_b_m.shape[0]):
        out[k] = gravity_gradient_torque_1(r_b_m[k], inertia_kg_m2)
    return out


def gravity_gradient_torque_nm(r_eci_m: np.ndarray, q_ib: np.ndarray, inertia_kg_m2: np.ndarray) -> np.ndarray:
    """Gravity-gradient torque in body axes (N·m) along an orbit: r_B = Λ̃ ∘ r_I ∘ Λ, then 3μ/r³ r̂ × J r̂."""
    r = _vectors(r_eci_m, "r_eci_m")
    j = np.asarray(inertia_kg_m2, dtype=float)
    if j.shape != (3, 3) or not np.all(np.isfinite(j)) or not np.allclose(j, j.T):
        raise ValueError("inertia_kg_m2: expected a finite symmetric (3, 3) matrix")
    if np.any(np.linalg.eigvalsh(j) <= 0.0):
        raise ValueError("inertia_kg_m2: must be positive definite")
    r_b = quaternion.rotate(quaternion.conjugate(quaternion.normalize(q_ib)), r)
    return _gravity_gradient_many(np.ascontiguousarray(r_b.reshape(-1, 3)), j).reshape(r_b.shape)


@njit(cache=True)
def _plate_moment(centroids_b_m: np.ndarray, i: int, f0: float, f1: float, f2: float) -> tuple[float, float, float]:
    """c_i × F: the moment about the centre of mass of a force F on plate i (body axes, three floats)."""
    c0, c1, c2 = centroids_b_m[i, 0], centroids_b_m[i, 1], centroids_b_m[i, 2]
    return c1 * f2 - c2 * f1, c2 * f0 - c0 * f2, c0 * f1 - c1 * f0


@njit(cache=True)
def _drag_plates(
    w0: float,
    w1: float,
    w2: float,
    density_kg_m3: float,
    drag_coefficient: float,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
) -> tuple[float, float, float]:
    """Σ c_i × (−½ ρ C_D A_i cos θ_i |w| w) over the plates facing the flow w = (w0, w1, w2), body axes, three
    floats."""
    t0 = t1 = t2 = 0.0
    speed = np.sqrt(dot3_floats(w0, w1, w2, w0, w1, w2))
    if speed == 0.0:
        return t0, t1, t2
    for i in range(areas_m2.size):
        cos_t = dot3_floats(normals_b[i, 0], normals_b[i, 1], normals_b[i, 2], w0, w1, w2) / speed
        if cos_t > 0.0:
            k = -0.5 * density_kg_m3 * drag_coefficient * areas_m2[i] * cos_t * speed
            f0, f1, f2 = k * w0, k * w1, k * w2
            m0, m1, m2 = _plate_moment(centroids_b_m, i, f0, f1, f2)
            t0, t1, t2 = t0 + m0, t1 + m1, t2 + m2
    return t0, t1, t2


@njit(cache=True)
def _radiation_plates(
    s0: float,
    s1: float,
    s2: float,
    pressure_n_m2: float,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
    specular: np.ndarray,
    diffuse: np.ndarray,
) -> tuple[float, float, float]:
    """Σ c_i × F_i, F_i = −P A_i cos θ_i [(1 − ρs) ŝ + 2(ρs cos θ_i + ρd/3) n̂_i] over the sunlit plates, Sun
    direction ŝ = (s0, s1, s2) (body axes), three floats."""
    t0 = t1 = t2 = 0.0
    for i in range(areas_m2.size):
        n0, n1, n2 = normals_b[i, 0], normals_b[i, 1], normals_b[i, 2]
        cos_t = dot3_floats(n0, n1, n2, s0, s1, s2)
        if cos_t > 0.0:
            k = -pressure_n_m2 * areas_m2[i] * cos_t
            absorbed = 1.0 - specular[i]
            normal = 2.0 * (specular[i] * cos_t + diffuse[i] / 3.0)
            f0, f1, f2 = (
                k * (absorbed * s0 + normal * n0),
                k * (absorbed * s1 + normal * n1),
                k * (absorbed * s2 + normal * n2),
            )
            m0, m1, m2 = _plate_moment(centroids_b_m, i, f0, f1, f2)
            t0, t1, t2 = t0 + m0, t1 + m1, t2 + m2
    return t0, t1, t2


@njit(cache=True)
def aerodynamic_torque_1(
    v_rel_b_m_s: np.ndarray,
    density_kg_m3: float,
    drag_coefficient: float,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
) -> np.ndarray:
    """Flat-plate free-molecular drag torque Σ c_i × (−½ ρ C_D A_i cos θ_i |v| v) (N·m, body axes)."""
    torque = np.empty(3)
    torque[0], torque[1], torque[2] = _drag_plates(
        v_rel_b_m_s[0],
        v_rel_b_m_s[1],
        v_rel_b_m_s[2],
        density_kg_m3,
        drag_coefficient,
        normals_b,
        areas_m2,
        centroids_b_m,
    )
    return torque


@njit(cache=True)
def solar_pressure_torque_1(
    sun_b_unit: np.ndarray,
    sun_distance_m: float,
    illumination: float,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
    specular: np.ndarray,
    diffuse: np.ndarray,
) -> np.ndarray:
    """Flat-plate SRP torque, F = −P A cos θ [(1 − ρs) ŝ + 2(ρs cos θ + ρd/3) n̂] (M&G eq 3.73), N·m."""
    p = SOLAR_PRESSURE_1AU_N_M2 * (AU_M / sun_distance_m) ** 2 * illumination
    torque = np.empty(3)
    torque[0], torque[1], torque[2] = _radiation_plates(
        sun_b_unit[0], sun_b_unit[1], sun_b_unit[2], p, normals_b, areas_m2, centroids_b_m, specular, diffuse
    )
    return torque


def _plates(normals_b: np.ndarray, areas_m2: np.ndarray, centroids_b_m: np.ndarray) -> tuple[np.ndarray, ...]:
    """Validated flat-plate set: unit normals (P, 3), areas (P,), centroids from the centre of mass (P, 3)."""
    n = _vectors(normals_b, "normals_b").reshape(-1, 3)
    c = _vectors(centroids_b_m, "centroids_b_m").reshape(-1, 3)
    a = np.asarray(areas_m2, dtype=float).ravel()
    if a.shape[0] != n.shape[0] or c.shape[0] != n.shape[0]:
        raise ValueError("areas_m2, centroids_b_m: need one area and one centroid per plate normal")
    if not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise ValueError("areas_m2: must be finite and non-negative")
    if np.any(np.abs(np.linalg.norm(n, axis=1) - 1.0) > 1e-9):
        raise ValueError("normals_b: plate normals must be unit vectors")
    return np.ascontiguousarray(n), np.ascontiguousarray(a), np.ascontiguousarray(c)


def _fractions(values: np.ndarray | float, size: int, name: str) -> np.ndarray:
    f = np.broadcast_to(np.asarray(values, dtype=float), (size,))
    if not np.all(np.isfinite(f)) or np.any(f < 0.0) or np.any(f > 1.0):
        raise ValueError(f"{name}: reflectivity fractions must lie in [0, 1]")
    return np.ascontiguousarray(f)


def aerodynamic_torque_nm(
    r_eci_m: np.ndarray,
    v_eci_m_s: np.ndarray,
    q_ib: np.ndarray,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
    drag_coefficient: float = 2.2,
) -> np.ndarray:
    """Drag torque (N·m, body axes) along an orbit: v_rel = v − ω⊕ẑ × r, ρ of Vallado Table 8-4 (M^d of seed 000 eq 1).

    The ellipsoidal height is taken from the ECI position: it only depends on the distance to the
    rotation axis and along it, and the GCRS pole is within 0.5° of the true one (< 0.1 km of height).
    """
    r, v = _vectors(r_eci_m, "r_eci_m").reshape(-1, 3), _vectors(v_eci_m_s, "v_eci_m_s").reshape(-1, 3)
    if not (np.isfinite(drag_coefficient) and drag_coefficient >= 0.0):
        raise ValueError("drag_coefficient: must be finite and non-negative")
    n, a, c = _plates(normals_b, areas_m2, centroids_b_m)
    _, _, alt = frames.ecef_to_geodetic(r)
    rho = np.array([atmosphere_density_1(h) for h in np.maximum(alt, 0.0)])
    v_rel = v - np.cross([0.0, 0.0, frames.EARTH_ROTATION_RATE_RAD_S], r)
    v_rel_b = quaternion.rotate(quaternion.conjugate(quaternion.normalize(q_ib)), v_rel).reshape(-1, 3)
    return np.array([aerodynamic_torque_1(v_rel_b[k], rho[k], float(drag_coefficient), n, a, c) for k in range(len(r))])


def solar_pressure_torque_nm(
    r_eci_m: np.ndarray,
    t_unix_s: np.ndarray | float,
    q_ib: np.ndarray,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
    specular: np.ndarray | float = 0.0,
    diffuse: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Solar-pressure torque (N·m, body axes) along an orbit, Almanac Sun and conical shadow (M^d, seed 000 eq 1)."""
    r = _vectors(r_eci_m, "r_eci_m").reshape(-1, 3)
    t = np.broadcast_to(_times(t_unix_s), r.shape[:1])
    n, a, c = _plates(normals_b, areas_m2, centroids_b_m)
    spec, diff = _fractions(specular, a.size, "specular"), _fractions(diffuse, a.size, "diffuse")
    if np.any(spec + diff > 1.0):
        raise ValueError("specular, diffuse: their sum per plate cannot exceed 1")
    q = np.broadcast_to(quaternion.normalize(q_ib), r.shape[:1] + (4,))
    torque = np.empty_like(r)
    for k in range(r.shape[0]):
        r_sun = sun_position_1(t[k])
        d = r_sun - r[k]
        dist = float(np.linalg.norm(d))
        s_b = quaternion.rotate(quaternion.conjugate(q[k]), d / dist)
        torque[k] = solar_pressure_torque_1(s_b, dist, illumination_1(r[k], r_sun), n, a, c, spec, diff)
    return torque


@njit(cache=True)
def field_table_into(table: np.ndarray, t0: float, step: float, t: float, out: np.ndarray) -> None:
    """Field (or any row) of ``table`` sampled every ``step`` s from t0, linearly interpolated at t into ``out``."""
    u = (t - t0) / step
    i = min(max(int(np.floor(u)), 0), table.shape[0] - 2)
    s = u - i
    for j in range(out.shape[0]):
        out[j] = (1.0 - s) * table[i, j] + s * table[i + 1, j]


@njit(cache=True)
def add_aerodynamic_torque_orbit_into(
    q_ib: np.ndarray,
    r_eci_m: np.ndarray,
    v_eci_m_s: np.ndarray,
    drag_coefficient: float,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
    torque_nm: np.ndarray,
) -> None:
    """``torque_nm`` += :func:`aerodynamic_torque_1` where the spacecraft is, without allocating (the flight loop,
    every step): wind v − ω_E × r of the co-rotating atmosphere in body axes (``q_ib`` = q[0:4]), density of
    :func:`atmosphere_density_1` at |r| − R_E (N·m, body axes)."""
    w0, w1, w2 = quaternion.conjugate_rotate_components_1(
        q_ib,
        v_eci_m_s[0] + EARTH_ROTATION_RAD_S * r_eci_m[1],
        v_eci_m_s[1] - EARTH_ROTATION_RAD_S * r_eci_m[0],
        v_eci_m_s[2],
    )
    r0, r1, r2 = r_eci_m[0], r_eci_m[1], r_eci_m[2]
    alt = np.sqrt(dot3_floats(r0, r1, r2, r0, r1, r2)) - _R_EARTH_M
    t0, t1, t2 = _drag_plates(
        w0, w1, w2, atmosphere_density_1(alt), drag_coefficient, normals_b, areas_m2, centroids_b_m
    )
    torque_nm[0] += t0
    torque_nm[1] += t1
    torque_nm[2] += t2


@njit(cache=True)
def add_solar_pressure_torque_orbit_into(
    q_ib: np.ndarray,
    r_eci_m: np.ndarray,
    sun_eci_m: np.ndarray,
    normals_b: np.ndarray,
    areas_m2: np.ndarray,
    centroids_b_m: np.ndarray,
    specular: np.ndarray,
    diffuse: np.ndarray,
    torque_nm: np.ndarray,
) -> None:
    """``torque_nm`` += :func:`solar_pressure_torque_1` where the spacecraft is, without allocating (the flight
    loop, every step): Sun direction in body axes (``q_ib`` = q[0:4]), distance and the sunlit fraction of
    :func:`illumination_1` (N·m, body axes)."""
    d0, d1, d2 = sun_eci_m[0] - r_eci_m[0], sun_eci_m[1] - r_eci_m[1], sun_eci_m[2] - r_eci_m[2]
    dist = np.sqrt(dot3_floats(d0, d1, d2, d0, d1, d2))
    s0, s1, s2 = quaternion.conjugate_rotate_components_1(q_ib, d0 / dist, d1 / dist, d2 / dist)
    p = SOLAR_PRESSURE_1AU_N_M2 * (AU_M / dist) ** 2 * illumination_1(r_eci_m, sun_eci_m)
    t0, t1, t2 = _radiation_plates(s0, s1, s2, p, normals_b, areas_m2, centroids_b_m, specular, diffuse)
    torque_nm[0] += t0
    torque_nm[1] += t1
    torque_nm[2] += t2
