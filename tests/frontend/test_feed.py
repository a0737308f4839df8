"""TrajectoryFeed against exact truths: the synthetic spacecraft points exactly along the analytic
orbital frame, its twin is rolled by exactly 1°, and the orbit is an exact circle."""

from __future__ import annotations

import numpy as np
import pytest

from frontend.feed import FeedWindow, TrajectoryFeed, TwinFeed, attitude_error_rad
from sim_core import frames, orbit, quaternion
from tests.frontend.conftest import synthetic_trajectory

ROLL_DEG = 1.0
SPLINE_TOL_RAD = 1e-7  # C¹ spline between 1 s samples of a 1.1 mrad/s rotation: O((ω h)⁴) ≪ 1e-7
SAMPLE_TOL_RAD = 1e-10
HERMITE_TOL_M = 5e-3  # table velocity is the 2nd-order difference of 1 s samples (h² |d³r/dt³| / 6 ≈ 1.6 mm/s),
# carried over 10 s table steps by the cubic Hermite: a few millimetres
VELOCITY_TOL_M_S = 5e-3  # the same 2nd-order difference: n² v h² / 6 ≈ 1.5 mm/s inside, twice that at the ends
J2_SHORT_PERIOD_M = 20e3  # J2 changes a circular radius by at most ~10 km within one orbit


@pytest.fixture(scope="module")
def feed() -> TrajectoryFeed:
    return TrajectoryFeed(synthetic_trajectory(offset_deg=ROLL_DEG), actual_variant=0, simulated_variant=1)


def _epoch(feed: TrajectoryFeed) -> float:
    return feed.span_unix_s()[0]


def test_feed_implements_the_twin_feed_protocol(feed):
    assert isinstance(feed, TwinFeed)


def test_actual_attitude_between_samples_is_the_analytic_orbital_frame(feed):
    t = np.linspace(0.3, 590.7, 97)
    r, v = orbit.circular_orbit(t, 600e3, 97.8, 30.0)
    truth = frames.orf_quaternion(r, v)
    assert np.max(attitude_error_rad(feed.attitude_actual(t + _epoch(feed)), truth)) < SPLINE_TOL_RAD


def test_attitude_error_against_the_rolled_twin_is_the_roll(feed):
    t0, t1 = feed.span_unix_s()
    w = feed.window(t0, t1)
    assert isinstance(w, FeedWindow) and w.t_unix_s.size == 601
    np.testing.assert_allclose(np.degrees(w.error_angle_rad), ROLL_DEG, rtol=0, atol=1e-9)


def test_orbit_inside_the_data_matches_the_circle_and_its_speed(feed):
    t = np.linspace(1.0, 599.0, 50)
    r, v = feed.orbit_eci(t + _epoch(feed))
    r_true, v_true = orbit.circular_orbit(t, 600e3, 97.8, 30.0)
    np.testing.assert_allclose(r, r_true, rtol=0, atol=HERMITE_TOL_M)
    np.testing.assert_allclose(v, v_true, rtol=0, atol=VELOCITY_TOL_M_S)


def test_orbit_beyond_the_data_stays_on_the_j2_perturbed_circle(feed):
    t0, t1 = feed.span_unix_s()
    t = np.concatenate([np.linspace(t0 - 5800.0, t0 - 10.0, 30), np.linspace(t1 + 10.0, t1 + 5800.0, 30)])
    r, _ = feed.orbit_eci(t)
    assert np.max(np.abs(np.linalg.norm(r, axis=-1) - orbit.R_EARTH_M - 600e3)) < J2_SHORT_PERIOD_M


def test_active_alarms_list_uncleared_faults_and_recent_saturations():
    traj = synthetic_trajectory()
    traj.events[0] = [
        (10.0, "fault_onset", 2),
        (20.0, "md_saturated", 0),
        (30.0, "fault_onset", 1),
        (40.0, "fault_cleared", 1),
    ]
    feed = TrajectoryFeed(traj)
    epoch = traj.extra["epoch_unix_s"]
    assert feed.active_alarms(epoch + 5.0) == []
    at_35 = feed.active_alarms(epoch + 35.0)
    assert any("fault 2" in a for a in at_35) and any("fault 1" in a for a in at_35)
    assert any("md_saturated" in a for a in at_35)
    at_200 = feed.active_alarms(epoch + 200.0)
    assert any("fault 2" in a for a in at_200)
    assert not any("fault 1" in a or "md_saturated" in a for a in at_200)


def test_attitude_samples_are_hit_exactly(feed):
    traj = synthetic_trajectory(offset_deg=ROLL_DEG)
    t = traj.t_s[::37] + _epoch(feed)
    q = feed.attitude_simulated(t)
    assert (
        np.max(quaternion.angle(quaternion.multiply(quaternion.conjugate(traj["q_ib"][1][::37]), q))) < SAMPLE_TOL_RAD
    )


@pytest.mark.parametrize(
    ("kwargs", "field"), [({"actual_variant": 5}, "actual_variant"), ({"simulated_variant": -1}, "simulated_variant")]
)
def test_bad_variant_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        TrajectoryFeed(synthetic_trajectory(), **kwargs)
