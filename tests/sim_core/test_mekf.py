"""MEKF (gyros + star tracker) against simulated truth: convergence, bias estimation, NEES consistency."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from sim_core import mekf, sensors
from sim_core import quaternion as qt

DT = 0.1  # gyro / propagation step (s)
UPDATE_EVERY = 5  # star tracker every 0.5 s
SIGMA_ST = 3.0 * sensors.ARCSEC  # seed 000 §5: σ = 3″
GYRO_NOISE = 1e-4  # rad/s per sample
DRIFT_DENSITY = 1e-6  # rad/s/√s, Markov drift with τ ≫ run: a bias random walk for the filter
DRIFT_TAU = 1e6
BIAS = np.radians([0.05, -0.03, 0.02])  # constant gyro bias (rad/s)
INITIAL_ERROR = np.radians(5.0)


def _scenario(seed: int, n: int):
    """Truth with a held, slowly varying rate; gyro and star-tracker samples of it."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    omega = np.column_stack([0.01 * np.sin(0.02 * t), 0.005 * np.cos(0.013 * t), 0.002 + 0 * t])
    q = np.empty((n, 4))
    q[0] = qt.normalize(rng.normal(size=4))
    steps = qt.from_axis_angle(omega, np.linalg.norm(omega, axis=-1) * DT)  # exact for a held rate
    for k in range(1, n):
        q[k] = qt.multiply(q[k - 1], steps[k - 1])
    drift = sensors.GaussMarkovDrift(DRIFT_TAU, DRIFT_DENSITY, DT)
    gyro, d, _ = sensors.gyro(omega, BIAS, drift, GYRO_NOISE, 0.5, rng, np.zeros(3))
    q_meas, _ = sensors.star_tracker(q, omega, SIGMA_ST, 0.05, rng)
    valid = np.arange(n) % UPDATE_EVERY == 0
    axis = qt.normalize(np.concatenate([[0.0], rng.normal(size=3)]))[1:]
    q0 = qt.multiply(q[0], qt.from_axis_angle(axis, INITIAL_ERROR))
    return q, BIAS + d, gyro, q_meas, valid, q0


def _run(seed: int, n: int):
    q, bias, gyro, q_meas, valid, q0 = _scenario(seed, n)
    sv, su = mekf.process_noise_from_gyro(GYRO_NOISE, DT, DRIFT_DENSITY)
    p0 = mekf.initial_covariance(INITIAL_ERROR, np.radians(0.1))
    q_hat, b_hat, p = mekf.mekf_run(q0, np.zeros(3), p0, gyro, q_meas, valid, DT, sv, su, SIGMA_ST)
    dq = qt.multiply(qt.conjugate(q_hat), q)
    dq = np.where(dq[:, :1] < 0, -dq, dq)
    err = np.concatenate([2.0 * dq[:, 1:], bias - b_hat], axis=-1)  # error state (δθ, Δb)
    return err, p


def test_mekf_converges_from_5_deg_and_estimates_constant_bias():
    err, p = _run(seed=3, n=6000)
    att_arcsec = np.linalg.norm(err[:, :3], axis=-1) / sensors.ARCSEC
    # from 5° (18,000″) to below 10 star-tracker σ within 2 s (four updates), and it stays there
    CONVERGED_ARCSEC, WITHIN_STEPS = 10.0 * SIGMA_ST / sensors.ARCSEC, 20
    assert att_arcsec[WITHIN_STEPS:].max() < CONVERGED_ARCSEC
    # the 0.05°/s bias is learned to better than 1 % of its size by the end of the run
    BIAS_FRACTION = 0.01
    assert np.all(np.abs(err[-1, 3:]) < BIAS_FRACTION * np.abs(BIAS))


def test_mekf_3_sigma_bounds_contain_error_and_nees_is_chi_square():
    runs, n, skip = 10, 3000, 100
    inside, nees = [], []
    for seed in range(runs):
        err, p = _run(seed=100 + seed, n=n)
        sig = np.sqrt(np.diagonal(p, axis1=1, axis2=2))
        inside.append(np.abs(err[skip:]) <= 3.0 * sig[skip:])
        nees.append(np.einsum("ki,kij,kj->k", err, np.linalg.inv(p), err)[skip:])
    # Gaussian errors fall inside ±3σ 99.73 % of the time; demand ≥ 99 % on every state component
    assert np.all(np.mean(np.concatenate(inside), axis=0) >= 0.99)
    # the run-averaged NEES at each time is χ²(6·runs)/runs; its time mean lies in the 99.9 % band
    mean_nees = np.mean(np.mean(nees, axis=0))
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * runs) / runs
    assert lo < mean_nees < hi


def test_update_returns_chi_square_innovation_for_consistent_filter():
    rng = np.random.default_rng(4)
    n = 4000
    p = mekf.initial_covariance(np.radians(0.01), 1e-5)
    q_true = qt.normalize(rng.normal(size=(n, 4)))
    delta = rng.multivariate_normal(np.zeros(3), p[:3, :3], size=n)
    q_hat = qt.multiply(q_true, sensors.rotation_noise_quaternion(delta))
    q_meas, _ = sensors.star_tracker(q_true, np.zeros((n, 3)), SIGMA_ST, 1.0, rng)
    sig3 = np.full(3, SIGMA_ST)
    nis = [mekf.mekf_update_1(q_hat[k], np.zeros(3), p.copy(), q_meas[k], sig3) for k in range(n)]
    # mean of n χ²(3) draws: 3 ± 5·√(6/n)
    assert abs(np.mean(nis) - 3.0) < 5.0 * np.sqrt(6.0 / n)


def test_bad_shapes_name_the_fields():
    with pytest.raises(ValueError, match="q_meas_ib"):
        mekf.mekf_run(
            [1, 0, 0, 0],
            np.zeros(3),
            np.eye(6),
            np.zeros((3, 3)),
            np.zeros((2, 4)),
            np.ones(3, bool),
            0.1,
            1e-5,
            1e-6,
            1e-5,
        )


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(-0.05, 0.05, allow_subnormal=False), min_size=3, max_size=3),
    st.floats(0.01, 1.0),
    st.integers(1, 200),
)
def test_propagation_integrates_a_constant_rate_exactly_and_keeps_covariance_positive(omega, dt, n):
    omega = np.array(omega)
    q0 = qt.normalize(np.array([0.3, -0.5, 0.1, 0.8]))
    q, b, p = q0.copy(), np.zeros(3), mekf.initial_covariance(1e-3, 1e-5)
    for _ in range(n):
        mekf.mekf_propagate_1(q, b, p, omega, dt, 1e-6, 1e-8)
    # Λ̇ = ½ Λ ∘ ω with constant ω: Λ(t) = Λ0 ∘ (cos(|ω|t/2), ω̂ sin(|ω|t/2))
    exact = (
        qt.multiply(q0, qt.from_axis_angle(omega, np.linalg.norm(omega) * n * dt)) if np.linalg.norm(omega) > 0 else q0
    )
    ROUND_OFF = 1e-13 * n  # one normalised product per step
    assert qt.angle(qt.multiply(qt.conjugate(exact), q)) < ROUND_OFF
    assert np.allclose(p, p.T, atol=0.0)
    assert np.all(np.linalg.eigvalsh(p) > 0.0)


def test_mekf_on_sun_and_magnetometer_directions_converges_with_consistent_3_sigma_bounds():
    n, every = 6000, 10  # vector sensors at 1 Hz
    q, bias, gyro, _, _, q0 = _scenario(seed=21, n=n)
    rng = np.random.default_rng(22)
    sun_i, b_i = np.array([0.3, 0.9, -0.2]), np.array([2e-5, -1e-5, 3e-5])  # tesla
    sigma_sun, mag_noise = np.radians(0.05), 5e-9  # fine sun sensor; 5 nT magnetometer
    r_i = np.array([7e6, 0.0, 0.0])  # sunlit side
    sun_b, sun_ok = sensors.sun_sensor(q, sun_i, r_i, [0, 0, 1], np.pi, sigma_sun, rng)
    mag_b, mag_ok = sensors.magnetometer(q, b_i, np.zeros(3), mag_noise, 1e-4, rng)
    sigma_mag = mag_noise / np.linalg.norm(b_i)  # direction noise of the field vector
    sv, su = mekf.process_noise_from_gyro(GYRO_NOISE, DT, DRIFT_DENSITY)
    q_hat, b_hat = q0.copy(), np.zeros(3)
    p = mekf.initial_covariance(INITIAL_ERROR, np.radians(0.1))
    err, sig = np.empty((n, 6)), np.empty((n, 6))
    for k in range(n):
        if k > 0:
            mekf.mekf_propagate_1(q_hat, b_hat, p, gyro[k - 1], DT, sv, su)
        if k % every == 0:
            assert sun_ok[k] and mag_ok[k]
            mekf.mekf_vector_update_1(q_hat, b_hat, p, sun_b[k], sun_i, sigma_sun)
            mekf.mekf_vector_update_1(q_hat, b_hat, p, mag_b[k], b_i, sigma_mag)
        dq = qt.multiply(qt.conjugate(q_hat), q[k])
        err[k] = np.concatenate([2.0 * dq[1:] * np.sign(dq[0]), bias[k] - b_hat])
        sig[k] = np.sqrt(np.diag(p))
    settled = 300  # 30 s
    # two non-collinear directions observe all three axes: from 5° to the sun sensor's level
    assert np.linalg.norm(err[settled:, :3], axis=-1).max() < 5.0 * sigma_sun
    assert np.mean(np.abs(err[settled:]) <= 3.0 * sig[settled:], axis=0).min() >= 0.99
