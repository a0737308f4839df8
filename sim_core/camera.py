"""Survey-camera geometry on the WGS84 ellipsoid: line of sight, footprint, CCD-line projection,
ground trace, survey-zone bounds, station visibility circles and the day/night terminator.

Seed 000 §6 (SURIUS-S): the map shows "the flight trace, bounds of the SC survey zone, and also
bounds of light and shade"; the animation shows "the trace point, a point of the line-of-sight
intersection with the Earth surface and the CCD line projection onto the surface".

Conventions (DESIGN.md, frames.py): the telescope boresight is body +x; the CCD line of the
push-broom camera lies along body +z, which in the nominal (ORF-aligned) attitude is across track
(z^o = x^o × y^o), so a roll about body y sweeps the line across track. ``c_eb`` is the direction
cosine matrix body → ECEF, shape (..., 3, 3); every position is ECEF in metres. All functions are
vectorised over leading axes and return NaN where a ray misses the Earth.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_core import frames, quaternion

__all__ = [
    "BORESIGHT_B",
    "CCD_LINE_B",
    "body_to_ecef_dcm",
    "intersect_ellipsoid",
    "line_of_sight_ecef_m",
    "camera_rays_b",
    "footprint_ecef_m",
    "ccd_line_ecef_m",
    "ground_trace_ecef_m",
    "survey_zone_bounds_ecef_m",
    "station_visibility_circle_ecef_m",
    "terminator_ecef_m",
    "image_motion_rad_s",
    "ground_point_velocity_eci_m_s",
    "surface_point_from_normal",
    "intersect_ellipsoid_1",
    "ground_trace_1",
]

BORESIGHT_B = np.array([1.0, 0.0, 0.0])
CCD_LINE_B = np.array([0.0, 0.0, 1.0])
_A = frames.WGS84_A_M
_B = frames.WGS84_A_M * (1.0 - frames.WGS84_F)
_AXES = np.array([_A, _A, _B])
_E2 = frames.WGS84_E2
_EP2 = _E2 / (1.0 - _E2)


def _vectors(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected shape (..., 3), got {v.shape}")
    return v


def _dcm(c: np.ndarray, name: str = "c_eb") -> np.ndarray:
    c = np.asarray(c, dtype=float)
    if c.shape[-2:] != (3, 3):
        raise ValueError(f"{name}: expected shape (..., 3, 3), got {c.shape}")
    return c


def _half_angle(value: float, name: str) -> float:
    if not 0.0 < value < np.pi / 2:
        raise ValueError(f"{name}: half angle must lie in (0, π/2) rad, got {value}")
    return float(value)


def _count(n: int, name: str, minimum: int) -> int:
    if int(n) != n or n < minimum:
        raise ValueError(f"{name}: expected an integer ≥ {minimum}, got {n}")
    return int(n)


def body_to_ecef_dcm(q_ib: np.ndarray, eci_to_ecef: np.ndarray) -> np.ndarray:
    """DCM body → ECEF, C_eb = M_ei · R(Λ) with Λ = q_ib (seed 000 §2 attitude in the IRF), (..., 3, 3)."""
    dcm: npt.NDArray[np.float64] = _dcm(eci_to_ecef, "eci_to_ecef") @ quaternion.to_dcm(quaternion.normalize(q_ib))
    return dcm


def intersect_ellipsoid(origin_m: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """First point where the ray origin + s·d (s ≥ 0) meets the WGS84 ellipsoid, NaN on a miss (seed 000 §6 LOS)."""
    o, d = np.broadcast_arrays(_vectors(origin_m, "origin_m"), _vectors(direction, "direction"))
    if np.any(np.all(d == 0.0, axis=-1)):
        raise ValueError("direction: zero vector has no direction")
    out = _intersect_many(np.ascontiguousarray(o.reshape(-1, 3)), np.ascontiguousarray(d.reshape(-1, 3)))
    return out.reshape(o.shape)


@njit(cache=True)
def intersect_ellipsoid_1(o: np.ndarray, d: np.ndarray, out: np.ndarray) -> None:
    """Ray–WGS84 intersection of one ray into ``out`` (NaN on a miss), compiled kernel.

    Scaling by the semi-axes turns the ellipsoid into the unit sphere: |o' + s d'|² = 1 is a
    quadratic in s whose smaller non-negative root is the visible surface point.
    """
    ox, oy, oz = o[0] / _A, o[1] / _A, o[2] / _B
    dx, dy, dz = d[0] / _A, d[1] / _A, d[2] / _B
    a = dx * dx + dy * dy + dz * dz
    b = ox * dx + oy * dy + oz * dz
    c = ox * ox + oy * oy + oz * oz - 1.0
    disc = b * b - a * c
    s = (-b - np.sqrt(disc)) / a if disc >= 0.0 else -1.0
    if s < 0.0:
        out[0] = out[1] = out[2] = np.nan
        return
    out[0] = (ox + s * dx) * _A
    out[1] = (oy + s * dy) * _A
    out[2] = (oz + s * dz) * _B


@njit(cache=True)
def _intersect_many(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    out = np.empty_like(o)
    for k in range(o.shape[0]):
        intersect_ellipsoid_1(o[k], d[k], out[k])
    return out


@njit(cache=True)
def _project_many(r: np.ndarray, c: np.ndarray, rays_b: np.ndarray) -> np.ndarray:
    """Rays fanned from each origin (body rays rotated by C_eb), per-origin terms hoisted out."""
    out = np.empty((r.shape[0], rays_b.shape[0], 3))
    for k in range(r.shape[0]):
        ox, oy, oz = r[k, 0] / _A, r[k, 1] / _A, r[k, 2] / _B
        cc = ox * ox + oy * oy + oz * oz - 1.0
        for j in range(rays_b.shape[0]):
            bx, by, bz = rays_b[j, 0], rays_b[j, 1], rays_b[j, 2]
            dx = (c[k, 0, 0] * bx + c[k, 0, 1] * by + c[k, 0, 2] * bz) / _A
            dy = (c[k, 1, 0] * bx + c[k, 1, 1] * by + c[k, 1, 2] * bz) / _A
            dz = (c[k, 2, 0] * bx + c[k, 2, 1] * by + c[k, 2, 2] * bz) / _B
            a = dx * dx + dy * dy + dz * dz
            b = ox * dx + oy * dy + oz * dz
            disc = b * b - a * cc
            s = (-b - np.sqrt(disc)) / a if disc >= 0.0 else -1.0
            if s < 0.0:
                out[k, j, 0] = out[k, j, 1] = out[k, j, 2] = np.nan
            else:
                out[k, j, 0] = (ox + s * dx) * _A
                out[k, j, 1] = (oy + s * dy) * _A
                out[k, j, 2] = (oz + s * dz) * _B
    return out


def line_of_sight_ecef_m(r_ecef_m: np.ndarray, c_eb: np.ndarray) -> np.ndarray:
    """Point where the telescope boresight (body +x) meets the Earth, ECEF m, NaN if it misses (seed 000 §6)."""
    return intersect_ellipsoid(r_ecef_m, _dcm(c_eb)[..., :, 0])


@lru_cache(maxsize=32)
def camera_rays_b(half_across_rad: float, half_along_rad: float, n_per_edge: int) -> np.ndarray:
    """Unit body-frame rays around the rectangular field of view, counter-clockwise, shape (4 n, 3).

    The field is a pyramid about +x: tan-plane coordinates (y, z) = (tan α_along, tan α_across) on
    the edges of the rectangle, so straight edges in the focal plane stay straight rays. Cached and
    read-only (the display asks for the same field every frame).
    """
    ta = np.tan(_half_angle(half_across_rad, "half_across_rad"))
    tl = np.tan(_half_angle(half_along_rad, "half_along_rad"))
    n = _count(n_per_edge, "n_per_edge", 1)
    u = np.linspace(-1.0, 1.0, n, endpoint=False)
    edges = [(u * tl, -ta + 0 * u), (tl + 0 * u, u * ta), (-u * tl, ta + 0 * u), (-tl + 0 * u, -u * ta)]
    y = np.concatenate([e[0] for e in edges])
    z = np.concatenate([e[1] for e in edges])
    rays = np.stack([np.ones_like(y), y, z], axis=-1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    rays.flags.writeable = False  # cached: shared by every caller
    return rays


def _project_rays(r_ecef_m: np.ndarray, c_eb: np.ndarray, rays_b: np.ndarray) -> np.ndarray:
    r, c = _vectors(r_ecef_m, "r_ecef_m"), _dcm(c_eb)
    lead = np.broadcast_shapes(r.shape[:-1], c.shape[:-2])
    r = np.ascontiguousarray(np.broadcast_to(r, lead + (3,)).reshape(-1, 3))
    c = np.ascontiguousarray(np.broadcast_to(c, lead + (3, 3)).reshape(-1, 3, 3))
    return _project_many(r, c, np.ascontiguousarray(rays_b)).reshape(lead + rays_b.shape)


def footprint_ecef_m(
    r_ecef_m: np.ndarray, c_eb: np.ndarray, half_across_rad: float, half_along_rad: float, n_per_edge: int = 4
) -> np.ndarray:
    """Camera footprint polygon on the ellipsoid, ECEF m, shape (..., 4 n, 3), NaN where a ray misses (seed 000 §6)."""
    return _project_rays(r_ecef_m, c_eb, camera_rays_b(half_across_rad, half_along_rad, n_per_edge))


def ccd_line_ecef_m(r_ecef_m: np.ndarray, c_eb: np.ndarray, half_across_rad: float, n_points: int = 9) -> np.ndarray:
    """Projection of the CCD line (body x–z plane, ±half_across about +x) on the ellipsoid, (..., n, 3), seed 000 §6."""
    ta = np.tan(_half_angle(half_across_rad, "half_across_rad"))
    z = np.linspace(-ta, ta, _count(n_points, "n_points", 2))
    rays = np.stack([np.ones_like(z), np.zeros_like(z), z], axis=-1)
    return _project_rays(r_ecef_m, c_eb, rays / np.linalg.norm(rays, axis=-1, keepdims=True))


def surface_point_from_normal(normal: np.ndarray) -> np.ndarray:
    """The point of the WGS84 ellipsoid whose outward normal is ``normal``, ECEF m (x²/a² + y²/a² + z²/b² = 1).

    The gradient at p is (p_x/a², p_y/a², p_z/b²) ∥ n, hence p = A² n / sqrt(nᵗ A² n) with A = diag(a, a, b).
    """
    n = _vectors(normal, "normal")
    a2n = _AXES**2 * n
    point_m: npt.NDArray[np.float64] = a2n / np.sqrt(np.sum(a2n * n, axis=-1, keepdims=True))
    return point_m


def ground_trace_ecef_m(r_ecef_m: np.ndarray) -> np.ndarray:
    """Sub-satellite (geodetic nadir) point of the flight trace, ECEF m, shape (..., 3) (seed 000 §6 "trace")."""
    r = _vectors(r_ecef_m, "r_ecef_m")
    return _ground_trace_many(np.ascontiguousarray(r.reshape(-1, 3))).reshape(r.shape)


@njit(cache=True)
def ground_trace_1(r: np.ndarray, out: np.ndarray) -> None:
    """Geodetic nadir point of one ECEF position into ``out``, compiled kernel.

    Bowring's closed form (1976, one step) gives the geodetic latitude to ~2e-9 rad for heights up
    to 1,500 km; the trace point is the ellipsoid point with that geodetic normal.
    """
    p = np.sqrt(r[0] * r[0] + r[1] * r[1])
    beta = np.arctan2(_A * r[2], _B * p)
    sb, cb = np.sin(beta), np.cos(beta)
    lat = np.arctan2(r[2] + _EP2 * _B * sb * sb * sb, p - _E2 * _A * cb * cb * cb)
    lon = np.arctan2(r[1], r[0])
    nx, ny, nz = np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)
    scale = np.sqrt(_A * _A * (nx * nx + ny * ny) + _B * _B * nz * nz)
    out[0] = _A * _A * nx / scale
    out[1] = _A * _A * ny / scale
    out[2] = _B * _B * nz / scale


@njit(cache=True)
def _ground_trace_many(r: np.ndarray) -> np.ndarray:
    out = np.empty_like(r)
    for k in range(r.shape[0]):
        ground_trace_1(r[k], out[k])
    return out


def survey_zone_bounds_ecef_m(
    r_ecef_m: np.ndarray, v_ecef_m_s: np.ndarray, max_roll_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """Left and right bounds of the survey zone: the boresight rolled ±max_roll across track from nadir (seed 000 §6).

    The ORF of the rotating-Earth ground track (x toward −r̂, y along v_ecef, z = x × y) is turned
    about y^o by ±max_roll (seed 000 §2 roll φ2), and each rolled boresight is intersected with the
    ellipsoid; each result has shape (..., 3).
    """
    axes = frames.orf_axes(_vectors(r_ecef_m, "r_ecef_m"), _vectors(v_ecef_m_s, "v_ecef_m_s"))
    roll = _half_angle(max_roll_rad, "max_roll_rad")
    x, z = axes[..., :, 0], axes[..., :, 2]
    # z^o = nadir × forward points to the right of the track; a boresight tilted toward ±z^o
    right = intersect_ellipsoid(r_ecef_m, np.cos(roll) * x + np.sin(roll) * z)
    left = intersect_ellipsoid(r_ecef_m, np.cos(roll) * x - np.sin(roll) * z)
    return left, right


def station_visibility_circle_ecef_m(
    lat_deg: float, lon_deg: float, orbit_altitude_m: float, min_elevation_deg: float, n_points: int = 72
) -> np.ndarray:
    """Ground circle around a station inside which a satellite at the given altitude is above the mask, (n, 3) ECEF m.

    Spherical Earth of the local geocentric radius R: the Earth-central angle is
    λ = arccos(R cos ε / (R + h)) − ε (triangle Earth centre–station–satellite); the circle is the set of
    sub-satellite points
    at angle λ from the station, put on the ellipsoid along their geocentric directions.
    """
    if not -90.0 <= lat_deg <= 90.0:
        raise ValueError("lat_deg: must lie in [-90, 90]")
    if not 0.0 <= min_elevation_deg < 90.0:
        raise ValueError("min_elevation_deg: must lie in [0, 90)")
    if not orbit_altitude_m > 0.0:
        raise ValueError("orbit_altitude_m: must be positive")
    station = frames.geodetic_to_ecef(lat_deg, lon_deg, 0.0)
    radius = float(np.linalg.norm(station))
    eps = np.radians(min_elevation_deg)
    lam = np.arccos(radius * np.cos(eps) / (radius + orbit_altitude_m)) - eps
    u = station / radius
    east = np.cross([0.0, 0.0, 1.0], u)
    east = east / np.linalg.norm(east) if np.linalg.norm(east) > 1e-12 else np.array([0.0, 1.0, 0.0])
    north = np.cross(u, east)
    az = np.linspace(0.0, 2.0 * np.pi, _count(n_points, "n_points", 3), endpoint=False)[:, None]
    dirs = np.cos(lam) * u + np.sin(lam) * (np.cos(az) * north + np.sin(az) * east)
    return intersect_ellipsoid(dirs * 2.0 * _A, -dirs)


def terminator_ecef_m(sun_ecef_m: np.ndarray, n_points: int = 180) -> np.ndarray:
    """Day/night boundary on the ellipsoid: points whose surface normal is perpendicular to the Sun, (..., n, 3).

    Seed 000 §6 "bounds of light and shade" for a Sun at infinity: normals n = cos θ u + sin θ w with
    u, w ⊥ ŝ, mapped to the surface by :func:`surface_point_from_normal`.
    """
    s = _vectors(sun_ecef_m, "sun_ecef_m")
    s = s / np.linalg.norm(s, axis=-1, keepdims=True)
    helper = np.where(np.abs(s[..., 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    u = np.cross(s, helper)
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    w = np.cross(s, u)
    theta = np.linspace(0.0, 2.0 * np.pi, _count(n_points, "n_points", 3))
    normals = np.cos(theta)[:, None] * u[..., None, :] + np.sin(theta)[:, None] * w[..., None, :]
    return surface_point_from_normal(normals)


def ground_point_velocity_eci_m_s(p_eci_m: np.ndarray) -> np.ndarray:
    """Inertial velocity ω⊕ × p of a point fixed on the Earth (rotation about ECI z; the CIP tilt is < 1e-6 rad)."""
    p = _vectors(p_eci_m, "p_eci_m")
    return np.cross([0.0, 0.0, frames.EARTH_ROTATION_RATE_RAD_S], p)


def image_motion_rad_s(
    r_eci_m: np.ndarray,
    v_eci_m_s: np.ndarray,
    q_ib: np.ndarray,
    omega_b_rad_s: np.ndarray,
    p_eci_m: np.ndarray,
    p_velocity_eci_m_s: np.ndarray,
) -> np.ndarray:
    """Image-motion velocity of a ground point in the focal plane, (..., 2) rad/s (seed 000 §6 SURIUS-S).

    With ρ = C_bi (p − r) the point seen in body axes, its focal-plane (tangent) coordinates are
    (ρ_y/ρ_x, ρ_z/ρ_x) — along track and along the CCD line for the nominal attitude; multiplied by
    the focal length they are metres on the detector. Their rate follows from
    ρ̇ = C_bi (ṗ − v) − ω × ρ (transport theorem, ω in body axes, seed 000 eq 1 kinematics).
    """
    r, v = _vectors(r_eci_m, "r_eci_m"), _vectors(v_eci_m_s, "v_eci_m_s")
    p, vp = _vectors(p_eci_m, "p_eci_m"), _vectors(p_velocity_eci_m_s, "p_velocity_eci_m_s")
    w = _vectors(omega_b_rad_s, "omega_b_rad_s")
    q_bi = quaternion.conjugate(quaternion.normalize(q_ib))
    rho = quaternion.rotate(q_bi, p - r)
    rho_dot = quaternion.rotate(q_bi, vp - v) - np.cross(w, rho)
    x = rho[..., 0:1]
    if np.any(x <= 0.0):
        raise ValueError("p_eci_m: the point lies behind the focal plane (ρ_x ≤ 0)")
    rate: npt.NDArray[np.float64] = (rho_dot[..., 1:] * x - rho[..., 1:] * rho_dot[..., 0:1]) / x**2
    return rate
