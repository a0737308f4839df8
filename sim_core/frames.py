"""Reference frames: ECI (GCRS), TEME, ECEF (ITRS), WGS84 geodetic and the orbital frame ORF.

Conventions (written once here and in docs/conventions.md):

* Time is UTC as float64 seconds since the Unix epoch (``t_unix_s``); UT1 = UTC + DUT1 from the
  IERS table that skyfield ships (``load.timescale(builtin=True)``, offline).
* ECI is the GCRS (≈ J2000 to 23 mas). ECEF is the ITRS: ECEF = W · R3(ERA) · C · ECI with ERA the
  IAU 2000 Earth rotation angle of UT1, C the IAU 2000A/2006 celestial-to-intermediate
  (precession-nutation) matrix and W the polar motion (IERS finals2000A.all shipped by skyfield-data),
  C and W taken from skyfield on an hourly grid and interpolated (error < 1e-10 rad), each hour's values
  evaluated once per process and kept (``_NODES_KEPT`` hours: a live twin's re-sync asks for the same hours
  again and again; skyfield took ~10 ms of its ~50 ms). Against
  Vallado's AIAA 2006-6753 example the chain TEME → GCRS → ITRS is good to a few millimetres.
* TEME (SGP4 output, AIAA 2006-6753 App. C) → GCRS uses skyfield's TEME rotation
  (GMST 1982 minus GAST, then the true-of-date → GCRS matrix), accuracy at the mas level.
* ORF (seed 000 §2, DESIGN.md): x^o toward nadir (−r̂), y^o along the orbital velocity (the part of
  v normal to r), z^o = x^o × y^o (= −orbit normal). Λ_o(t) rotates ORF vectors into ECI; the body
  attitude relative to the ORF is Λ^o = Λ̃_o ∘ Λ.
* Kernels (``*_1``) are numba functions on float64 arrays for the engine loop; for them C, W and
  DUT1 are frozen at the scenario start (drift < 1e-6 rad per day).
"""

from __future__ import annotations

import functools
import threading
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_core import quaternion

if TYPE_CHECKING:
    from skyfield.timelib import Time

__all__ = [
    "WGS84_A_M",
    "WGS84_F",
    "WGS84_E2",
    "EARTH_ROTATION_RATE_RAD_S",
    "skyfield_time",
    "skyfield_data_path",
    "ut1_minus_utc_s",
    "earth_rotation_angle_rad",
    "celestial_to_intermediate",
    "polar_motion",
    "eci_to_ecef_matrix",
    "eci_to_ecef",
    "ecef_to_eci",
    "teme_to_eci",
    "geodetic_to_ecef",
    "ecef_to_geodetic",
    "orf_axes",
    "orf_quaternion",
    "orf_rate_rad_s",
    "earth_orientation_frozen",
    "earth_rotation_angle_1",
    "eci_to_ecef_1",
    "ecef_to_eci_1",
    "orf_quaternion_1",
]

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
EARTH_ROTATION_RATE_RAD_S = 2.0 * np.pi * 1.00273781191135448 / 86400.0  # dERA/dt (IERS 2010)
_J2000_UNIX_S = 946728000.0  # 2000-01-01T12:00:00 UTC (ERA epoch JD 2451545.0 of UT1)
_GRID_STEP_S = 3600.0  # precession-nutation sampling step (nutation curvature error < 1e-10 rad)
_NODES_KEPT = 24 * 31  # hourly nodes kept (a month of hours, ≈ 0.5 MB); the oldest kept goes first
_GEODETIC_ITERATIONS = 6  # Bowring/Newton: sub-micrometre for |h| < 1e5 km


def skyfield_data_path() -> Path:
    """Folder of skyfield-data's offline files (DE421, finals2000A.all), its expiry warning silenced.

    Past the end of finals2000A.all, skyfield holds DUT1 and polar motion at their last predictions
    (a stale DUT1 of 0.1 s moves ECEF by ~50 m at LEO radius; angles by 7e-6 rad).
    """
    import skyfield_data

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*has expired.*")
        return Path(skyfield_data.get_skyfield_data_path())


@functools.lru_cache(maxsize=1)
def _timescale() -> Any:  # a skyfield Timescale (skyfield is untyped)
    """skyfield's built-in timescale (leap seconds, DUT1), loaded once, offline."""
    from skyfield.api import load
    from skyfield.data import iers

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*has expired.*")
        ts = load.timescale(builtin=True)
    with open(skyfield_data_path() / "finals2000A.all", "rb") as finals:
        iers.install_polar_motion_table(ts, iers.parse_x_y_dut1_from_finals_all(finals))
    return ts


def _times(t_unix_s: np.ndarray | float, name: str = "t_unix_s") -> np.ndarray:
    t = np.asarray(t_unix_s, dtype=float)
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return t


def _vectors(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected shape (..., 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return v


def skyfield_time(t_unix_s: np.ndarray) -> Time:
    """skyfield Time of Unix UTC seconds, for skyfield models (days split off: leap seconds not double-counted)."""
    days = np.floor(t_unix_s / 86400.0)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*has expired.*")
        return _timescale().utc(1970, 1, 1 + days.astype(np.int64), 0, 0, t_unix_s - days * 86400.0)


def ut1_minus_utc_s(t_unix_s: np.ndarray | float) -> np.ndarray:
    """DUT1 = UT1 − UTC (s) from the IERS table shipped with skyfield (held constant past its end)."""
    t = _times(t_unix_s)
    return np.asarray(skyfield_time(np.atleast_1d(t)).dut1, dtype=float).reshape(t.shape)


def earth_rotation_angle_rad(t_ut1_unix_s: np.ndarray | float) -> np.ndarray:
    """IAU 2000 Earth rotation angle θ = 2π(0.7790572732640 + 1.00273781191135448 Tu), Tu in UT1 days."""
    tu = (_times(t_ut1_unix_s, "t_ut1_unix_s") - _J2000_UNIX_S) / 86400.0
    turns = 0.7790572732640 + 0.00273781191135448 * tu + np.mod(tu, 1.0)
    return 2.0 * np.pi * np.mod(turns, 1.0)


def _rot3(angle_rad: np.ndarray) -> np.ndarray:
    """Passive rotation matrices R3(θ) (frame turned by θ about z), shape (..., 3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    r = np.zeros(np.shape(angle_rad) + (3, 3))
    r[..., 0, 0], r[..., 0, 1], r[..., 1, 0], r[..., 1, 1], r[..., 2, 2] = c, s, -s, c, 1.0
    return r


_nodes: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # hour → C, W, TEME (see _hour_nodes)
_nodes_lock = threading.Lock()


def _hour_nodes(hours: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """C, W and GCRS→TEME matrices at whole UTC hours (``hours`` × 3600 s): skyfield evaluates the hours not
    kept yet, in one call; the newest ``_NODES_KEPT`` hours are kept (thread-safe)."""
    found = {h: _nodes.get(h) for h in hours.tolist()}
    missing = [h for h, v in found.items() if v is None]
    if missing:
        grid = np.array(missing) * _GRID_STEP_S
        sky = skyfield_time(grid)
        era = earth_rotation_angle_rad(grid + np.asarray(sky.dut1, dtype=float))
        gast = np.asarray(sky.gast, dtype=float) * (2.0 * np.pi / 24.0)
        m_tod = np.moveaxis(np.asarray(sky.M), -1, 0)  # GCRS → true equator and equinox of date
        c_grid = _rot3(gast - era) @ m_tod  # R3(ERA)·C = R3(GAST)·M
        from skyfield.sgp4lib import TEME

        teme_grid = np.moveaxis(np.asarray(TEME.rotation_at(sky)), -1, 0)
        w_grid = np.moveaxis(np.asarray(sky.polar_motion_matrix()), -1, 0)
        computed = {h: (c_grid[i], w_grid[i], teme_grid[i]) for i, h in enumerate(missing)}
        found.update(computed)
        with _nodes_lock:
            _nodes.update(computed)
            while len(_nodes) > _NODES_KEPT:
                del _nodes[next(iter(_nodes))]
    c, w, teme = zip(*(found[h] for h in hours.tolist()))
    return np.stack(c), np.stack(w), np.stack(teme)


def _slow_matrices(t_unix_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GCRS→CIRS (C), polar motion (W) and GCRS→TEME matrices at flat times, linear between the
    whole UTC hours that bracket them (only those hours are evaluated by skyfield, once: _hour_nodes)."""
    hour = np.floor(t_unix_s / _GRID_STEP_S)
    nodes, k = np.unique(np.concatenate([hour, hour + 1.0]), return_inverse=True)
    k = k[: hour.size]
    c_grid, w_grid, teme_grid = _hour_nodes(nodes)
    k1 = np.searchsorted(nodes, hour + 1.0)
    f = (t_unix_s / _GRID_STEP_S - hour)[:, None, None]
    c = (1.0 - f) * c_grid[k] + f * c_grid[k1]
    teme = (1.0 - f) * teme_grid[k] + f * teme_grid[k1]
    w = (1.0 - f) * w_grid[k] + f * w_grid[k1]
    return c, w, teme


def celestial_to_intermediate(t_unix_s: np.ndarray | float) -> np.ndarray:
    """Precession-nutation matrix C (GCRS → CIRS, IAU 2000A/2006 via skyfield), shape (..., 3, 3)."""
    t = _times(t_unix_s)
    c, _, _ = _slow_matrices(np.atleast_1d(t).ravel())
    return c.reshape(t.shape + (3, 3))


def polar_motion(t_unix_s: np.ndarray | float) -> np.ndarray:
    """Polar-motion matrix W (TIRS → ITRS, IERS x_p, y_p, s′ via skyfield), shape (..., 3, 3)."""
    t = _times(t_unix_s)
    _, w, _ = _slow_matrices(np.atleast_1d(t).ravel())
    return w.reshape(t.shape + (3, 3))


def eci_to_ecef_matrix(t_unix_s: np.ndarray | float) -> np.ndarray:
    """Rotation ECI (GCRS) → ECEF (ITRS): W · R3(ERA(UT1)) · C (IERS 2010 eq 5.1), shape (..., 3, 3)."""
    t = _times(t_unix_s)
    flat = np.atleast_1d(t).ravel()
    c, w, _ = _slow_matrices(flat)
    era = earth_rotation_angle_rad(flat + ut1_minus_utc_s(flat))
    dcm: npt.NDArray[np.float64] = (w @ _rot3(era) @ c).reshape(t.shape + (3, 3))
    return dcm


def eci_to_ecef(
    r_eci_m: np.ndarray, v_eci_m_s: np.ndarray, t_unix_s: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """ECI → ECEF position and velocity: r_e = R r_i, v_e = R v_i − ω⊕ × r_e (Vallado eq 3-80)."""
    r, v = _vectors(r_eci_m, "r_eci_m"), _vectors(v_eci_m_s, "v_eci_m_s")
    m = eci_to_ecef_matrix(t_unix_s)
    r_e = np.einsum("...ij,...j->...i", m, r)
    omega = np.array([0.0, 0.0, EARTH_ROTATION_RATE_RAD_S])
    return r_e, np.einsum("...ij,...j->...i", m, v) - np.cross(omega, r_e)


def ecef_to_eci(
    r_ecef_m: np.ndarray, v_ecef_m_s: np.ndarray, t_unix_s: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """ECEF → ECI position and velocity: r_i = Rᵗ r_e, v_i = Rᵗ (v_e + ω⊕ × r_e) (Vallado eq 3-80)."""
    r, v = _vectors(r_ecef_m, "r_ecef_m"), _vectors(v_ecef_m_s, "v_ecef_m_s")
    mt = np.swapaxes(eci_to_ecef_matrix(t_unix_s), -1, -2)
    omega = np.array([0.0, 0.0, EARTH_ROTATION_RATE_RAD_S])
    return np.einsum("...ij,...j->...i", mt, r), np.einsum("...ij,...j->...i", mt, v + np.cross(omega, r))


def teme_to_eci(
    r_teme_m: np.ndarray, v_teme_m_s: np.ndarray, t_unix_s: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """TEME (SGP4 output, AIAA 2006-6753 App. C) → ECI (GCRS) position and velocity."""
    r, v = _vectors(r_teme_m, "r_teme_m"), _vectors(v_teme_m_s, "v_teme_m_s")
    t = _times(t_unix_s)
    _, _, teme = _slow_matrices(np.atleast_1d(t).ravel())
    mt = np.swapaxes(teme, -1, -2).reshape(t.shape + (3, 3))
    return np.einsum("...ij,...j->...i", mt, r), np.einsum("...ij,...j->...i", mt, v)


def geodetic_to_ecef(lat_deg: np.ndarray | float, lon_deg: np.ndarray | float, alt_m: np.ndarray | float) -> np.ndarray:
    """WGS84 geodetic latitude, longitude, ellipsoidal height → ECEF (m), shape (..., 3)."""
    lat = np.radians(_times(lat_deg, "lat_deg"))
    lon = np.radians(_times(lon_deg, "lon_deg"))
    h = _times(alt_m, "alt_m")
    if np.any(np.abs(lat) > np.pi / 2):
        raise ValueError("lat_deg: must lie in [-90, 90]")
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack(
        np.broadcast_arrays(
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - WGS84_E2) + h) * np.sin(lat),
        ),
        axis=-1,
    )


def ecef_to_geodetic(r_ecef_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ECEF (m) → WGS84 geodetic (lat_deg, lon_deg, alt_m) by Newton iteration on latitude."""
    r = _vectors(r_ecef_m, "r_ecef_m")
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(_GEODETIC_ITERATIONS):
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        lat = np.arctan2(z + WGS84_E2 * n * np.sin(lat), p)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    cos_lat, sin_lat = np.cos(lat), np.sin(lat)
    alt = p * cos_lat + z * sin_lat - n * (1.0 - WGS84_E2 * sin_lat**2)
    return np.degrees(lat), np.degrees(np.arctan2(y, x)), alt


def orf_axes(r_eci_m: np.ndarray, v_eci_m_s: np.ndarray) -> np.ndarray:
    """ORF axes in ECI as matrix columns [x^o y^o z^o]: x^o = −r̂, z^o = x^o×v̂/|·|, y^o = z^o×x^o (seed 000 §2)."""
    r, v = _vectors(r_eci_m, "r_eci_m"), _vectors(v_eci_m_s, "v_eci_m_s")
    x = -r / np.linalg.norm(r, axis=-1, keepdims=True)
    z = np.cross(x, v)
    nz = np.linalg.norm(z, axis=-1, keepdims=True)
    if np.any(nz == 0.0):
        raise ValueError("v_eci_m_s: velocity parallel to position leaves the ORF undefined")
    z = z / nz
    return np.stack([x, np.cross(z, x), z], axis=-1)


def orf_quaternion(r_eci_m: np.ndarray, v_eci_m_s: np.ndarray) -> np.ndarray:
    """ORF quaternion Λ_o(t) (rotates ORF vectors into ECI; seed 000 §2 Λ^o = Λ̃_o ∘ Λ), shape (..., 4)."""
    return quaternion.from_dcm(orf_axes(r_eci_m, v_eci_m_s))


def orf_rate_rad_s(r_eci_m: np.ndarray, v_eci_m_s: np.ndarray) -> np.ndarray:
    """Angular velocity of the ORF in ECI, ω_o = (r × v)/r² (exact for central-force motion)."""
    r, v = _vectors(r_eci_m, "r_eci_m"), _vectors(v_eci_m_s, "v_eci_m_s")
    omega_rad_s: npt.NDArray[np.float64] = np.cross(r, v) / np.sum(r * r, axis=-1, keepdims=True)
    return omega_rad_s


def earth_orientation_frozen(t0_unix_s: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Precession-nutation C (3, 3), polar motion W (3, 3) and DUT1 (s) at t0, for the ``*_1`` kernels."""
    t0 = float(_times(t0_unix_s, "t0_unix_s"))
    return celestial_to_intermediate(t0), polar_motion(t0), float(ut1_minus_utc_s(t0))


@njit(cache=True)
def earth_rotation_angle_1(t_ut1_unix_s: float) -> float:
    """IAU 2000 Earth rotation angle (rad) of one UT1 instant (compiled kernel)."""
    tu = (t_ut1_unix_s - _J2000_UNIX_S) / 86400.0
    turns = 0.7790572732640 + 0.00273781191135448 * tu + (tu - np.floor(tu))
    return float(2.0 * np.pi * (turns - np.floor(turns)))


@njit(cache=True)
def eci_to_ecef_1(v_eci: np.ndarray, c_pn: np.ndarray, w_pm: np.ndarray, era_rad: float) -> np.ndarray:
    """Rotate one ECI vector into ECEF: W · R3(ERA) · C · v (compiled kernel, no velocity transport)."""
    w0 = c_pn[0, 0] * v_eci[0] + c_pn[0, 1] * v_eci[1] + c_pn[0, 2] * v_eci[2]
    w1 = c_pn[1, 0] * v_eci[0] + c_pn[1, 1] * v_eci[1] + c_pn[1, 2] * v_eci[2]
    w2 = c_pn[2, 0] * v_eci[0] + c_pn[2, 1] * v_eci[1] + c_pn[2, 2] * v_eci[2]
    c, s = np.cos(era_rad), np.sin(era_rad)
    u0, u1 = c * w0 + s * w1, c * w1 - s * w0
    out = np.empty(3)
    for i in range(3):
        out[i] = w_pm[i, 0] * u0 + w_pm[i, 1] * u1 + w_pm[i, 2] * w2
    return out


@njit(cache=True)
def ecef_to_eci_1(v_ecef: np.ndarray, c_pn: np.ndarray, w_pm: np.ndarray, era_rad: float) -> np.ndarray:
    """Rotate one ECEF vector into ECI: Cᵗ · R3(−ERA) · Wᵗ · v (compiled kernel, no velocity transport)."""
    u0 = w_pm[0, 0] * v_ecef[0] + w_pm[1, 0] * v_ecef[1] + w_pm[2, 0] * v_ecef[2]
    u1 = w_pm[0, 1] * v_ecef[0] + w_pm[1, 1] * v_ecef[1] + w_pm[2, 1] * v_ecef[2]
    u2 = w_pm[0, 2] * v_ecef[0] + w_pm[1, 2] * v_ecef[1] + w_pm[2, 2] * v_ecef[2]
    c, s = np.cos(era_rad), np.sin(era_rad)
    w0, w1 = c * u0 - s * u1, s * u0 + c * u1
    out = np.empty(3)
    for i in range(3):
        out[i] = c_pn[0, i] * w0 + c_pn[1, i] * w1 + c_pn[2, i] * u2
    return out


@njit(cache=True)
def orf_quaternion_1(r_eci: np.ndarray, v_eci: np.ndarray) -> np.ndarray:
    """ORF quaternion Λ_o of one position/velocity (compiled kernel, Shepperd's method, λ0 ≥ 0)."""
    rn = np.sqrt(r_eci[0] ** 2 + r_eci[1] ** 2 + r_eci[2] ** 2)
    x0, x1, x2 = -r_eci[0] / rn, -r_eci[1] / rn, -r_eci[2] / rn
    z0 = x1 * v_eci[2] - x2 * v_eci[1]
    z1 = x2 * v_eci[0] - x0 * v_eci[2]
    z2 = x0 * v_eci[1] - x1 * v_eci[0]
    zn = np.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
    z0, z1, z2 = z0 / zn, z1 / zn, z2 / zn
    y0, y1, y2 = z1 * x2 - z2 * x1, z2 * x0 - z0 * x2, z0 * x1 - z1 * x0
    # DCM columns x, y, z: m[i][j] = axis_j[i]
    tr = x0 + y1 + z2
    q = np.empty(4)
    if tr >= x0 and tr >= y1 and tr >= z2:
        q[0] = 0.5 * np.sqrt(1.0 + tr)
        f = 0.25 / q[0]
        q[1], q[2], q[3] = (y2 - z1) * f, (z0 - x2) * f, (x1 - y0) * f
    elif x0 >= y1 and x0 >= z2:
        q[1] = 0.5 * np.sqrt(1.0 + 2.0 * x0 - tr)
        f = 0.25 / q[1]
        q[0], q[2], q[3] = (y2 - z1) * f, (y0 + x1) * f, (z0 + x2) * f
    elif y1 >= z2:
        q[2] = 0.5 * np.sqrt(1.0 + 2.0 * y1 - tr)
        f = 0.25 / q[2]
        q[0], q[1], q[3] = (z0 - x2) * f, (y0 + x1) * f, (z1 + y2) * f
    else:
        q[3] = 0.5 * np.sqrt(1.0 + 2.0 * z2 - tr)
        f = 0.25 / q[3]
        q[0], q[1], q[2] = (x1 - y0) * f, (z0 + x2) * f, (z1 + y2) * f
    if q[0] < 0.0:
        for i in range(4):
            q[i] = -q[i]
    return q
