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


def _count_ll(y, drift, q_var: float, sensor_var: float, offset=None) -> float:
    n = len(y)
    off = np.zeros((1, n)) if offset is None else np.asarray(offset, dtype=float)[None]
    d = np.asarray(drift, dtype=float)[None].copy()
    return float(
        fd.count_loglik(np.asarray(y, float), d, np.full(n - 1, q_var), 1.0, sensor_var, off, np.zeros((1, n), bool))[0]
    )


def test_count_loglik_of_a_noiseless_ramp_is_the_measure_of_consistent_starts() -> None:
    """Speed x0 + 0.3 k rounded to counts, x0 uniform over the first count: readings 0 0 1 1 1 2 need
    x0 + 0.3 < 0.5, x0 + 0.6 ≥ 0.5, x0 + 1.5 ≥ 1.5 and x0 + 1.2 < 1.5, i.e. x0 ∈ [0, 0.2): probability 0.2
    (by hand). The white-noise model of rounding (variance 1/12) is far off."""
    y = [0, 0, 1, 1, 1, 2]
    assert abs(_count_ll(y, [0.3] * 5, 1e-12, 1e-6) - math.log(0.2)) < 0.1
    assert abs(_count_ll(y[:4], [0.3] * 3, 1e-12, 1e-6) - math.log(0.3)) < 0.1  # x0 ∈ [−0.1, 0.2)
    gaussian = fd.level_loglik(
        np.asarray(y, float),
        np.full((1, 5), 0.3),
        np.full(5, 1e-12),
        np.full(6, 1 / 12),
        np.zeros((1, 6)),
        np.zeros((1, 6), bool),
    )[0]
    assert abs(gaussian - math.log(0.2)) > 0.5


def test_count_loglik_matches_a_monte_carlo_of_rounded_noisy_ramps() -> None:
    """P(readings | model) estimated by flying 400,000 noisy ramps and counting those that round to the same
    readings; a drift 10 % off the truth included (the evidence a hypothesis gets is a difference of these)."""
    rng = np.random.default_rng(11)
    for slope, sq, sr, n in ((0.37, 0.05, 0.02, 8), (0.1, 0.02, 0.01, 12), (0.37, 0.2, 0.05, 8)):
        x = 0.3 + np.concatenate([[0.0], np.cumsum(slope + sq * rng.standard_normal(n - 1))])
        y = np.round(x)
        for drift in (slope, 1.1 * slope):
            paths = y[0] + rng.uniform(-0.5, 0.5, 400_000)
            same = np.ones(paths.shape[0], dtype=bool)
            for k in range(1, n):
                paths = paths + drift + sq * rng.standard_normal(paths.shape[0])
                same &= np.round(paths + sr * rng.standard_normal(paths.shape[0])) == y[k]
            assert abs(_count_ll(y, [drift] * (n - 1), sq**2, sr**2) - math.log(same.mean())) < 0.15


def test_count_loglik_cannot_tell_speeds_the_readings_do_not_separate() -> None:
    """Ten readings of 0: a still wheel keeps them with probability 1, one creeping 0.02 count/s with the
    probability 0.82 that it started below 0.5 − 0.18 (by hand): a hypothesis the readings cannot rule out keeps
    a comparable likelihood. A count transition where a ramp predicts it is evidence against a slower ramp."""
    y = np.zeros(10)
    assert abs(_count_ll(y, [0.0] * 9, 1e-8, 1e-4)) < 0.1
    assert abs(_count_ll(y, [0.02] * 9, 1e-8, 1e-4) - math.log(0.82)) < 0.1
    ramp = [0, 0, 1, 1, 1, 1, 2, 2, 2, 2]  # 0.25 count/s from x0 = 0.1: transitions at 1.6 s and 5.6 s
    assert _count_ll(ramp, [0.25] * 9, 1e-8, 1e-4) > _count_ll(ramp, [0.2] * 9, 1e-8, 1e-4) + 1.0
    # a one-count bias from sample 5 explains a jump of a still wheel by one count; without it the jump needs
    # a start within a few σ = 0.01 of the count's edge (the Gaussian slices of the start leak past it: the
    # likelihood errs towards "cannot tell", never towards certainty)
    offset = np.r_[np.zeros(5), np.ones(5)]
    jump = [0, 0, 0, 0, 0, 1, 1, 1, 1, 1]
    assert _count_ll(jump, [0.0] * 9, 1e-8, 1e-4, offset) > _count_ll(jump, [0.0] * 9, 1e-8, 1e-4) + 5.0


def test_a_rotor_seized_between_samples_may_be_read_braking() -> None:
    """A wheel at 40 counts seizes between samples 5 and 6 and is read 4 counts at sample 6, then 0: the first
    reset sample reads anywhere between the speed and 0, so the seizure beats a motionless rotor's reading of 4
    (which rounding alone cannot give a speed reset to 0 exactly) and beats no fault (a 40-count drop)."""
    y = np.r_[np.full(6, 40.0), [4.0], np.zeros(5)]
    n = y.shape[0]
    reset = np.zeros((2, n), dtype=np.bool_)
    reset[0, 6:] = True
    ll = fd.count_loglik(y, np.zeros((2, n - 1)), np.full(n - 1, 1e-8), 1.0, 1e-4, np.zeros((2, n)), reset)
    assert np.all(np.isfinite(ll))
    assert ll[0] > ll[1] + 100.0
    assert ll[0] > math.log(1.0 / 40.0) - 1.0  # the braking reading: one count of the 40 it may take


def test_count_loglik_of_hypotheses_sharing_the_nominal_prefix_is_unchanged_by_sharing_it() -> None:
    """Fault hypotheses are the nominal model before their onsets: continuing each from the nominal filter's state
    at its first differing sample gives the likelihood of filtering every row from the start, bit for bit (rows
    that differ from sample 0, through a drift, an offset or a reset, and a missing reading included)."""
    rng = np.random.default_rng(5)
    n, g = 300, 60
    drift = 0.05 + 0.02 * np.sin(np.arange(n - 1) / 20.0)
    y = np.round(0.3 + np.concatenate([[0.0], np.cumsum(drift + 0.01 * rng.standard_normal(n - 1))]))
    y[40] = np.nan
    onsets = np.sort(rng.integers(0, n - 1, g))
    after = np.arange(n - 1)[None, :] >= onsets[:, None]
    rows = np.where(after, 0.6 * drift[None, :], drift[None, :])
    offset = np.zeros((g, n))
    offset[::5] = 0.5 * (np.arange(n)[None, :] >= onsets[::5, None])
    reset = np.zeros((g, n), dtype=np.bool_)
    reset[2::7] = np.arange(n)[None, :] >= 200
    args = (y, rows, np.full(n - 1, 1e-4), 1.0, 1e-4, offset, reset)
    np.testing.assert_array_equal(fd.count_loglik(*args, nominal_drift=drift), fd.count_loglik(*args))
    nominal = fd.count_loglik(y, drift[None, :], *args[2:5], np.zeros((1, n)), np.zeros((1, n), bool), drift)
    assert nominal[0] == fd.count_loglik(y, drift[None, :], *args[2:5], np.zeros((1, n)), np.zeros((1, n), bool))[0]


def _ramps(rows: int, n: int = 200) -> tuple:
    """Readings of a slowly turning wheel (rounded to 1) and ``rows`` hypotheses: its drift scaled after an onset."""
    rng = np.random.default_rng(11)
    drift = 0.03 + 0.01 * np.cos(np.arange(n - 1) / 15.0)
    y = np.round(0.2 + np.concatenate([[0.0], np.cumsum(drift + 0.005 * rng.standard_normal(n - 1))]))
    onsets = rng.integers(0, n - 1, rows)
    scale = rng.uniform(0.0, 1.5, rows)
    hyps = np.where(np.arange(n - 1)[None, :] >= onsets[:, None], scale[:, None] * drift[None, :], drift[None, :])
    return y, hyps, np.full(n - 1, 1e-5), 1.0, 4e-4, np.zeros((rows, n)), np.zeros((rows, n), dtype=np.bool_), drift


def test_count_loglik_rows_abandoned_below_a_floor_stay_below_it_and_the_best_row_is_exact() -> None:
    """A row's log-likelihood only falls as readings are added: a row abandoned below its floor reports a value
    below the floor (as its full value is), and the best row of the floor is computed in full."""
    y, hyps, *rest = _ramps(40)
    full = fd.count_loglik(y, hyps, *rest)
    floor = np.full(hyps.shape[0], full.max())
    cut = fd.count_loglik(y, hyps, *rest, floor=floor)
    best = int(np.argmax(full))
    assert cut[best] == full[best]
    others = np.arange(hyps.shape[0]) != best
    assert np.all(cut[others] < floor[others])
    assert np.all(cut[others] >= full[others] - 1e-9)  # filtering stopped early: its partial value, never lower
    assert np.any(cut[others] > full[others] + 1.0)  # and rows far below the best were stopped early


def test_count_loglik_does_not_depend_on_how_rows_are_split_between_threads() -> None:
    """Rows are independent: one call over many rows (split between threads) equals calls over a few rows each."""
    y, hyps, q_var, quantum, sensor_var, offset, reset, drift = _ramps(3 * fd.THREAD_ROWS)
    whole = fd.count_loglik(y, hyps, q_var, quantum, sensor_var, offset, reset, drift)
    parts = [
        fd.count_loglik(y, hyps[a : a + 7], q_var, quantum, sensor_var, offset[a : a + 7], reset[a : a + 7], drift)
        for a in range(0, hyps.shape[0], 7)
    ]
    np.testing.assert_array_equal(whole, np.concatenate(parts))
