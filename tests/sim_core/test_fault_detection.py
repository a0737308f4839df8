"""Residual statistics of the diagnosis against independent truths: the Kalman likelihood against the dense
multivariate normal density (scipy), the window test's false-alarm bound against the Gaussian tail."""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import multivariate_normal

from sim_core import fault_detection as fd


def _dense_loglik(y, drift, q_var, r_var, offset):
    """log N(y[1:] | mean, cov) of the local-level model given y[0] (diffuse start), built as one dense Gaussian."""
    x0 = y[0] - offset[0]
    mean = x0 + np.concatenate([[0.0], np.cumsum(drift)]) + offset
    walk = np.concatenate([[0.0], np.cumsum(q_var)])
    cov = np.minimum.outer(walk, walk) + np.diag(r_var)
    cov += r_var[0]  # x0 = y0 − o0 carries the first sample's measurement error into every later sample
    mu, c = mean[1:], cov[1:, 1:]
    return multivariate_normal(mu, c).logpdf(y[1:])


def test_level_loglik_matches_the_dense_gaussian_density() -> None:
    rng = np.random.default_rng(4)
    n = 40
    drift = rng.normal(0.0, 0.3, n - 1)
    q_var = rng.uniform(0.01, 0.2, n - 1)
    r_var = rng.uniform(0.05, 0.3, n)
    offset = np.where(np.arange(n) >= 25, 0.7, 0.0)
    y = rng.normal(0.0, 1.0, n).cumsum()
    got = fd.level_loglik(y, drift[None], q_var, r_var, offset[None], np.zeros((1, n), dtype=np.bool_))[0]
    assert math.isclose(got, _dense_loglik(y, drift, q_var, r_var, offset), rel_tol=1e-9)


def test_leading_missing_samples_start_the_level_at_the_first_sample_there_is() -> None:
    rng = np.random.default_rng(5)
    n, lead = 40, 3
    drift = rng.normal(0.0, 0.3, n - 1)
    q_var = rng.uniform(0.01, 0.2, n - 1)
    r_var = rng.uniform(0.05, 0.3, n)
    offset = np.where(np.arange(n) >= 25, 0.7, 0.0)
    y = rng.normal(0.0, 1.0, n).cumsum()
    y[:lead] = np.nan  # e.g. a field model before the first GPS fix
    got = fd.level_loglik(y, drift[None], q_var, r_var, offset[None], np.zeros((1, n), dtype=np.bool_))[0]
    tail = slice(lead, None)
    want = _dense_loglik(y[tail], drift[lead:], q_var[lead:], r_var[tail], offset[tail])
    assert math.isclose(got, want, rel_tol=1e-9)


def test_reset_forces_the_state_to_zero() -> None:
    n = 20
    y = np.r_[np.full(10, 5.0), np.zeros(10)]
    reset = np.zeros((2, n), dtype=np.bool_)
    reset[1, 10:] = True
    drift = np.zeros((2, n - 1))
    ll = fd.level_loglik(y, drift, np.full(n - 1, 1e-6), np.full(n, 0.01), np.zeros((2, n)), reset)
    assert ll[1] > ll[0] + 100.0  # a seized rotor at sample 10 explains the drop to zero, no fault does not


def test_window_alarm_rate_matches_the_gaussian_tail() -> None:
    """Gaussian random walk without a fault at n = 3: the alarm rate per test is close to 2Φ(−3)."""
    rng = np.random.default_rng(0)
    n, trials, alarms = 200, 400, 0
    for _ in range(trials):
        r = np.cumsum(rng.normal(0.0, 1.0, n))[None, :]
        alarms += (
            fd.window_alarm(r, np.ones((1, n - 1)), np.zeros((1, n)), 0.0, 1.0, n_sigma=3.0, windows_s=(1.0,))
            is not None
        )
    per_test = math.erfc(3.0 / math.sqrt(2.0))
    expected = 1.0 - (1.0 - per_test) ** (n - 1)
    assert abs(alarms / trials - expected) < 4.0 * math.sqrt(expected * (1 - expected) / trials)


def test_quantised_ramp_never_alarms_however_slow() -> None:
    """Rounding to a quantum q is bounded by q/2, so a noise-free ramp of any slope passes the bound-aware test."""
    q = 0.0262
    for slope in (1e-4, 1e-3, 3e-2):
        t = np.arange(3000.0)
        y = q * np.round(slope * t / q)
        r = fd.open_loop_residual(y, np.full(2999, slope))[None, :]
        assert fd.window_alarm(r, np.full((1, 2999), 1e-12), np.full((1, 3000), q * q / 12), q, 1.0) is None


def test_false_alarm_bound_is_the_union_of_tails() -> None:
    rate = fd.false_alarms_per_day(10, 1.0, n_sigma=6.5, n_windows=5)
    assert math.isclose(rate, 86_400 * 50 * math.erfc(6.5 / math.sqrt(2.0)))
    assert rate < 1e-3
