"""Attitude spline against exact truths: it passes through the samples, a constant-rate rotation
(closed form Λ0 ∘ exp(ω t)) is reproduced between samples, its analytic body rate obeys the
kinematics Λ̇ = ½ Λ ∘ ω (finite differences), and the left and right derivatives agree at every knot
for uneven sample spacing (C¹), where piecewise slerp visibly breaks."""

from __future__ import annotations

import numpy as np
import pytest

from sim_core import attitude_spline, quaternion
from sim_core.attitude_spline import AttitudeSpline

EXACT_TOL = 1e-12  # float64 round-off on unit quaternions
KNOT_STEP_S = 1e-6  # one-sided difference step at the knots
# one-sided differences carry O(δ · |ω̇|) truncation; δ = 1e-6 s and |ω̇| ≲ 1 rad/s² → ≤ 1e-6 rad/s
C1_TOL_RAD_S = 1e-5
SLERP_KINK_MIN_RAD_S = 1e-2  # a C⁰ slerp through the same samples jumps by more than this
FD_STEP_S = 1e-5
FD_TOL_RAD_S = 1e-7  # central difference O(δ²|ω̈|) plus round-off 1e-16/δ


def _random_samples(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.3, 2.0, size=n))  # uneven spacing
    steps = attitude_spline.exp_rotation(rng.normal(scale=0.3, size=(n, 3)))
    q = steps[0:1]
    for s in steps[1:]:
        q = np.vstack([q, quaternion.multiply(q[-1], s)])
    return t, q


def _body_rate_fd(spline: AttitudeSpline, t: float, step: float, side: int) -> np.ndarray:
    """One-sided body rate 2 log(Λ̃(t) ∘ Λ(t ± δ)) / (±δ)."""
    q0, q1 = spline.attitude(t), spline.attitude(t + side * step)
    return attitude_spline.log_rotation(quaternion.multiply(quaternion.conjugate(q0), q1)) / (side * step)


def test_spline_passes_exactly_through_every_sample():
    t, q = _random_samples(12, seed=1)
    spline = AttitudeSpline(t, q)
    d = quaternion.angle(quaternion.multiply(quaternion.conjugate(q), spline.attitude(t)))
    assert np.max(d) < EXACT_TOL * 100


def test_constant_rate_rotation_is_reproduced_between_uneven_samples():
    omega = np.array([0.02, -0.5, 0.3])
    q0 = quaternion.normalize(np.array([0.3, -0.2, 0.9, 0.1]))
    t = np.array([0.0, 0.4, 1.7, 2.0, 3.9, 4.2])
    q = quaternion.multiply(q0, attitude_spline.exp_rotation(t[:, None] * omega))
    spline = AttitudeSpline(t, q)
    tq = np.linspace(0.0, 4.2, 301)
    truth = quaternion.multiply(q0, attitude_spline.exp_rotation(tq[:, None] * omega))
    err = quaternion.angle(quaternion.multiply(quaternion.conjugate(truth), spline.attitude(tq)))
    assert np.max(err) < 1e-10
    np.testing.assert_allclose(spline.rate_b_rad_s(tq), np.broadcast_to(omega, (tq.size, 3)), rtol=0, atol=1e-10)


def test_left_and_right_derivatives_agree_at_every_knot_for_uneven_spacing():
    t, q = _random_samples(10, seed=2)
    spline = AttitudeSpline(t, q)
    for tk in t[1:-1]:
        left = _body_rate_fd(spline, tk, KNOT_STEP_S, -1)
        right = _body_rate_fd(spline, tk, KNOT_STEP_S, +1)
        assert np.linalg.norm(left - right) < C1_TOL_RAD_S


def test_piecewise_slerp_through_the_same_samples_has_kinks_the_spline_removes():
    t, q = _random_samples(6, seed=2)
    k = 2
    before = quaternion.slerp(q[k - 1], q[k], 1.0 - KNOT_STEP_S / (t[k] - t[k - 1]))
    after = quaternion.slerp(q[k], q[k + 1], KNOT_STEP_S / (t[k + 1] - t[k]))
    w_left = attitude_spline.log_rotation(quaternion.multiply(quaternion.conjugate(before), q[k])) / KNOT_STEP_S
    w_right = attitude_spline.log_rotation(quaternion.multiply(quaternion.conjugate(q[k]), after)) / KNOT_STEP_S
    assert np.linalg.norm(w_left - w_right) > SLERP_KINK_MIN_RAD_S


def test_analytic_body_rate_obeys_the_kinematics_by_central_differences():
    t, q = _random_samples(8, seed=3)
    spline = AttitudeSpline(t, q)
    for tc in np.linspace(t[0] + 0.01, t[-1] - 0.01, 37):
        fd = 0.5 * (_body_rate_fd(spline, tc, FD_STEP_S, +1) + _body_rate_fd(spline, tc, FD_STEP_S, -1))
        np.testing.assert_allclose(spline.rate_b_rad_s(tc), fd, rtol=0, atol=FD_TOL_RAD_S)


def test_given_telemetry_rates_are_the_spline_rates_at_the_samples():
    t, q = _random_samples(7, seed=4)
    omega = np.random.default_rng(5).normal(scale=0.1, size=(7, 3))
    spline = AttitudeSpline(t, q, omega)
    np.testing.assert_allclose(spline.rate_b_rad_s(t), omega, rtol=0, atol=1e-12)


def test_right_jacobian_is_the_derivative_of_the_exponential_and_its_inverse_inverts_it():
    rng = np.random.default_rng(6)
    for phi in [rng.normal(size=3), 1e-8 * rng.normal(size=3), 2.5 * rng.normal(size=3) / 2.0]:
        jr = attitude_spline.right_jacobian(phi)
        np.testing.assert_allclose(jr @ attitude_spline.right_jacobian_inverse(phi), np.eye(3), atol=1e-12)
        for axis in np.eye(3):  # exp(φ)⁻¹ ∘ exp(φ + δ a) ≈ exp(J_r(φ) a δ)
            d = 1e-6
            fwd = quaternion.multiply(
                quaternion.conjugate(attitude_spline.exp_rotation(phi)), attitude_spline.exp_rotation(phi + d * axis)
            )
            np.testing.assert_allclose(attitude_spline.log_rotation(fwd) / d, jr @ axis, atol=1e-6)


@pytest.mark.parametrize(
    ("args", "field"),
    [
        ((np.array([0.0]), np.array([[1.0, 0, 0, 0]])), "t_s"),
        ((np.array([0.0, 0.0]), np.array([[1.0, 0, 0, 0]] * 2)), "t_s"),
        ((np.array([0.0, 1.0]), np.array([[1.0, 0, 0]] * 2)), "q_ib"),
        ((np.array([0.0, 1.0]), np.array([[1.0, 0, 0, 0]] * 2), np.zeros((3, 3))), "omega_b_rad_s"),
    ],
)
def test_bad_input_names_the_field(args, field):
    with pytest.raises(ValueError, match=field):
        AttitudeSpline(*args)


def test_query_outside_the_samples_names_the_field():
    spline = AttitudeSpline(np.array([0.0, 1.0]), np.array([[1.0, 0, 0, 0]] * 2))
    with pytest.raises(ValueError, match="t_s"):
        spline.attitude(2.0)
