"""TRIAD and the star-tracker least squares against scipy's Wahba solvers and first-order error theory."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sim_core import estimation as est
from sim_core import quaternion as qt
from sim_core import sensors

EXACT = 1e-12  # float64 round-off on unit quaternions and angles (rad)
N_MC = 20_000
STAT_SIGMAS = 5.0  # statistic within 5 of its standard errors
SIGMA_VEC = 1e-3  # rad, direction noise per perpendicular axis


def _quat_error(q_true, q_est):
    return qt.angle(qt.multiply(qt.conjugate(q_true), q_est))


def _perturb(w_b, sigma, rng):
    """Unit vectors rotated by a random small rotation: σ per axis perpendicular to each vector."""
    return qt.rotate(sensors.rotation_noise_quaternion(sigma * rng.standard_normal(w_b.shape)), w_b)


def _cross_mat(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def _triad_first_order_covariance(w1, w2, s1, s2):
    """Body-frame TRIAD error covariance by first-order propagation of the two direction errors.

    δθ = ν1 × W1 + a W1 with a = −(⟨ν2, n⟩ + ⟨ν1 × W1, W2 × n⟩)/|W1 × W2|, n = W1×W2/|W1×W2|:
    W1 is matched exactly, W2 only in the plane normal to n.
    """
    x = np.cross(w1, w2)
    s = np.linalg.norm(x)
    n = x / s
    m1 = -_cross_mat(w1) - np.outer(w1, np.cross(w2, n) @ -_cross_mat(w1)) / s
    m2 = -np.outer(w1, n) / s
    i3 = np.eye(3)
    return s1**2 * m1 @ (i3 - np.outer(w1, w1)) @ m1.T + s2**2 * m2 @ (i3 - np.outer(w2, w2)) @ m2.T


def test_triad_recovers_known_attitudes_exactly_without_noise():
    rng = np.random.default_rng(1)
    q = qt.normalize(rng.normal(size=(50, 4)))
    u_i, v_i = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    u_b, v_b = qt.rotate(qt.conjugate(q), u_i), qt.rotate(qt.conjugate(q), v_i)
    assert np.all(_quat_error(q, est.triad(u_b, v_b, u_i, v_i)) < EXACT)
    for k in range(50):
        assert _quat_error(q[k], est.triad_1(u_b[k], v_b[k], u_i[k], v_i[k])) < EXACT


def test_triad_equals_scipy_align_vectors_with_infinite_main_vector_weight():
    rng = np.random.default_rng(2)
    for _ in range(50):
        q = qt.normalize(rng.normal(size=4))
        refs = rng.normal(size=(2, 3))
        refs /= np.linalg.norm(refs, axis=-1, keepdims=True)
        meas = _perturb(qt.rotate(qt.conjugate(q), refs), 0.01, rng)
        ours = est.triad(meas[0], meas[1], refs[0], refs[1])
        # scipy aligns an infinitely weighted primary vector exactly, then the second as well as it can
        theirs = Rotation.align_vectors(refs, meas, weights=[np.inf, 1.0])[0].as_quat(scalar_first=True)
        assert _quat_error(theirs, ours) < 1e-10  # scipy's SVD path loses a few digits


def test_triad_error_covariance_matches_first_order_propagation():
    rng = np.random.default_rng(3)
    q = qt.normalize(rng.normal(size=4))
    refs = np.array([[0.2, 0.9, -0.1], [0.7, -0.3, 0.6]])
    refs /= np.linalg.norm(refs, axis=-1, keepdims=True)
    w = qt.rotate(qt.conjugate(q), refs)
    s1, s2 = SIGMA_VEC, 3 * SIGMA_VEC  # a fine main sensor, a coarse auxiliary one
    u_m = _perturb(np.tile(w[0], (N_MC, 1)), s1, rng)
    v_m = _perturb(np.tile(w[1], (N_MC, 1)), s2, rng)
    e = qt.multiply(qt.conjugate(q), est.triad(u_m, v_m, refs[0], refs[1]))
    err = 2.0 * e[:, 1:] * np.sign(e[:, :1])
    p = _triad_first_order_covariance(w[0], w[1], s1, s2)
    l_inv = np.linalg.inv(np.linalg.cholesky(p))
    white = np.cov((err @ l_inv.T).T)  # should be I: entries within ~√(2/n) of it
    assert np.all(np.abs(white - np.eye(3)) < STAT_SIGMAS * np.sqrt(2.0 / N_MC))


def _star_field(rng, n_stars, q):
    """n unit star directions in an 8° field of view around the body +z boresight, in IRF and body."""
    off = np.radians(4.0) * rng.uniform(-1, 1, size=(n_stars, 2))
    b = np.column_stack([off, np.ones(n_stars)])
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    return b, qt.rotate(q, b)


def test_lsm_recovers_known_attitude_exactly_from_a_2_deg_prior():
    rng = np.random.default_rng(4)
    for _ in range(20):
        q = qt.normalize(rng.normal(size=4))
        stars_b, stars_i = _star_field(rng, 6, q)
        prior = qt.multiply(q, qt.from_axis_angle(rng.normal(size=3), np.radians(2.0)))
        q_hat, _ = est.star_tracker_lsm(stars_b, stars_i, prior)
        assert _quat_error(q, q_hat) < EXACT


def test_lsm_converges_to_the_davenport_optimum_of_scipy_align_vectors():
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = qt.normalize(rng.normal(size=4))
        stars_b, stars_i = _star_field(rng, 8, q)
        meas = _perturb(stars_b, 5 * sensors.ARCSEC, rng)
        q_hat, _ = est.star_tracker_lsm(meas, stars_i, q)
        # iterated LSM solves Hᵀz = 0 = the gradient of Wahba's loss, whose minimum scipy finds
        wahba = Rotation.align_vectors(stars_i, meas)[0].as_quat(scalar_first=True)
        assert _quat_error(wahba, q_hat) < 1e-10


def test_lsm_error_covariance_matches_r_inverse_hth():
    rng = np.random.default_rng(6)
    q = qt.normalize(rng.normal(size=4))
    stars_b, stars_i = _star_field(rng, 5, q)
    sigma = 5 * sensors.ARCSEC
    n = 1500
    errs = np.empty((n, 3))
    for k in range(n):
        q_hat, cov = est.star_tracker_lsm(_perturb(stars_b, sigma, rng), stars_i, q, sigma**2)
        e = qt.multiply(qt.conjugate(q), q_hat)
        errs[k] = 2.0 * e[1:] * np.sign(e[0])
    # noise ⊥ each star: Hᵀ(I − RRᵀ)H = HᵀH, so the estimate covariance is σ²(HᵀH)⁻¹ (eq 13)
    white = np.cov((errs @ np.linalg.inv(np.linalg.cholesky(cov)).T).T)
    assert np.all(np.abs(white - np.eye(3)) < STAT_SIGMAS * np.sqrt(2.0 / n))


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: est.triad([1, 0, 0], [2, 0, 0], [1, 0, 0], [0, 1, 0]), "u_b, v_b"),
        (lambda: est.triad([1, 0, 0], [0, 1, 0], [0, 0, 0], [0, 1, 0]), "u_i"),
        (lambda: est.star_tracker_lsm(np.eye(3)[:1], np.eye(3)[:1], [1, 0, 0, 0]), "stars_b"),
        (
            lambda: est.star_tracker_lsm(
                np.array([[0, 0, 1.0], [0, 0, 1.0]]), np.array([[0, 0, 1.0], [0, 0, 1.0]]), [1, 0, 0, 0]
            ),
            "collinear",
        ),
    ],
)
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()


unit_quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1)
vectors = st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 1e-3)
MIN_SEPARATION = np.radians(1.0)  # TRIAD's error grows as 1/sin(angle between U and V)


@settings(max_examples=200, deadline=None)
@given(unit_quaternions, vectors, vectors)
def test_triad_is_exact_for_any_attitude_and_distinct_vector_pair(q, u_i, v_i):
    u_i, v_i = np.array(u_i), np.array(v_i)
    sin_sep = np.linalg.norm(np.cross(u_i, v_i)) / (np.linalg.norm(u_i) * np.linalg.norm(v_i))
    assume(sin_sep > np.sin(MIN_SEPARATION))
    q = qt.normalize(np.array(q))
    u_b, v_b = qt.rotate(qt.conjugate(q), u_i), qt.rotate(qt.conjugate(q), v_i)
    # round-off is amplified by 1/sin(separation) in the auxiliary direction
    assert _quat_error(q, est.triad(u_b, v_b, u_i, v_i)) < EXACT / sin_sep
