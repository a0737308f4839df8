"""Camera geometry against exact truths: the WGS84 equator is a circle of radius a (law of sines
gives the exact ground range of an off-nadir ray there), the ellipsoid equation and its normal,
the iterative geodetic conversion of frames.py, and the elevation angle seen from a station."""

from __future__ import annotations

import numpy as np
import pytest

from sim_core import camera, frames

A_M = frames.WGS84_A_M
B_M = frames.WGS84_A_M * (1.0 - frames.WGS84_F)
ALTITUDE_M = 600e3
SURFACE_TOL = 1e-12  # relative residual of x²/a² + y²/a² + z²/b² = 1: float64 round-off
ANGLE_TOL_RAD = 1e-12  # exact formulas, float64 round-off on angles of order 0.1 rad
BOWRING_TOL_RAD = 3e-9  # Bowring's one-step latitude up to 1,500 km height (2 cm on the ground)
PARALLEL_TOL = 1e-9  # |n̂ × û| of unit vectors that must be parallel (sub-mm at Earth scale)
# Bowring's latitude error δ tilts the direction from the trace point to the satellite by δ(1 + a/h):
TRACE_NORMAL_TOL = BOWRING_TOL_RAD * (1.0 + A_M / 300e3)

# Satellite over the equator at longitude 0, boresight (body +x) to the centre, CCD line (body +z)
# along ECEF +y: every across-track ray stays in the equatorial plane, where the Earth is a circle.
R_EQ_M = np.array([A_M + ALTITUDE_M, 0.0, 0.0])
C_EB_EQ = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])  # columns: body x, y, z in ECEF


def _ellipsoid_residual(p: np.ndarray) -> np.ndarray:
    return (p[..., 0] ** 2 + p[..., 1] ** 2) / A_M**2 + p[..., 2] ** 2 / B_M**2 - 1.0


def _central_angle_law_of_sines(off_nadir_rad: float) -> float:
    """Earth-central angle λ of a ray η off nadir from radius a + h onto a circle of radius a."""
    return float(np.arcsin((A_M + ALTITUDE_M) / A_M * np.sin(off_nadir_rad)) - off_nadir_rad)


def test_ray_from_above_the_pole_hits_the_polar_semi_axis():
    p = camera.intersect_ellipsoid(np.array([0.0, 0.0, 8e6]), np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(p, [0.0, 0.0, B_M], rtol=0, atol=1e-6)


def test_ray_pointing_away_or_past_the_limb_misses():
    p = camera.intersect_ellipsoid(np.array([[7e6, 0, 0], [7e6, 0, 0]]), np.array([[1.0, 0, 0], [0, 1.0, 0]]))
    assert np.all(np.isnan(p))


def test_intersections_lie_on_the_ellipsoid():
    rng = np.random.default_rng(7)
    origin = rng.normal(size=(500, 3))
    origin *= (A_M + ALTITUDE_M) / np.linalg.norm(origin, axis=-1, keepdims=True)
    direction = -origin + rng.normal(scale=2e6, size=(500, 3))
    p = camera.intersect_ellipsoid(origin, direction)
    hit = ~np.isnan(p[:, 0])
    assert hit.sum() > 400
    assert np.max(np.abs(_ellipsoid_residual(p[hit]))) < SURFACE_TOL


def test_line_of_sight_at_nadir_over_the_equator_is_the_equator_point():
    np.testing.assert_allclose(camera.line_of_sight_ecef_m(R_EQ_M, C_EB_EQ), [A_M, 0.0, 0.0], rtol=0, atol=1e-6)


def test_ccd_line_ends_match_the_law_of_sines_on_the_equator_circle():
    half_across = np.radians(10.0)
    line = camera.ccd_line_ecef_m(R_EQ_M, C_EB_EQ, half_across, n_points=5)
    lam = np.arctan2(line[:, 1], line[:, 0])
    assert abs(lam[-1] - _central_angle_law_of_sines(half_across)) < ANGLE_TOL_RAD
    assert abs(lam[0] + _central_angle_law_of_sines(half_across)) < ANGLE_TOL_RAD
    assert abs(lam[2]) < ANGLE_TOL_RAD


def test_footprint_rays_pass_through_the_satellite_along_the_designed_body_rays():
    rays_b = camera.camera_rays_b(np.radians(2.0), np.radians(1.0), 3)
    poly = camera.footprint_ecef_m(R_EQ_M, C_EB_EQ, np.radians(2.0), np.radians(1.0), 3)
    seen = (poly - R_EQ_M) / np.linalg.norm(poly - R_EQ_M, axis=-1, keepdims=True)
    np.testing.assert_allclose(seen, rays_b @ C_EB_EQ.T, rtol=0, atol=PARALLEL_TOL)
    assert np.max(np.abs(_ellipsoid_residual(poly))) < SURFACE_TOL


def test_footprint_across_track_edge_midpoint_matches_the_law_of_sines():
    half_across = np.radians(3.0)
    poly = camera.footprint_ecef_m(R_EQ_M, C_EB_EQ, half_across, np.radians(1.0), 2)
    mid = 5  # two rays per edge, counter-clockwise: vertex 5 is (along 0, across +tan α), in the equator plane
    np.testing.assert_allclose(camera.camera_rays_b(half_across, np.radians(1.0), 2)[mid, 1], 0.0, atol=1e-15)
    lam = np.arctan2(poly[mid, 1], poly[mid, 0])
    assert abs(lam - _central_angle_law_of_sines(half_across)) < ANGLE_TOL_RAD
    assert abs(poly[mid, 2]) < 1e-6


def test_ground_trace_matches_iterative_geodetic_latitude_and_normal_through_the_satellite():
    rng = np.random.default_rng(3)
    r = rng.normal(size=(2000, 3))
    r *= (A_M + rng.uniform(300e3, 1500e3, size=(2000, 1))) / np.linalg.norm(r, axis=-1, keepdims=True)
    p = camera.ground_trace_ecef_m(r)
    assert np.max(np.abs(_ellipsoid_residual(p))) < SURFACE_TOL
    lat_iter, lon_iter, _ = frames.ecef_to_geodetic(r)
    lat, lon, alt = frames.ecef_to_geodetic(p)
    assert np.max(np.abs(np.radians(lat - lat_iter))) < BOWRING_TOL_RAD
    assert np.max(np.abs(alt)) < 1e-3
    normal = p * np.array([1 / A_M**2, 1 / A_M**2, 1 / B_M**2])
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    up = (r - p) / np.linalg.norm(r - p, axis=-1, keepdims=True)
    assert np.max(np.linalg.norm(np.cross(normal, up), axis=-1)) < TRACE_NORMAL_TOL


def test_survey_zone_bounds_on_a_northbound_equator_crossing_match_the_law_of_sines():
    max_roll = np.radians(30.0)
    v = np.array([0.0, 0.0, 7560.0])  # heading north: the right of the track is east (+y)
    left, right = camera.survey_zone_bounds_ecef_m(R_EQ_M, v, max_roll)
    lam = _central_angle_law_of_sines(max_roll)
    assert abs(np.arctan2(right[1], right[0]) - lam) < ANGLE_TOL_RAD
    assert abs(np.arctan2(left[1], left[0]) + lam) < ANGLE_TOL_RAD


def test_station_circle_points_see_the_satellite_at_the_elevation_mask():
    lat, lon, mask_deg = 67.86, 20.96, 5.0  # Kiruna
    circle = camera.station_visibility_circle_ecef_m(lat, lon, ALTITUDE_M, mask_deg, n_points=36)
    station = frames.geodetic_to_ecef(lat, lon, 0.0)
    radius = np.linalg.norm(station)
    sat = circle / np.linalg.norm(circle, axis=-1, keepdims=True) * (radius + ALTITUDE_M)
    los = sat - station
    elevation = np.arcsin(los @ (station / radius) / np.linalg.norm(los, axis=-1))
    np.testing.assert_allclose(elevation, np.radians(mask_deg), rtol=0, atol=ANGLE_TOL_RAD)


def test_terminator_points_have_the_sun_on_their_geodetic_horizon():
    sun = np.array([1.2e11, -8.0e10, 4.0e10])
    points = camera.terminator_ecef_m(sun, n_points=90)
    lat, lon, alt = frames.ecef_to_geodetic(points)
    la, lo = np.radians(lat), np.radians(lon)
    up = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1)
    np.testing.assert_allclose(up @ (sun / np.linalg.norm(sun)), 0.0, rtol=0, atol=PARALLEL_TOL)
    assert np.max(np.abs(alt)) < 1e-3


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: camera.intersect_ellipsoid(np.zeros(2), np.ones(3)), "origin_m"),
        (lambda: camera.line_of_sight_ecef_m(R_EQ_M, np.eye(2)), "c_eb"),
        (lambda: camera.footprint_ecef_m(R_EQ_M, C_EB_EQ, 2.0, 0.1), "half_across_rad"),
        (lambda: camera.ccd_line_ecef_m(R_EQ_M, C_EB_EQ, 0.1, n_points=1), "n_points"),
        (lambda: camera.station_visibility_circle_ecef_m(95.0, 0.0, ALTITUDE_M, 5.0), "lat_deg"),
        (lambda: camera.station_visibility_circle_ecef_m(0.0, 0.0, ALTITUDE_M, 95.0), "min_elevation_deg"),
    ],
)
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()


MU_M3_S2 = 3.986004418e14
IMAGE_RATE_TOL_RAD_S = 1e-9  # central difference with h = 0.01 s: O(h²) terms ≈ 1e-11 rad/s, round-off 1e-12


def test_image_motion_of_the_nadir_point_is_minus_n_r_over_h_for_an_orbit_locked_camera():
    """Non-rotating sphere, circular orbit, body = ORF (x nadir, y along track, z = x × y): the point
    at nadir moves backwards along track at n R / h in the focal plane (ρ̇_y = −v + n h = −n R)."""
    radius = A_M + ALTITUDE_M
    n = np.sqrt(MU_M3_S2 / radius**3)
    r, v = np.array([radius, 0.0, 0.0]), np.array([0.0, n * radius, 0.0])
    c_ib = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])  # columns x^o, y^o, z^o in ECI
    from sim_core import quaternion

    q_ib = quaternion.from_dcm(c_ib)
    omega_b = np.array([0.0, 0.0, -n])  # ORF turns about the orbit normal = −z^o
    rate = camera.image_motion_rad_s(r, v, q_ib, omega_b, np.array([A_M, 0.0, 0.0]), np.zeros(3))
    np.testing.assert_allclose(rate, [-n * A_M / ALTITUDE_M, 0.0], rtol=1e-12, atol=1e-15)


def test_image_motion_matches_finite_differences_of_the_exact_geometry():
    """Circular inclined orbit, constant body rate, a ground point turning with the Earth: the rate of
    its tangent-plane coordinates by central differences of the closed-form motion."""
    from sim_core import orbit, quaternion
    from sim_core.attitude_spline import exp_rotation

    omega_b = np.array([0.002, -0.01, 0.004])
    r0, _ = orbit.circular_orbit(np.array([0.0]), ALTITUDE_M, 97.8, 10.0, -25.0)
    p0 = r0[0] * A_M / np.linalg.norm(r0[0]) + np.array([30e3, -20e3, 40e3])  # a point near nadir
    x = (p0 - r0[0]) / np.linalg.norm(p0 - r0[0])  # boresight on the point at t = 0
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    q0 = quaternion.from_dcm(np.stack([x, y, np.cross(x, y)], axis=-1))
    we = frames.EARTH_ROTATION_RATE_RAD_S

    def state(t: float):
        r, v = orbit.circular_orbit(np.array([t]), ALTITUDE_M, 97.8, 10.0, -25.0)
        q = quaternion.multiply(q0, exp_rotation(omega_b * t))
        c, s = np.cos(we * t), np.sin(we * t)
        p = np.array([c * p0[0] - s * p0[1], s * p0[0] + c * p0[1], p0[2]])
        return r[0], v[0], q, p

    def tangent(t: float) -> np.ndarray:
        r, _, q, p = state(t)
        rho = quaternion.rotate(quaternion.conjugate(q), p - r)
        return rho[1:] / rho[0]

    h = 0.01
    truth = (tangent(h) - tangent(-h)) / (2 * h)
    r, v, q, p = state(0.0)
    rate = camera.image_motion_rad_s(r, v, q, omega_b, p, camera.ground_point_velocity_eci_m_s(p))
    np.testing.assert_allclose(tangent(0.0), 0.0, atol=1e-12)  # the point sits on the boresight at t = 0
    np.testing.assert_allclose(rate, truth, rtol=0, atol=IMAGE_RATE_TOL_RAD_S)
