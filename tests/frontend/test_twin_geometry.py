"""Twin geometry against independent truths: the Earth node's rotation against the full IERS chain
of frames.py (skyfield precession-nutation, polar motion, DUT1), the Sun against DE421, the line of
sight of an exactly nadir-pointing spacecraft and of its twin rolled by exactly 1°."""

from __future__ import annotations

import numpy as np
import pytest

from frontend.twin_geometry import SCENE_UNIT_M, TwinGeometry
from sim_core import environment, frames, quaternion

FROZEN_EOP_TOL_RAD = 1e-6  # C, W, DUT1 frozen at the pass start: drift < 1e-6 rad per day (frames.py)
SUN_TOL_RAD = np.radians(0.02)  # Almanac low-precision Sun vs DE421 (environment.py: ≈ 0.01°)
LOS_TOL_RAD = 1e-9  # exact geometry in float64 on Earth-radius-scaled vectors
ROLL_DEG = 1.0


@pytest.fixture(scope="module")
def geometry(twin_feed) -> TwinGeometry:
    return TwinGeometry(twin_feed)


def test_earth_node_rotation_matches_the_full_iers_chain(geometry):
    t0, t1 = geometry.feed.span_unix_s()
    for t in (t0, 0.5 * (t0 + t1), t1):
        f = geometry.frame(t)
        axes = np.eye(3) * 7e6
        truth, _ = frames.ecef_to_eci(axes, np.zeros((3, 3)), np.full(3, t))
        shown = quaternion.rotate(np.broadcast_to(f.earth_wxyz, (3, 4)), axes)
        cosines = np.sum(truth * shown, axis=-1) / 7e6**2
        assert np.max(np.arccos(np.clip(cosines, -1, 1))) < FROZEN_EOP_TOL_RAD


def test_sun_direction_matches_de421(geometry):
    t0, _ = geometry.feed.span_unix_s()
    f = geometry.frame(t0 + 100.0)
    sun = environment.sun_position_eci_m(t0 + 100.0)
    assert np.arccos(np.clip(f.sun_dir_eci @ sun / np.linalg.norm(sun), -1, 1)) < SUN_TOL_RAD


def test_line_of_sight_of_the_nadir_pointer_is_below_the_spacecraft(geometry):
    t0, _ = geometry.feed.span_unix_s()
    f = geometry.frame(t0 + 200.0)
    sat_ecef = quaternion.rotate(quaternion.conjugate(f.earth_wxyz), f.sat_eci)
    u, p = sat_ecef / np.linalg.norm(sat_ecef), f.los_actual_ecef / np.linalg.norm(f.los_actual_ecef)
    assert np.linalg.norm(np.cross(u, p)) < LOS_TOL_RAD
    resid = (f.los_actual_ecef[:2] ** 2).sum() + f.los_actual_ecef[2] ** 2 / (1 - frames.WGS84_F) ** 2 - 1.0
    assert abs(resid) < 1e-12


def test_line_of_sight_of_the_rolled_twin_is_off_nadir_by_the_roll(geometry):
    t0, _ = geometry.feed.span_unix_s()
    f = geometry.frame(t0 + 300.0)
    sat_ecef = quaternion.rotate(quaternion.conjugate(f.earth_wxyz), f.sat_eci)
    d = f.los_simulated_ecef - sat_ecef
    off = np.arccos(-d @ sat_ecef / np.linalg.norm(d) / np.linalg.norm(sat_ecef))
    assert abs(np.degrees(off) - ROLL_DEG) < np.degrees(LOS_TOL_RAD) * 1e3


def test_footprint_surrounds_the_line_of_sight_point(geometry):
    t0, _ = geometry.feed.span_unix_s()
    f = geometry.frame(t0 + 50.0)
    centre = np.mean(f.footprint_actual_ecef, axis=0)
    half_diag_m = np.max(np.linalg.norm(f.footprint_actual_ecef - f.los_actual_ecef, axis=-1)) * SCENE_UNIT_M
    assert np.linalg.norm(centre - f.los_actual_ecef) * SCENE_UNIT_M < 0.05 * half_diag_m
    assert 10e3 < half_diag_m < 50e3  # 600 km × tan(2°, 1°) corners ≈ 23 km
    assert f.observing


def test_terminator_points_face_the_sun_edge_on(geometry):
    t0, _ = geometry.feed.span_unix_s()
    f = geometry.frame(t0)
    sun_ecef = quaternion.rotate(quaternion.conjugate(f.earth_wxyz), f.sun_dir_eci)
    lat, lon, _ = frames.ecef_to_geodetic(f.terminator_ecef * SCENE_UNIT_M)
    la, lo = np.radians(lat), np.radians(lon)
    up = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1)
    assert np.max(np.abs(up @ sun_ecef)) < 1e-9


def test_trace_split_moves_forward_with_time_and_trace_lies_on_the_ellipsoid(geometry):
    t0, t1 = geometry.feed.span_unix_s()
    splits = [geometry.frame(t).trace_split for t in np.linspace(t0, t1, 5)]
    assert splits == sorted(splits) and splits[-1] > splits[0]
    p = geometry.trace_ecef * SCENE_UNIT_M
    b = frames.WGS84_A_M * (1 - frames.WGS84_F)
    resid = (p[:, 0] ** 2 + p[:, 1] ** 2) / frames.WGS84_A_M**2 + p[:, 2] ** 2 / b**2 - 1.0
    assert np.max(np.abs(resid)) < 1e-12


def test_image_motion_of_the_nadir_pointer_runs_backwards_at_about_v_ground_over_h(geometry):
    """Orbit-locked nadir camera: the boresight point slides back at n R / h (± Earth rotation, ellipsoid)."""
    t0, _ = geometry.feed.span_unix_s()
    f = geometry.frame(t0 + 250.0)
    motion = geometry.image_motion_rad_s(t0 + 250.0)
    radius = np.linalg.norm(f.sat_eci) * SCENE_UNIT_M
    n = np.sqrt(3.986004418e14 / radius**3)
    height = radius - np.linalg.norm(f.los_actual_ecef) * SCENE_UNIT_M
    expected = -n * (radius - height) / height
    assert abs(motion[0] / expected - 1.0) < 0.08  # Earth rotation ≤ 6 % of the ground speed
    assert abs(motion[1]) < 0.08 * abs(expected)
