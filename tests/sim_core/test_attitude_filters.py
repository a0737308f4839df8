"""Steady-state Kalman filters of seed 003 eqs 15-19 and seed 000 §4 against Riccati solutions and transfer functions."""

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import solve_continuous_are, solve_discrete_are

from sim_core import attitude_filters as af
from sim_core import quaternion as qt
from sim_core import sensors

RICCATI = 1e-9  # relative agreement of two Riccati solvers in float64
EXACT = 1e-12
CASES = [(1e-6, 1e-8), (1e-10, 1e-10), (4e-3, 1.0)]  # (q, r) spectral densities


@pytest.mark.parametrize(("q", "r"), CASES)
def test_continuous_gains_solve_the_continuous_riccati_equation(q, r):
    k12, k22 = af.continuous_gains(q, r)
    a, h = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[1.0, 0.0]])
    p = solve_continuous_are(a.T, h.T, np.diag([0.0, q]), np.array([[r]]))
    k = (p @ h.T / r)[:, 0]  # gains on (α̂, ω̂): (k22, k12)
    assert np.allclose([k22, k12], k, rtol=RICCATI)


@pytest.mark.parametrize(("q", "r"), CASES)
def test_time_constant_is_xi_to_minus_quarter_and_damping_is_0707(q, r):
    t, d = af.time_constant_and_damping(*af.continuous_gains(q, r))
    assert t == pytest.approx((q / r) ** -0.25, rel=EXACT)
    assert d == pytest.approx(np.sqrt(2.0) / 2.0, rel=EXACT)


@pytest.mark.parametrize(("q", "r"), CASES)
@pytest.mark.parametrize("dt", [0.25, 2.0, 1e-3])
def test_discrete_gains_match_scipy_solve_discrete_are(q, r, dt):
    f, h = np.array([[1.0, dt], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    qd = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    rd = np.array([[r / dt]])
    p = solve_discrete_are(f.T, h.T, qd, rd)
    k = (p @ h.T / (h @ p @ h.T + rd))[:, 0]
    assert np.allclose(af.discrete_gains(q, r, dt), k, rtol=RICCATI)


def test_discrete_gains_tend_to_seed_003_continuous_gains_as_dt_shrinks():
    q, r = 1e-6, 1e-8
    k12, k22 = af.continuous_gains(q, r)
    xi4 = (q / r) ** 0.25
    for dt in (1e-2, 1e-3, 1e-4):
        k_a, k_w = af.discrete_gains(q, r, dt)
        # the sampling error of the gains is first order in dt/T = dt ξ^{1/4}
        assert abs(k_a / dt / k22 - 1) < dt * xi4
        assert abs(k_w / dt / k12 - 1) < dt * xi4


def test_discretised_estimator_equals_the_transfer_functions_of_eq_18():
    k12, k22 = af.continuous_gains(1e-6, 1e-8)
    t_c, d = af.time_constant_and_damping(k12, k22)
    dt, n = 0.05, 400
    z = np.repeat(np.random.default_rng(1).normal(size=n // 20), 20) * 1e-3  # held samples
    time = np.arange(n) * dt
    den = [t_c**2, 2 * d * t_c, 1.0]
    _, omega_tf, _ = signal.lsim(([1.0, 0.0], den), z, time, interp=False)
    _, alpha_tf, _ = signal.lsim(([2 * d * t_c, 1.0], den), z, time, interp=False)
    phi, gamma = af.body_rate_discretisation(k12, k22, dt)
    alpha, omega = np.zeros(1), np.zeros(1)
    got = np.empty((n, 2))
    for k in range(n):
        got[k] = alpha[0], omega[0]
        af.body_rate_step_1(alpha, omega, z[k : k + 1], phi, gamma)
    # eq 18 lists the (T, d) form; lsim discretises it independently (ZOH)
    assert np.allclose(got[:, 0], alpha_tf, atol=1e-12)
    assert np.allclose(got[:, 1], omega_tf, atol=1e-12)


def test_error_quaternion_from_mismatch_inverts_seed_000_mismatch():
    rng = np.random.default_rng(2)
    q_p = qt.normalize(rng.normal(size=(50, 4)))
    e_true = qt.from_axis_angle(rng.normal(size=(50, 3)), rng.uniform(0.0, np.pi / 2, 50))
    e, eps = af.mismatch(q_p, qt.multiply(q_p, e_true))
    assert np.allclose(np.abs(np.sum(e * e_true, axis=-1)), 1.0, atol=EXACT)  # same rotation, any sign
    assert np.allclose(af.error_quaternion_from_mismatch(eps), e_true, atol=1e-9)  # asin near 90°
    for k in range(5):
        assert np.allclose(af.error_quaternion_from_mismatch_1(eps[k]), e_true[k], atol=1e-9)


def _run_mismatch_filter(q_p, q_meas, omega, k_a, k_w, beta, dt):
    state = np.zeros(9)
    out = np.empty((q_meas.shape[0], 9))
    for k in range(q_meas.shape[0]):
        af.mismatch_filter_step_1(state, q_p, q_meas[k], omega[k], True, k_a, k_w, beta, dt)
        out[k] = state
    return out


def test_mismatch_filter_tracks_a_ramp_exactly_without_noise():
    dt, n = 0.25, 800
    k_a, k_w = af.discrete_gains(1e-6, 1e-9, dt)
    q_p = qt.normalize(np.array([0.9, 0.1, -0.2, 0.3]))
    t = np.arange(n) * dt
    eps = np.outer(1e-4 + 2e-6 * t, [0.6, 0.0, -0.8])  # mismatch growing at a constant rate
    q_meas = qt.multiply(q_p, af.error_quaternion_from_mismatch(eps))
    out = _run_mismatch_filter(q_p, q_meas, np.zeros((n, 3)), k_a, k_w, 0.1, dt)
    # an α–β filter has zero steady-state error to a ramp (type-2 loop)
    assert np.allclose(out[-1, :3], eps[-1], atol=EXACT)
    assert np.allclose(out[-1, 3:6], 2e-6 * np.array([0.6, 0.0, -0.8]), atol=EXACT)


def test_filtered_attitude_reproduces_a_constant_offset_from_the_program_exactly():
    dt, n = 0.25, 400
    k_a, k_w = af.discrete_gains(1e-6, 1e-9, dt)
    q_p = qt.normalize(np.array([0.7, -0.1, 0.4, 0.2]))
    q_true = qt.multiply(q_p, qt.from_axis_angle(np.array([1.0, 2.0, -1.0]), np.radians(0.5)))
    omega = np.array([1e-3, -2e-3, 5e-4])
    out = _run_mismatch_filter(q_p, np.tile(q_true, (n, 1)), np.tile(omega, (n, 1)), k_a, k_w, 0.2, dt)
    q_f, w_f = af.filtered_attitude_1(out[-1], q_p)
    assert qt.angle(qt.multiply(qt.conjugate(q_true), q_f)) < EXACT
    assert np.allclose(w_f, omega, atol=EXACT)


def test_rate_smoothing_step_response_is_geometric():
    beta, n = 0.2, 30
    out = _run_mismatch_filter(
        np.array([1.0, 0, 0, 0]), np.tile([1.0, 0, 0, 0], (n, 1)), np.ones((n, 3)), 0.5, 0.1, beta, 0.25
    )
    assert np.allclose(out[:, 6], 1.0 - (1.0 - beta) ** np.arange(1, n + 1), atol=EXACT)


def test_mismatch_filter_error_covariance_matches_the_riccati_posterior():
    dt, segments, length, settle = 0.25, 60, 2000, 200
    sigma = 3.0 * sensors.ARCSEC  # seed 000 §5
    r = sigma**2 * dt
    q = r / (10 * dt) ** 4  # ξ^{-1/4} = 10 samples: short correlation, many independent errors
    k_a, k_w = af.discrete_gains(q, r, dt)
    rng = np.random.default_rng(7)
    f = np.array([[1.0, dt], [0.0, 1.0]])
    qd = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    q_p = np.array([1.0, 0.0, 0.0, 0.0])
    errors = []
    for _ in range(segments):  # restarts keep the integrated random walk a small angle
        w = rng.multivariate_normal(np.zeros(2), qd, size=(length, 3))
        x = np.zeros((length, 3, 2))
        for k in range(1, length):
            x[k] = x[k - 1] @ f.T + w[k]
        q_true = af.error_quaternion_from_mismatch(x[:, :, 0])
        q_meas, _ = sensors.star_tracker(q_true, np.zeros((length, 3)), sigma, 1.0, rng)
        out = _run_mismatch_filter(q_p, q_meas, np.zeros((length, 3)), k_a, k_w, 0.1, dt)
        errors.append(out[settle:, :3] - x[settle:, :, 0])
    err = np.concatenate(errors)
    p_prior = solve_discrete_are(f.T, np.array([[1.0], [0.0]]), qd, np.array([[sigma**2]]))
    p_post = p_prior[0, 0] - p_prior[0, 0] ** 2 / (p_prior[0, 0] + sigma**2)
    # ≈ 3·108,000/20 independent errors; 10 % is > 5 standard errors of a variance
    VAR_TOLERANCE = 0.1
    assert np.allclose(err.var(axis=0) / p_post, 1.0, atol=VAR_TOLERANCE)


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: af.continuous_gains(-1.0, 1.0), "q"),
        (lambda: af.discrete_gains(1.0, 0.0, 0.1), "r"),
        (lambda: af.discrete_gains(1.0, 1.0, 0.0), "dt_s"),
        (lambda: af.error_quaternion_from_mismatch([2.0, 0, 0]), "eps"),
    ],
)
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()


WGS84_FLATTENING = 1 / 298.257223563
EARTH_RATE = 7.2921150e-5  # rad/s, IERS


def _noaa20(shared_data):
    """NOAA-20 attitude (converted at this edge from scalar-last body→GCRS to scalar-first q_ib), ECEF r, v, times."""
    import csv

    path = shared_data / "real" / "noaa20_jpss1_apid11" / "jpss1_apid11_decoded.csv"
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    q = qt.normalize(np.array([[float(r[k]) for k in ("q4", "q1", "q2", "q3")] for r in rows]))
    t = np.array([np.datetime64(r["att_time"], "us") for r in rows]).astype(np.int64) * 1e-6
    r_e = np.array([[float(r[k]) for k in ("pos_x_m", "pos_y_m", "pos_z_m")] for r in rows])
    v_e = np.array([[float(r[k]) for k in ("vel_x_mps", "vel_y_mps", "vel_z_mps")] for r in rows])
    return q, t, r_e, v_e


def test_body_rate_estimator_recovers_noaa20_orbital_rate_from_real_attitude(shared_data):
    q, t, r_e, v_e = _noaa20(shared_data)
    dt = float(np.median(np.diff(t)))
    steps = qt.normalize(qt.multiply(qt.conjugate(q[:-1]), q[1:]))  # short way: q and −q alike
    theta = 2.0 * np.arctan2(np.linalg.norm(steps[:, 1:], axis=-1), steps[:, 0])[:, None]
    z = np.vstack(
        [np.zeros(3), np.cumsum(theta * steps[:, 1:] / np.linalg.norm(steps[:, 1:], axis=-1, keepdims=True), axis=0)]
    )
    time_constant = 20.0  # s: smooths the float32 quantisation, follows the orbit-scale motion
    k12, k22 = af.continuous_gains(time_constant**-4.0, 1.0)
    phi, gamma = af.body_rate_discretisation(k12, k22, dt)
    alpha, omega = z[0].copy(), np.zeros(3)
    rate = np.empty(len(z))
    for k in range(len(z)):
        af.body_rate_step_1(alpha, omega, z[k], phi, gamma)
        rate[k] = np.linalg.norm(omega)
    v_i = v_e + np.cross([0.0, 0.0, EARTH_RATE], r_e)  # ECEF → inertial velocity
    orbit_rate = np.linalg.norm(np.cross(r_e, v_i), axis=-1) / np.sum(r_e * r_e, axis=-1)
    rel = (rate / orbit_rate - 1.0)[int(15 * time_constant / dt) :]
    # a nadir-pointing body turns with the orbit frame; pointing at the geodetic nadir adds the
    # swing of the geodetic vertical, a relative modulation of ±2f (f: WGS-84 flattening)
    NOISE = 1e-3
    assert np.abs(rel).max() < 2 * WGS84_FLATTENING + NOISE
    assert abs(rel.mean()) < NOISE
