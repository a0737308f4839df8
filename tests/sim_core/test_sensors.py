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
        mk, ok = sensors.gyro_1(omega[k], bias, drift, np.full(3, sigma), model.decay, model.step_std, 1.0, np.concatenate([ng[k], w[k]]))
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
    ],
)
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()
