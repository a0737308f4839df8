"""Orbit of the spacecraft centre of mass: circular Keplerian, J2 propagation, SGP4 from a TLE.

All propagators return ECI (GCRS, see ``sim_core.frames``) position and velocity arrays of shape
(N, 3) in metres and m/s. Times are float64 seconds: since the Unix epoch UTC (``t_unix_s``) for
SGP4, since the element epoch (``t_s``) for the Keplerian and J2 models (their ECI is the frame of
the initial state). The ``*_1`` functions are numba kernels for the engine loop.

Seed 003 §3.2.3.2.1 names the J2 propagator but its text ends before the equations; we use the
standard J2 zonal acceleration (Vallado, *Fundamentals of Astrodynamics*, eq 8-30):
a = −μ r/r³ − (3/2) J2 μ R²/r⁵ [x(1 − 5z²/r²), y(1 − 5z²/r²), z(3 − 5z²/r²)].
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from numba import njit
from sgp4.api import Satrec

from sim_core import frames

__all__ = [
    "MU_EARTH_M3_S2",
    "J2_EARTH",
    "R_EARTH_M",
    "circular_orbit",
    "j2_acceleration",
    "propagate_j2",
    "raan_rate_j2_rad_s",
    "sun_synchronous_inclination_deg",
    "parse_tle",
    "read_tle_file",
    "tle_epoch_unix_s",
    "sgp4_teme",
    "sgp4_teme_since_epoch",
    "propagate_tle",
    "circular_orbit_1",
    "j2_acceleration_1",
    "j2_rk4_step_1",
    "hermite_state_into",
]

MU_EARTH_M3_S2 = 3.986004418e14  # EGM2008 / IERS 2010
J2_EARTH = 1.08262668e-3  # EGM96 unnormalised C20 sign-flipped
R_EARTH_M = frames.WGS84_A_M
_SIDEREAL_YEAR_S = 365.256363004 * 86400.0  # the mean Sun turns 2π per sidereal year in inertial space
_J2_MAX_STEP_S = 5.0  # RK4 step: energy drift < 1e-10 and < 3 cm along-track per day at LEO
_SGP4_ERRORS = {
    1: "mean eccentricity outside [0, 1)",
    2: "mean motion below zero",
    3: "perturbed eccentricity outside [0, 1]",
    4: "semi-latus rectum below zero",
    6: "orbit has decayed (radius below the Earth's)",
}


def _finite(a: np.ndarray | float, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return a


def circular_orbit(
    t_s: np.ndarray, altitude_m: float, inclination_deg: float, raan_deg: float, arg_latitude0_deg: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Circular Keplerian orbit r(t), v(t) in ECI (two-body problem, seed 003 §3.2.3.2.1 Keplerian OP)."""
    t = np.atleast_1d(_finite(t_s, "t_s"))
    for value, name in (
        (altitude_m, "altitude_m"),
        (inclination_deg, "inclination_deg"),
        (raan_deg, "raan_deg"),
        (arg_latitude0_deg, "arg_latitude0_deg"),
    ):
        _finite(value, name)
    if altitude_m <= -R_EARTH_M:
        raise ValueError("altitude_m: orbit radius must be positive")
    a = R_EARTH_M + float(altitude_m)
    n = np.sqrt(MU_EARTH_M3_S2 / a**3)
    inc, raan, u0 = np.radians([inclination_deg, raan_deg, arg_latitude0_deg])
    u = u0 + n * t
    node = np.array([np.cos(raan), np.sin(raan), 0.0])  # ascending node direction
    normal_in_plane = np.array([-np.sin(raan) * np.cos(inc), np.cos(raan) * np.cos(inc), np.sin(inc)])
    r_hat = np.cos(u)[:, None] * node + np.sin(u)[:, None] * normal_in_plane
    t_hat = -np.sin(u)[:, None] * node + np.cos(u)[:, None] * normal_in_plane
    return a * r_hat, (a * n) * t_hat


def j2_acceleration(r_eci_m: np.ndarray) -> np.ndarray:
    """Two-body + J2 gravitational acceleration (m/s²) at ECI positions (Vallado eq 8-30), shape (..., 3)."""
    r = _finite(r_eci_m, "r_eci_m")
    if r.shape[-1:] != (3,):
        raise ValueError(f"r_eci_m: expected shape (..., 3), got {r.shape}")
    r2 = np.sum(r * r, axis=-1, keepdims=True)
    z2 = 5.0 * r[..., 2:3] ** 2 / r2
    k = -1.5 * J2_EARTH * MU_EARTH_M3_S2 * R_EARTH_M**2 / (r2 * r2 * np.sqrt(r2))
    zonal = np.concatenate([1.0 - z2, 1.0 - z2, 3.0 - z2], axis=-1)
    accel_m_s2: npt.NDArray[np.float64] = (-MU_EARTH_M3_S2 / (r2 * np.sqrt(r2)) + k * zonal) * r
    return accel_m_s2


def propagate_j2(
    r0_eci_m: np.ndarray, v0_eci_m_s: np.ndarray, t_s: np.ndarray, max_step_s: float = _J2_MAX_STEP_S
) -> tuple[np.ndarray, np.ndarray]:
    """J2 orbit propagation (seed 003 §3.2.3.2.1) by fixed-step RK4 to non-decreasing times t_s ≥ 0."""
    r0, v0 = _finite(r0_eci_m, "r0_eci_m"), _finite(v0_eci_m_s, "v0_eci_m_s")
    if r0.shape != (3,) or v0.shape != (3,):
        raise ValueError("r0_eci_m, v0_eci_m_s: expected shape (3,) each")
    t = np.atleast_1d(_finite(t_s, "t_s"))
    if np.any(t < 0.0) or np.any(np.diff(t) < 0.0):
        raise ValueError("t_s: times must be non-negative and non-decreasing")
    if not max_step_s > 0.0:
        raise ValueError("max_step_s: must be positive")
    out = _propagate_j2_kernel(np.concatenate([r0, v0]), t, float(max_step_s))
    return out[:, :3], out[:, 3:]


def raan_rate_j2_rad_s(semi_major_axis_m: float, eccentricity: float, inclination_deg: float) -> float:
    """Secular J2 node regression Ω̇ = −(3/2) n J2 (R/p)² cos i (Vallado eq 9-41)."""
    a, e = float(semi_major_axis_m), float(eccentricity)
    if not (a > 0.0 and 0.0 <= e < 1.0):
        raise ValueError("semi_major_axis_m, eccentricity: need a > 0 and 0 ≤ e < 1")
    n = np.sqrt(MU_EARTH_M3_S2 / a**3)
    p = a * (1.0 - e * e)
    return float(-1.5 * n * J2_EARTH * (R_EARTH_M / p) ** 2 * np.cos(np.radians(inclination_deg)))


def sun_synchronous_inclination_deg(altitude_m: np.ndarray | float, eccentricity: float = 0.0) -> np.ndarray:
    """Inclination whose J2 node regression equals the mean Sun's motion: cos i = −Ω̇☉/[(3/2) n J2 (R/p)²]."""
    a = R_EARTH_M + _finite(altitude_m, "altitude_m")
    if np.any(a <= R_EARTH_M * 0.5) or not 0.0 <= eccentricity < 1.0:
        raise ValueError("altitude_m, eccentricity: need an orbit above the Earth and 0 ≤ e < 1")
    n = np.sqrt(MU_EARTH_M3_S2 / a**3)
    p = a * (1.0 - eccentricity**2)
    cos_i = -(2.0 * np.pi / _SIDEREAL_YEAR_S) / (1.5 * n * J2_EARTH * (R_EARTH_M / p) ** 2)
    if np.any(np.abs(cos_i) > 1.0):
        raise ValueError("altitude_m: too high for a Sun-synchronous orbit (|cos i| > 1)")
    return np.degrees(np.arccos(cos_i))


# --- SGP4 (Vallado's reference implementation through the `sgp4` package, WGS72 as the TLEs) ----

_TLE_FIELDS = {
    1: (
        ("satellite_number", 3, 7, "id"),
        ("epoch_year", 19, 20, "int"),
        ("epoch_day", 21, 32, "float"),
        ("mean_motion_dot", 34, 43, "float"),
        ("mean_motion_ddot", 45, 52, "exp"),
        ("bstar", 54, 61, "exp"),
    ),
    2: (
        ("satellite_number", 3, 7, "id"),
        ("inclination_deg", 9, 16, "float"),
        ("raan_deg", 18, 25, "float"),
        ("eccentricity", 27, 33, "digits"),
        ("arg_perigee_deg", 35, 42, "float"),
        ("mean_anomaly_deg", 44, 51, "float"),
        ("mean_motion_rev_day", 53, 63, "float"),
    ),
}


def _check_tle_field(line_no: int, line: str, name: str, c0: int, c1: int, kind: str) -> None:
    text = line[c0 - 1 : c1]
    where = f"TLE line {line_no} columns {c0}-{c1} ({name})"
    checks: dict[str, Callable[[str], bool]] = {
        "id": lambda s: s.strip().isalnum(),
        "int": lambda s: s.strip().isdigit(),
        "digits": lambda s: s.strip().isdigit(),
        "float": lambda s: _is_float(s),
        "exp": lambda s: _is_float(s[:-2].replace(" ", "") or "0") and _is_float(s[-2:].strip() or "0"),
    }
    if not checks[kind](text):
        raise ValueError(f"{where}: {text!r} is not a valid {kind} field")


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _tle_checksum(line: str) -> int:
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def parse_tle(line1: str, line2: str, verify_checksum: bool = True) -> Satrec:
    """Validated two-line element set → SGP4 satellite record (AIAA 2006-6753 TLE format)."""
    for no, line in ((1, line1), (2, line2)):
        if not isinstance(line, str) or len(line.rstrip()) < 69:
            raise ValueError(f"TLE line {no}: expected at least 69 columns, got {len(str(line).rstrip())}")
        if line[0] != str(no):
            raise ValueError(f"TLE line {no} column 1 (line_number): expected '{no}', got {line[0]!r}")
        for name, c0, c1, kind in _TLE_FIELDS[no]:
            _check_tle_field(no, line, name, c0, c1, kind)
        if verify_checksum and (not line[68].isdigit() or int(line[68]) != _tle_checksum(line)):
            raise ValueError(f"TLE line {no} column 69 (checksum): {line[68]!r}, computed {_tle_checksum(line)}")
    if line1[2:7] != line2[2:7]:
        raise ValueError(
            f"TLE line 2 columns 3-7 (satellite_number): {line2[2:7]!r} differs from line 1 {line1[2:7]!r}"
        )
    inc, n = float(line2[8:16]), float(line2[52:63])
    if not 0.0 <= inc <= 180.0:
        raise ValueError(f"TLE line 2 columns 9-16 (inclination_deg): {inc} outside [0, 180]")
    if not n > 0.0:
        raise ValueError(f"TLE line 2 columns 53-63 (mean_motion_rev_day): {n} must be positive")
    return Satrec.twoline2rv(line1[:69], line2[:69])


def read_tle_file(text: str) -> list[tuple[str, Satrec]]:
    """(name, satellite record) of every element set in a 2- or 3-line TLE text; name '' if absent."""
    lines = [ln.rstrip() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    out, name, k = [], "", 0
    while k < len(lines):
        if lines[k].startswith("1 ") and k + 1 < len(lines) and lines[k + 1].startswith("2 "):
            out.append((name, parse_tle(lines[k], lines[k + 1])))
            name, k = "", k + 2
        else:
            name, k = lines[k].strip(), k + 1
    return out


def tle_epoch_unix_s(satrec: Satrec) -> float:
    """Epoch of a TLE as UTC seconds since the Unix epoch."""
    return float((satrec.jdsatepoch - 2440587.5) * 86400.0 + satrec.jdsatepochF * 86400.0)


def sgp4_teme(satrec: Satrec, t_unix_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SGP4 (AIAA 2006-6753) TEME r (m), v (m/s) of shape (N, 3) and the per-time error code (0 = ok)."""
    t = np.atleast_1d(_finite(t_unix_s, "t_unix_s"))
    days = np.floor(t / 86400.0)
    return _sgp4(satrec, 2440587.5 + days, (t - days * 86400.0) / 86400.0)


def sgp4_teme_since_epoch(satrec: Satrec, minutes: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SGP4 TEME r (m), v (m/s), error code at minutes since the TLE epoch (exact epoch arithmetic)."""
    whole, fraction = np.divmod(np.atleast_1d(_finite(minutes, "minutes")) / 1440.0, 1.0)
    return _sgp4(satrec, satrec.jdsatepoch + whole, satrec.jdsatepochF + fraction)


def _sgp4(satrec: Satrec, jd: np.ndarray, fr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    err, r_km, v_km_s = satrec.sgp4_array(jd, fr)
    return np.asarray(r_km) * 1e3, np.asarray(v_km_s) * 1e3, np.asarray(err)


def propagate_tle(satrec: Satrec, t_unix_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """SGP4 of a TLE at UTC times → ECI (GCRS) r (m), v (m/s) of shape (N, 3); ValueError on SGP4 failure."""
    t = np.atleast_1d(_finite(t_unix_s, "t_unix_s"))
    r, v, err = sgp4_teme(satrec, t)
    if np.any(err != 0):
        k = int(np.flatnonzero(err)[0])
        reason = _SGP4_ERRORS.get(int(err[k]), f"error code {int(err[k])}")
        raise ValueError(f"t_unix_s: SGP4 fails at t = {t[k]:.3f} s for satellite {satrec.satnum}: {reason}")
    return frames.teme_to_eci(r, v, t)


# --- compiled kernels ------------------------------------------------------------------------


@njit(cache=True)
def circular_orbit_1(
    t_s: float, a_m: float, inc_rad: float, raan_rad: float, u0_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """ECI r, v on a circular orbit at t_s after the epoch where the argument of latitude is u0."""
    n = np.sqrt(MU_EARTH_M3_S2 / a_m**3)
    u = u0_rad + n * t_s
    cu, su, ci, si, co, so = np.cos(u), np.sin(u), np.cos(inc_rad), np.sin(inc_rad), np.cos(raan_rad), np.sin(raan_rad)
    speed = a_m * n
    r, v = np.empty(3), np.empty(3)
    r[0], r[1], r[2] = a_m * (co * cu - so * ci * su), a_m * (so * cu + co * ci * su), a_m * si * su
    v[0], v[1], v[2] = speed * (-co * su - so * ci * cu), speed * (-so * su + co * ci * cu), speed * si * cu
    return r, v


@njit(cache=True)
def j2_acceleration_1(r: np.ndarray) -> np.ndarray:
    """Two-body + J2 acceleration of one ECI position (Vallado eq 8-30), compiled kernel."""
    r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    rn = np.sqrt(r2)
    k = -1.5 * J2_EARTH * MU_EARTH_M3_S2 * R_EARTH_M**2 / (r2 * r2 * rn)
    z2 = 5.0 * r[2] * r[2] / r2
    g = -MU_EARTH_M3_S2 / (r2 * rn)
    a = np.empty(3)
    a[0] = (g + k * (1.0 - z2)) * r[0]
    a[1] = (g + k * (1.0 - z2)) * r[1]
    a[2] = (g + k * (3.0 - z2)) * r[2]
    return a


@njit(cache=True)
def _j2_derivative(s: np.ndarray) -> np.ndarray:
    d = np.empty(6)
    d[:3] = s[3:]
    d[3:] = j2_acceleration_1(s[:3])
    return d


@njit(cache=True)
def j2_rk4_step_1(state: np.ndarray, h_s: float) -> np.ndarray:
    """One RK4 step of the J2 equations of motion on state (x, y, z, vx, vy, vz), compiled kernel."""
    k1 = _j2_derivative(state)
    k2 = _j2_derivative(state + 0.5 * h_s * k1)
    k3 = _j2_derivative(state + 0.5 * h_s * k2)
    k4 = _j2_derivative(state + h_s * k3)
    state_next: npt.NDArray[np.float64] = state + (h_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return state_next


@njit(cache=True)
def _propagate_j2_kernel(state0: np.ndarray, t_s: np.ndarray, max_step_s: float) -> np.ndarray:
    out = np.empty((t_s.size, 6))
    s = state0.copy()
    t = 0.0
    for k in range(t_s.size):
        span = t_s[k] - t
        n = int(np.ceil(span / max_step_s))
        for _ in range(n):
            s = j2_rk4_step_1(s, span / n)
        t = t_s[k]
        out[k] = s
    return out


@njit(cache=True)
def hermite_state_into(
    table: np.ndarray, t0: float, step: float, t: float, r: np.ndarray, v: np.ndarray, acc: np.ndarray
) -> None:
    """ECI r, v, a at t from a table of rows (r, v, a) every ``step`` s from t0: cubic Hermite on (r, v),
    linear on a, written in place (the engine tabulates the orbit once per batch)."""
    u = (t - t0) / step
    i = min(max(int(np.floor(u)), 0), table.shape[0] - 2)
    s = u - i
    s2, s3 = s * s, s * s * s
    h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
    d00, d10, d01, d11 = (6 * s2 - 6 * s) / step, 3 * s2 - 4 * s + 1, (-6 * s2 + 6 * s) / step, 3 * s2 - 2 * s
    for j in range(3):
        r[j] = (
            h00 * table[i, j] + h10 * step * table[i, 3 + j] + h01 * table[i + 1, j] + h11 * step * table[i + 1, 3 + j]
        )
        v[j] = d00 * table[i, j] + d10 * table[i, 3 + j] + d01 * table[i + 1, j] + d11 * table[i + 1, 3 + j]
        acc[j] = (1 - s) * table[i, 6 + j] + s * table[i + 1, 6 + j]
