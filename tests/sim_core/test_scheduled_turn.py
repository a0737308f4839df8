"""Seed 001 scheduled turn against exact boundary conditions, kinematics, analytic plane turns."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from sim_core import quaternion as qt
from sim_core import scheduled_turn as stn

ROUND_OFF = 1e-12  # float64 round-off on unit quaternions and on rates of order 0.1 rad/s
KINEMATIC_CONSISTENCY = 1e-8  # issue 3: ω^p = 2 Λ̃∘Λ̇ and ω̇^p = dω^p/dt to this (rad/s, rad/s²)
FD_STEP_S = 1e-2  # 5-point stencil: truncation ~h⁴|x⁽⁵⁾| ≪ 1e-10, round-off ~1e-16/h = 1e-14
QUAD_ANGLE = 1e-12  # scipy.quad integrates a piecewise-linear rate to round-off (rad)


def _five_point(f, t: np.ndarray) -> np.ndarray:
    """Fourth-order central derivative of f at times t (independent of the program's own rates)."""
    h = FD_STEP_S
    return (f(t - 2 * h) - 8 * f(t - h) + 8 * f(t + h) - f(t + 2 * h)) / (12 * h)


def _smooth_times(plan: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Random times inside segments A, B, C, at least 3 stencil steps from any breakpoint."""
    t0, tau = plan[stn.T_START], plan[stn.TAU]
    breaks = np.array([0.0, plan[stn.T1], plan[stn.T2], tau])
    t = np.random.default_rng(seed).uniform(0.0, tau, 20 * n)
    keep = np.min(np.abs(t[:, None] - breaks[None, :]), axis=1) > 3 * FD_STEP_S
    return t0 + t[keep][:n]


def _rate_from_quaternion_derivative(plan: np.ndarray, t: np.ndarray) -> np.ndarray:
    q, _, _ = stn.scheduled_turn(plan, t)
    q_dot = _five_point(lambda s: stn.scheduled_turn(plan, s)[0], t)
    return 2.0 * qt.multiply(qt.conjugate(q), q_dot)


def _random_plan(seed: int, duration_s: float, rate_scale: float = 0.02) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q0, q1 = qt.normalize(rng.normal(size=(2, 4)))
    w0, w1 = rate_scale * rng.normal(size=(2, 3))
    return stn.plan_scheduled_turn(q0, w0, q1, w1, duration_s, t_start_s=1000.0)


def _same_rotation(p: np.ndarray, q: np.ndarray, tol: float) -> bool:
    return bool(np.all(np.abs(np.abs(np.sum(p * q, axis=-1)) - 1.0) <= tol))


@pytest.mark.parametrize("duration_s", [30.0, 143.0, 144.0, 600.0])
def test_boundary_conditions_met_to_round_off(duration_s):
    rng = np.random.default_rng(7)
    q0, q1 = qt.normalize(rng.normal(size=(2, 4)))
    w0, w1 = 0.02 * rng.normal(size=(2, 3))
    plan = stn.plan_scheduled_turn(q0, w0, q1, w1, duration_s, t_start_s=50.0)
    q, w, _ = stn.scheduled_turn(plan, np.array([50.0, 50.0 + duration_s]))
    assert np.max(np.abs(q[0] - q0)) < ROUND_OFF and np.max(np.abs(w[0] - w0)) < ROUND_OFF
    assert _same_rotation(q[1], q1, ROUND_OFF) and np.max(np.abs(w[1] - w1)) < ROUND_OFF


def test_end_state_is_continuous_from_inside_the_turn():
    plan = _random_plan(3, 300.0)
    t_end = plan[stn.T_START] + plan[stn.TAU]
    before, after = stn.scheduled_turn(plan, np.array([t_end - 1e-9, t_end]))[:2], stn.scheduled_turn(plan, t_end)[:2]
    assert np.max(np.abs(before[0][0] - after[0][0])) < 1e-10  # |ω| ~ 0.1 rad/s times 1e-9 s
    assert np.max(np.abs(before[1][0] - after[1][0])) < 1e-10


def test_transition_below_seed_clamp_still_meets_boundary():
    """A 0.001° transition: the seed's P = 0.0001 clamp would miss λ_k by ~1e-4, atan2 does not."""
    q0 = qt.normalize(np.array([0.3, -0.2, 0.5, 0.7]))
    for angle_rad in (np.radians(1e-3), 1e-12, 0.0):
        q1 = qt.multiply(q0, qt.from_axis_angle(np.array([1.0, 2.0, 3.0]), angle_rad))
        plan = stn.plan_scheduled_turn(q0, np.zeros(3), q1, np.zeros(3), 100.0)
        q, w, _ = stn.scheduled_turn(plan, np.array([0.0, 37.0, 100.0]))
        assert _same_rotation(q[2], q1, ROUND_OFF) and np.all(np.isfinite(w))
        assert abs(plan[stn.ANGLE2] - angle_rad) < ROUND_OFF


@pytest.mark.parametrize("duration_s", [60.0, 300.0])
def test_rate_equals_twice_conjugate_times_quaternion_derivative(duration_s):
    plan = _random_plan(11, duration_s)
    t = _smooth_times(plan, 40, seed=1)
    _, w, _ = stn.scheduled_turn(plan, t)
    assert np.max(np.abs(_rate_from_quaternion_derivative(plan, t)[:, 1:] - w)) < KINEMATIC_CONSISTENCY


@pytest.mark.parametrize("duration_s", [60.0, 300.0])
def test_acceleration_equals_derivative_of_rate(duration_s):
    plan = _random_plan(12, duration_s)
    t = _smooth_times(plan, 40, seed=2)
    _, _, wd = stn.scheduled_turn(plan, t)
    wd_numeric = _five_point(lambda s: stn.scheduled_turn(plan, s)[1], t)
    assert np.max(np.abs(wd_numeric - wd)) < KINEMATIC_CONSISTENCY


unit_quaternions = (
    st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: np.array(v) / np.linalg.norm(v))
)
body_rates = st.lists(st.floats(-0.05, 0.05), min_size=3, max_size=3).map(np.array)


@settings(max_examples=60, deadline=None)
@given(q0=unit_quaternions, q1=unit_quaternions, w0=body_rates, w1=body_rates, duration_s=st.floats(5.0, 900.0))
def test_property_boundaries_and_kinematics_for_random_conditions(q0, q1, w0, w1, duration_s):
    plan = stn.plan_scheduled_turn(q0, w0, q1, w1, duration_s)
    q, w, _ = stn.scheduled_turn(plan, np.array([0.0, duration_s]))
    w0_kept = np.where(np.linalg.norm(w0) > stn.RATE_EPSILON_RAD_S, w0, 0.0)
    w1_kept = np.where(np.linalg.norm(w1) > stn.RATE_EPSILON_RAD_S, w1, 0.0)
    assert np.max(np.abs(q[0] - q0)) < ROUND_OFF and _same_rotation(q[1], q1, ROUND_OFF)
    assert np.max(np.abs(w[0] - w0_kept)) < ROUND_OFF and np.max(np.abs(w[1] - w1_kept)) < ROUND_OFF
    t = _smooth_times(plan, 5, seed=int(duration_s * 1000) % 2**31)
    q_t, w_t, wd_t = stn.scheduled_turn(plan, t)
    assert np.allclose(np.linalg.norm(q_t, axis=1), 1.0, atol=ROUND_OFF)
    assert np.max(np.abs(_rate_from_quaternion_derivative(plan, t)[:, 1:] - w_t)) < KINEMATIC_CONSISTENCY
    wd_numeric = _five_point(lambda s: stn.scheduled_turn(plan, s)[1], t)
    assert np.max(np.abs(wd_numeric - wd_t)) < KINEMATIC_CONSISTENCY


def test_trapezoid_has_t1_72_s_and_a_plateau_only_from_144_s():
    for duration_s, has_plateau in ((100.0, False), (143.9, False), (144.0, False), (144.5, True), (500.0, True)):
        plan = _random_plan(5, duration_s)
        expected_t1 = stn.ACCELERATION_TIME_S if duration_s >= 144.0 else duration_s / 2
        assert plan[stn.T1] == expected_t1 and plan[stn.T2] == duration_s - expected_t1
        segments = stn.turn_segment(plan, plan[stn.T_START] + np.linspace(0.0, duration_s, 20001))
        assert (stn.SEGMENT_B in segments) == has_plateau
        assert segments[-1] == stn.SEGMENT_D and segments[0] == stn.SEGMENT_A


def _trapezoid_rate(t: float, angle: float, duration: float) -> float:
    t1 = 72.0 if duration >= 144.0 else duration / 2
    peak = angle / (duration - t1)
    return peak * min(t / t1, 1.0, (duration - t) / t1)


@pytest.mark.parametrize("duration_s", [100.0, 400.0])
def test_rest_to_rest_single_axis_turn_follows_integrated_trapezoid(duration_s):
    angle = np.radians(20.0)
    axis = np.array([0.0, 1.0, 0.0])  # a 20° roll about y^o, seed 000 §5
    plan = stn.plan_scheduled_turn(
        np.array([1.0, 0, 0, 0]), np.zeros(3), qt.from_axis_angle(axis, angle), np.zeros(3), duration_s
    )
    t = np.linspace(0.0, duration_s, 37)
    q, w, wd = stn.scheduled_turn(plan, t)
    theta = np.array(
        [
            quad(
                _trapezoid_rate,
                0.0,
                ti,
                args=(angle, duration_s),
                points=[72.0, duration_s - 72.0, duration_s / 2],
                epsabs=1e-14,
            )[0]
            for ti in t
        ]
    )
    assert np.max(np.abs(q - qt.from_axis_angle(axis, theta))) < QUAD_ANGLE
    rate = np.array([_trapezoid_rate(ti, angle, duration_s) for ti in t])
    assert np.max(np.abs(w - rate[:, None] * axis)) < ROUND_OFF
    assert np.max(np.abs(wd[:, [0, 2]])) < ROUND_OFF  # the corrected segment A acceleration is along e2
    assert wd[1, 1] == pytest.approx(plan[stn.ACC2], rel=ROUND_OFF)


def test_pure_rate_damping_is_linear_deceleration():
    """λ_k reached by damping ω_n alone: φ2 = 0 and ω(T) = ω_n (τ − T)/τ (seed 001 ГНС)."""
    w0, tau = np.array([0.0, 0.0, 0.01]), 120.0
    q1 = qt.from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.5 * 0.01 * tau)
    plan = stn.plan_scheduled_turn(np.array([1.0, 0, 0, 0]), w0, q1, np.zeros(3), tau)
    t = np.linspace(0.0, tau, 13)[:-1]
    _, w, wd = stn.scheduled_turn(plan, t)
    assert plan[stn.ANGLE2] < ROUND_OFF
    assert np.max(np.abs(w - w0 * ((tau - t) / tau)[:, None])) < ROUND_OFF
    assert np.max(np.abs(wd - (-w0 / tau))) < ROUND_OFF


def test_segment_d_keeps_the_final_rate_about_a_fixed_axis():
    plan = _random_plan(9, 200.0)
    t_end = plan[stn.T_START] + plan[stn.TAU]
    q_end, w_end, _ = stn.scheduled_turn(plan, t_end)
    dt = np.array([0.0, 10.0, 250.0])
    q, w, wd = stn.scheduled_turn(plan, t_end + dt)
    angle = np.linalg.norm(w_end[0]) * dt
    exact = qt.multiply(q_end[0], qt.from_axis_angle(w_end[0], angle))
    assert np.max(np.abs(q - exact)) < ROUND_OFF and np.max(np.abs(w - w_end[0])) < ROUND_OFF
    assert np.all(wd == 0.0)


def test_envelope_bounds_hold_and_are_tight_rest_to_rest():
    plan = _random_plan(21, 250.0, rate_scale=0.03)
    env = stn.turn_envelope(plan)
    t = plan[stn.T_START] + np.linspace(0.0, env.duration_s, 5001)
    _, w, wd = stn.scheduled_turn(plan, t)
    assert np.max(np.linalg.norm(w, axis=1)) <= env.max_rate_bound_rad_s
    assert np.max(np.linalg.norm(wd, axis=1)) <= env.max_acceleration_bound_rad_s2
    rest = stn.plan_scheduled_turn(
        np.array([1.0, 0, 0, 0]), np.zeros(3), np.array([0.0, 1.0, 0, 0]), np.zeros(3), 250.0
    )
    env = stn.turn_envelope(rest)
    _, w, wd = stn.scheduled_turn(rest, np.linspace(0.0, 250.0, 5001))
    assert np.max(np.linalg.norm(w, axis=1)) == pytest.approx(env.max_rate_bound_rad_s, rel=ROUND_OFF)
    assert np.max(np.linalg.norm(wd, axis=1)) == pytest.approx(env.max_acceleration_bound_rad_s2, rel=ROUND_OFF)


@pytest.mark.parametrize(
    ("angle_deg", "max_rate_deg_s", "max_acc_deg_s2"),
    [(20.0, 1.0, 0.05), (20.0, 0.5, 0.5), (90.0, 0.5, 0.01), (90.0, 1.0, 0.002), (1.0, 0.1, 0.001)],
)
def test_shortest_rest_to_rest_duration_saturates_one_limit(angle_deg, max_rate_deg_s, max_acc_deg_s2):
    angle, w_max, a_max = np.radians([angle_deg, max_rate_deg_s, max_acc_deg_s2])
    tau = stn.shortest_rest_to_rest_duration_s(angle, w_max, a_max)
    plan = stn.plan_scheduled_turn(
        np.array([1.0, 0, 0, 0]), np.zeros(3), qt.from_axis_angle(np.array([0.0, 1.0, 0.0]), angle), np.zeros(3), tau
    )
    env = stn.turn_envelope(plan)
    rate_use, acc_use = env.transition_rate_rad_s / w_max, env.transition_acceleration_rad_s2 / a_max
    assert max(rate_use, acc_use) == pytest.approx(1.0, rel=1e-12) and min(rate_use, acc_use) <= 1.0 + 1e-12


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"q_start": np.array([1.0, 1.0, 0, 0])}, "q_start"),
        ({"q_end": np.array([1.0, 0, 0])}, "q_end"),
        ({"omega_start_b_rad_s": np.array([np.nan, 0, 0])}, "omega_start_b_rad_s"),
        ({"omega_end_b_rad_s": np.zeros(4)}, "omega_end_b_rad_s"),
        ({"duration_s": 0.0}, "duration_s"),
        ({"t_start_s": np.inf}, "t_start_s"),
    ],
)
def test_bad_input_names_the_field(kwargs, field):
    good = {
        "q_start": np.array([1.0, 0, 0, 0]),
        "omega_start_b_rad_s": np.zeros(3),
        "q_end": np.array([1.0, 0, 0, 0]),
        "omega_end_b_rad_s": np.zeros(3),
        "duration_s": 100.0,
        "t_start_s": 0.0,
    }
    with pytest.raises(ValueError, match=field):
        stn.plan_scheduled_turn(**{**good, **kwargs})


def test_times_before_the_start_are_refused():
    plan = _random_plan(1, 100.0)
    with pytest.raises(ValueError, match="t_s"):
        stn.scheduled_turn(plan, plan[stn.T_START] - 1.0)
    with pytest.raises(ValueError, match="plan"):
        stn.scheduled_turn(plan[:10], 0.0)


def test_seed_acceleration_sum_misses_the_transport_terms_we_add():
    """Seed 001 ε_пр (three relative accelerations only) differs from dω^p/dt when the axes differ."""
    plan = _random_plan(31, 300.0, rate_scale=0.03)
    t = _smooth_times(plan, 20, seed=4)
    tt, tau = t - plan[stn.T_START], plan[stn.TAU]
    e1, e2, e3 = plan[stn.E1 : stn.E1 + 3], plan[stn.E2 : stn.E2 + 3], plan[stn.E3 : stn.E3 + 3]
    w_start, w_end, acc = plan[stn.RATE_START], plan[stn.RATE_END], plan[stn.ACC2]
    segment = stn.turn_segment(plan, t)
    phi2 = np.where(
        segment == stn.SEGMENT_A,
        0.5 * acc * tt**2,
        np.where(
            segment == stn.SEGMENT_B,
            plan[stn.ANGLE2_T1] + plan[stn.RATE2] * (tt - plan[stn.T1]),
            plan[stn.ANGLE2] - 0.5 * acc * (tau - tt) ** 2,
        ),
    )
    eps2 = np.select([segment == stn.SEGMENT_A, segment == stn.SEGMENT_B], [acc, 0.0], -acc)
    lam3 = qt.from_axis_angle(np.broadcast_to(e3, (t.size, 3)), 0.5 * w_end * tt**2 / tau)
    lam23 = qt.multiply(qt.from_axis_angle(np.broadcast_to(e2, (t.size, 3)), phi2), lam3)
    seed_eps = (
        qt.rotate(qt.conjugate(lam23), np.broadcast_to(-w_start / tau * e1, (t.size, 3)))
        + qt.rotate(qt.conjugate(lam3), eps2[:, None] * e2)
        + w_end / tau * e3
    )
    wd_true = _five_point(lambda s: stn.scheduled_turn(plan, s)[1], t)
    _, _, wd = stn.scheduled_turn(plan, t)
    assert np.max(np.abs(wd - wd_true)) < KINEMATIC_CONSISTENCY
    assert np.max(np.abs(seed_eps - wd_true)) > 1e3 * KINEMATIC_CONSISTENCY, np.max(np.abs(seed_eps - wd_true))
