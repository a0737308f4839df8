"""Sensor models against their analytic statistics (fixed seeds, bounds from sampling theory)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_core import quaternion as qt
from sim_core import sensors

N_SAMPLES = 40_000
# A sample statistic lies within this many of its own standard errors (p ≈ 6e-7 per check).
STAT_SIGMAS = 5.0
EXACT = 1e-12  # float64 round-off


def _std_error_of_variance(n: int, rho: float = 0.0) -> float:
    """Relative standard error of a sample variance of a Gaussian AR(1) series with lag-1 correlation ρ."""
    return np.sqrt(2.0 / n * (1.0 + rho**2) / (1.0 - rho**2))


def test_variant_generators_are_reproducible_and_independent_of_batch_size():
    a = sensors.variant_generators(42, 3)[2].standard_normal(5)
    b = sensors.variant_generators(42, 7)[2].standard_normal(5)
    c = sensors.variant_generators(42, 7)[1].standard_normal(5)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)


def test_star_tracker_error_covariance_matches_sigma_per_axis():
    rng = np.random.default_rng(7)
    q = qt.normalize(rng.normal(size=(N_SAMPLES, 4)))
    sigma = np.array([2.0, 3.0, 15.0]) * sensors.ARCSEC  # cross-boresight and roll axes
    q_meas, valid = sensors.star_tracker(q, np.zeros((N_SAMPLES, 3)), sigma, 0.05, rng)
    # scipy's rotation vector of Λ̃ ∘ Λ^m is an independent extraction of the body noise angle
    err = Rotation.from_quat(qt.multiply(qt.conjugate(q), q_meas), scalar_first=True).as_rotvec()
    assert valid.all()
    assert np.all(np.abs(err.mean(axis=0)) < STAT_SIGMAS * sigma / np.sqrt(N_SAMPLES))
    rel = err.std(axis=0) / sigma - 1.0
    assert np.all(np.abs(rel) < STAT_SIGMAS * _std_error_of_variance(N_SAMPLES) / 2.0)
    corr = np.corrcoef(err.T)[np.triu_indices(3, 1)]
    assert np.all(np.abs(corr) < STAT_SIGMAS / np.sqrt(N_SAMPLES))


def test_star_tracker_kernel_equals_vectorised_model_on_the_same_draws():
    q = qt.normalize(np.random.default_rng(1).normal(size=(20, 4)))
    omega = np.full((20, 3), 0.01)
    sigma = 5.0 * sensors.ARCSEC
    q_meas, valid = sensors.star_tracker(q, omega, sigma, 0.05, np.random.default_rng(3))
    normals = np.random.default_rng(3).standard_normal((20, 3))
    for k in range(20):
        qk, ok = sensors.star_tracker_1(q[k], omega[k], np.full(3, sigma), 0.05, normals[k])
        assert ok == valid[k]
        assert np.allclose(qk, q_meas[k], atol=EXACT)


def test_star_tracker_flags_samples_above_tracking_rate():
    q = np.tile([1.0, 0.0, 0.0, 0.0], (2, 1))
    omega = np.array([[0.0, 0.0, 0.034], [0.0, 0.0, 0.036]])
    _, valid = sensors.star_tracker(q, omega, 1e-5, np.radians(2.0), np.random.default_rng(0))
    assert valid.tolist() == [True, False]


def test_star_tracker_is_blinded_only_by_a_lit_sun_inside_its_exclusion_cone():
    sun = np.array([1.0, 0.0, 0.0])
    toward = qt.from_axis_angle([0, 1, 0], np.pi / 2)  # body +z boresight turned onto +x
    q = np.stack([toward, qt.multiply(toward, qt.from_axis_angle([1, 0, 0], np.radians(31.0))), toward])
    r = np.array([[7e6, 0, 0], [7e6, 0, 0], [-7e6, 0, 0]])  # the last one in eclipse
    blinded = sensors.star_tracker_blinded(q, sun, r, [0, 0, 1], np.radians(30.0))
    assert blinded.tolist() == [True, False, False]
    for k in range(3):
        got = sensors.star_tracker_blinded_1(
            q[k], sun, r[k].astype(float), np.array([0, 0, 1.0]), np.cos(np.radians(30.0))
        )
        assert got == blinded[k]


def test_markov_drift_matches_first_order_gauss_markov_statistics():
    dt, tau, density = 0.1, 2.0, 1e-4
    model = sensors.GaussMarkovDrift(tau, density, dt)
    rng = np.random.default_rng(11)
    d = sensors.gauss_markov_drift(model, N_SAMPLES * 5, model.stationary_std * rng.standard_normal(3), rng)
    n, phi = d.shape[0], np.exp(-dt / tau)
    sigma_d = density * np.sqrt(tau / 2.0)  # stationary std of ḋ = −d/τ + n_d
    # the mean of an AR(1) series has variance σ²(1 + φ)/(n(1 − φ))
    assert np.all(np.abs(d.mean(axis=0)) < STAT_SIGMAS * sigma_d * np.sqrt((1 + phi) / (n * (1 - phi))))
    rel = d.var(axis=0) / sigma_d**2 - 1.0
    assert np.all(np.abs(rel) < STAT_SIGMAS * _std_error_of_variance(n, phi))
    x = d - d.mean(axis=0)
    for lag in (1, 10, int(tau / dt)):
        rho = np.sum(x[lag:] * x[:-lag], axis=0) / np.sum(x * x, axis=0)
        # Bartlett: the lag-k sample autocorrelation has standard error ≈ √((1 + φ²)/(1 − φ²)/n)
        bound = STAT_SIGMAS * np.sqrt((1 + phi**2) / (1 - phi**2) / n)
        assert np.all(np.abs(rho - np.exp(-lag * dt / tau)) < bound)


def test_gyro_residual_is_constant_bias_plus_drift_plus_white_noise():
    dt = 0.1
    model = sensors.GaussMarkovDrift(100.0, 1e-5, dt)
    omega = np.column_stack([np.sin(np.arange(N_SAMPLES) * dt * 0.01)] * 3) * 0.01
    bias = np.array([1e-3, -2e-3, 5e-4])
    sigma = 2e-4
    meas, drift, valid = sensors.gyro(omega, bias, model, sigma, 0.1, np.random.default_rng(5))
    white = meas - omega - bias - drift
    assert valid.all()
    assert np.all(np.abs(white.mean(axis=0)) < STAT_SIGMAS * sigma / np.sqrt(N_SAMPLES))
    assert np.all(np.abs(white.std(axis=0) / sigma - 1.0) < STAT_SIGMAS * _std_error_of_variance(N_SAMPLES) / 2.0)


def test_gyro_kernel_equals_vectorised_model_on_the_same_draws():
    n, dt = 50, 0.1
    model = sensors.GaussMarkovDrift(np.array([2.0, 3.0, 4.0]), 1e-3, dt)
    omega = np.random.default_rng(2).normal(size=(n, 3)) * 0.01
    bias, sigma, d0 = np.array([0.01, 0.0, -0.01]), 1e-3, np.array([1e-3, 2e-3, -1e-3])
    meas, _, _ = sensors.gyro(omega, bias, model, sigma, 1.0, np.random.default_rng(9), d0)
    g = np.random.default_rng(9)
    w, ng = g.standard_normal((n - 1, 3)), g.standard_normal((n, 3))
    w = np.vstack([w, np.zeros((1, 3))])
    drift = d0.copy()
    for k in range(n):
        mk, ok = sensors.gyro_1(
            omega[k], bias, drift, np.full(3, sigma), model.decay, model.step_std, 1.0, np.concatenate([ng[k], w[k]])
        )
        assert ok
        assert np.allclose(mk, meas[k], atol=EXACT)


def test_gyro_saturates_and_flags_out_of_range_rates():
    model = sensors.GaussMarkovDrift(1.0, 0.0, 0.1)
    omega = np.array([[0.1, 0.0, 0.0], [0.3, 0.0, 0.0]])
    meas, _, valid = sensors.gyro(omega, np.zeros(3), model, 0.0, 0.2, np.random.default_rng(0), np.zeros(3))
    assert valid.tolist() == [True, False]
    assert meas[1, 0] == 0.2


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: sensors.GaussMarkovDrift(0.0, 1e-3, 0.1), "tau_s"),
        (lambda: sensors.GaussMarkovDrift(1.0, -1.0, 0.1), "density_rad_s_sqrt_s"),
        (lambda: sensors.star_tracker([1, 0, 0, 0], [0, 0, 0], -1.0, 1.0, np.random.default_rng()), "sigma_rad"),
        (lambda: sensors.variant_generators(1, 0), "n_variants"),
        (lambda: sensors.earth_sensor(0.0, 0.0, [0.0], 1e-3, 0.2, np.random.default_rng()), "bias_rad"),
        (
            lambda: sensors.magnetometer([1, 0, 0, 0], [np.nan, 0, 0], np.zeros(3), 0.0, 1.0, np.random.default_rng()),
            "b_i_t",
        ),
        (lambda: sensors.wheel_tachometer([1.0], 0.0, 10.0), "resolution_rad_s"),
        (
            lambda: sensors.gps_receiver(np.zeros(3), np.zeros(3), 1.0, 1.0, 1.5, np.random.default_rng()),
            "dropout_probability",
        ),
    ],
)
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()


def test_nadir_roll_pitch_are_the_132_angles_of_the_attitude_in_the_orbit_frame():
    from sim_core import frames

    rng = np.random.default_rng(12)
    r = rng.normal(size=(200, 3)) * 7e6
    v = rng.normal(size=(200, 3)) * 7e3
    yaw, roll, pitch = (rng.uniform(-0.5, 0.5, 200) for _ in range(3))
    q_ib = qt.multiply(frames.orf_quaternion(r, v), qt.from_euler_132(yaw, roll, pitch))
    got_roll, got_pitch = sensors.nadir_roll_pitch(q_ib, r)
    assert np.allclose(got_roll, roll, atol=EXACT) and np.allclose(got_pitch, pitch, atol=EXACT)
    for k in range(5):
        assert np.allclose(sensors.nadir_roll_pitch_1(q_ib[k], r[k]), (roll[k], pitch[k]), atol=EXACT)


def test_earth_sensor_residual_is_constant_bias_plus_white_noise():
    rng = np.random.default_rng(21)
    roll, pitch = rng.uniform(-0.1, 0.1, N_SAMPLES), rng.uniform(-0.1, 0.1, N_SAMPLES)
    bias, sigma = np.array([2e-3, -1e-3]), np.array([1e-3, 2e-3])
    meas, valid = sensors.earth_sensor(roll, pitch, bias, sigma, np.radians(15.0), rng)
    res = meas - np.column_stack([roll, pitch])
    assert valid.all()
    assert np.all(np.abs(res.mean(axis=0) - bias) < STAT_SIGMAS * sigma / np.sqrt(N_SAMPLES))
    assert np.all(np.abs(res.std(axis=0) / sigma - 1.0) < STAT_SIGMAS * _std_error_of_variance(N_SAMPLES) / 2.0)
    _, out = sensors.earth_sensor(0.3, 0.0, bias, sigma, np.radians(15.0), rng)
    assert not out


def test_earth_sensor_kernel_equals_vectorised_model():
    bias, sigma = np.array([2e-3, -1e-3]), np.array([1e-3, 2e-3])
    meas, valid = sensors.earth_sensor(0.05, -0.02, bias, sigma, 0.2, np.random.default_rng(4))
    m1, v1 = sensors.earth_sensor_1(0.05, -0.02, bias, sigma, 0.2, np.random.default_rng(4).standard_normal(2))
    assert v1 == valid and np.allclose(m1, meas, atol=EXACT)


def test_magnetometer_without_noise_is_the_scipy_inverse_rotation():
    rng = np.random.default_rng(8)
    q = qt.normalize(rng.normal(size=(100, 4)))
    b_i = rng.normal(size=(100, 3)) * 3e-5
    b_b, valid = sensors.magnetometer(q, b_i, np.zeros(3), 0.0, 1e-4, rng)
    expected = Rotation.from_quat(q, scalar_first=True).inv().apply(b_i)
    assert valid.all()
    assert np.allclose(b_b, expected, atol=EXACT * 1e-4)
    k, ok = sensors.magnetometer_1(q[0], b_i[0], np.zeros(3), 0.0, 1e-4, np.zeros(3))
    assert ok and np.allclose(k, expected[0], atol=EXACT * 1e-4)


def test_magnetometer_saturates_and_flags_out_of_range_field():
    b_b, valid = sensors.magnetometer([1, 0, 0, 0], [8e-5, 0, 0], np.zeros(3), 0.0, 6e-5, np.random.default_rng(0))
    assert not valid and b_b[0] == 6e-5


def test_shadow_fraction_of_an_orbit_in_the_sun_plane_is_asin_r_over_a_over_pi():
    EARTH = sensors.EARTH_RADIUS_M
    a = EARTH + 600e3
    u = np.linspace(0.0, 2.0 * np.pi, 200_001)[:-1]
    r = a * np.column_stack([np.cos(u), np.sin(u), np.zeros_like(u)])
    frac = sensors.in_earth_shadow(r, np.array([1.0, 0.0, 0.0])).mean()
    GRID = 2.0 / u.size  # one grid cell at each shadow boundary
    assert abs(frac - np.arcsin(EARTH / a) / np.pi) < GRID


def test_sun_sensor_is_invalid_in_eclipse_and_outside_its_field_of_view():
    rng = np.random.default_rng(2)
    sun = np.array([1.0, 0.0, 0.0])
    r = np.array([[7e6, 0, 0], [-7e6, 0, 0], [-7e6, 0, 0]])
    q = np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0], list(qt.from_axis_angle([0, 0, 1], np.pi / 2))])
    s_b, valid = sensors.sun_sensor(q, sun, r, [1, 0, 0], np.radians(60.0), 0.0, rng)
    assert valid.tolist() == [True, False, False]
    r2 = np.array([7e6, 0, 0])
    s_out, v_out = sensors.sun_sensor(q[2], sun, r2, [1, 0, 0], np.radians(60.0), 0.0, rng)
    assert not v_out and np.allclose(s_out, [0, -1, 0], atol=EXACT)
    for k in range(3):
        s1, v1 = sensors.sun_sensor_1(
            q[k], sun, r[k].astype(float), np.array([1.0, 0, 0]), np.cos(np.radians(60.0)), 0.0, np.zeros(3)
        )
        assert v1 == valid[k] and np.allclose(s1, s_b[k], atol=EXACT)


def test_sun_sensor_angular_error_matches_noise_sigma():
    rng = np.random.default_rng(6)
    sigma = np.radians(0.1)
    q = qt.normalize(rng.normal(size=(N_SAMPLES, 4)))
    sun = np.array([0.3, -0.5, 0.8])
    s_b, _ = sensors.sun_sensor(q, sun, np.array([7e6, 0, 0]), [1, 0, 0], np.pi, sigma, rng)
    truth = Rotation.from_quat(q, scalar_first=True).inv().apply(sun / np.linalg.norm(sun))
    ang = np.arccos(np.clip(np.sum(s_b * truth, axis=-1), -1.0, 1.0))
    # two perpendicular axes of N(0, σ²) move a direction by a Rayleigh angle: E[ang²] = 2σ²
    assert abs(np.mean(ang**2) / (2 * sigma**2) - 1.0) < STAT_SIGMAS * np.sqrt(1.0 / N_SAMPLES)


def test_tachometer_quantisation_error_is_uniform_within_half_a_step():
    q_step = 2.0 * np.pi / 1024 / 0.1  # 1024 counts per revolution counted over 0.1 s
    speed = np.random.default_rng(1).uniform(-600.0, 600.0, N_SAMPLES)
    meas, valid = sensors.wheel_tachometer(speed, q_step, 650.0)
    err = meas - speed
    assert valid.all()
    assert np.abs(err).max() <= 0.5 * q_step * (1 + EXACT)
    # uniform on ±q/2: std q/√12; the sample variance of a uniform has relative error √(0.8/n)
    assert abs(err.std() / (q_step / np.sqrt(12.0)) - 1.0) < STAT_SIGMAS * np.sqrt(0.8 / N_SAMPLES) / 2.0
    k, kv = sensors.wheel_tachometer_1(np.array([speed[0], 700.0]), q_step, 650.0)
    assert k[0] == meas[0] and kv.tolist() == [True, False]


def test_gps_noise_and_dropout_rate_match_their_parameters():
    rng = np.random.default_rng(3)
    r = np.tile([7e6, 0.0, 0.0], (N_SAMPLES, 1))
    v = np.tile([0.0, 7.5e3, 0.0], (N_SAMPLES, 1))
    p = 0.05
    r_m, v_m, valid = sensors.gps_receiver(r, v, 10.0, 0.1, p, rng)
    assert abs((1 - valid.mean()) - p) < STAT_SIGMAS * np.sqrt(p * (1 - p) / N_SAMPLES)
    assert np.all(np.abs((r_m - r).std(axis=0) / 10.0 - 1) < STAT_SIGMAS * _std_error_of_variance(N_SAMPLES) / 2)
    assert np.all(np.abs((v_m - v).std(axis=0) / 0.1 - 1) < STAT_SIGMAS * _std_error_of_variance(N_SAMPLES) / 2)
