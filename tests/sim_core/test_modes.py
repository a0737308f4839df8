"""Mode machine: transitions when and only when their conditions hold (independent look-back oracle)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core import modes as md

TH = md.ModeThresholds()
RD, SUN, ORF, ROUTE, FAULT = md.MODE_RATE_DAMPING, md.MODE_SUN_SAFE, md.MODE_ORF, md.MODE_ROUTE, md.MODE_FAULT


def oracle(x, mode=RD, th=TH):
    """The docstring's transition table evaluated by looking back over the input arrays ``x``."""
    t, rate, valid, sun = x["t_s"], x["rate_norm_rad_s"], np.asarray(x["attitude_valid"]), x["sun_error_rad"]
    pointing, window, fault, recovered = x["pointing_error_rad"], x["route_window"], x["fault"], x["recovered"]
    damped_c = rate < th.rate_damped_rad_s
    sun_c = valid & (sun < th.sun_capture_rad)
    lost_c = ~valid
    entry, modes = -1, []
    for k in range(len(t)):

        def held(c):
            if not c[k]:
                return False
            j = k
            while j - 1 > entry and c[j - 1]:
                j -= 1
            return t[k] - t[j] >= th.confirm_s

        rules = [
            (mode == FAULT, RD if recovered[k] else FAULT),
            (bool(fault[k]), FAULT),
            (mode in (SUN, ORF, ROUTE) and rate[k] > th.rate_lost_rad_s, RD),
            (mode in (ORF, ROUTE) and held(lost_c), SUN),
            (mode == RD and held(damped_c), SUN),
            (mode == SUN and held(sun_c), ORF),
            (mode == ORF and window[k] and pointing[k] < th.pointing_ready_rad, ROUTE),
            (mode == ROUTE and not window[k], ORF),
        ]
        new = next((to for cond, to in rules if cond), mode)
        if new != mode:
            mode, entry = new, k
        modes.append(mode)
    return np.array(modes)


def _inputs(n, dt=1.0):
    t = dt * np.arange(n)
    return {
        "t_s": t,
        "rate_norm_rad_s": np.zeros(n),
        "attitude_valid": np.ones(n, bool),
        "sun_error_rad": np.zeros(n),
        "pointing_error_rad": np.zeros(n),
        "route_window": np.zeros(n, bool),
        "fault": np.zeros(n, bool),
        "recovered": np.zeros(n, bool),
    }


def test_detumble_to_route_chain_fires_at_analytic_times():
    """B-dot decay ω0 e^{−t/τ}: SUN at ⌈τ ln(ω0/ω_d)⌉ + confirm, then ORF, ROUTE and back to ORF."""
    x = _inputs(4000)
    t = x["t_s"]
    w0, tau_s = np.radians(3.0), 300.0
    x["rate_norm_rad_s"] = w0 * np.exp(-t / tau_s)
    t_damped = np.ceil(tau_s * np.log(w0 / TH.rate_damped_rad_s))  # first 1-s sample below threshold
    t_sun_mode = t_damped + TH.confirm_s
    x["attitude_valid"] = t >= 1500.0
    x["sun_error_rad"] = np.radians(40.0) * np.exp(-(t - t_sun_mode) / 100.0).clip(max=1.0)
    t_sun_ok = t_sun_mode + np.ceil(100.0 * np.log(40.0 / 5.0))  # sun error below 5°
    t_orf = max(t_sun_ok, 1500.0) + TH.confirm_s
    x["route_window"] = (t >= 3000.0) & (t < 3500.0)
    h = md.run_modes(**x)
    assert h.event_t_s.tolist() == [t_sun_mode, t_orf, 3000.0, 3500.0]
    assert list(zip(h.event_from, h.event_to)) == [(RD, SUN), (SUN, ORF), (ORF, ROUTE), (ROUTE, ORF)]
    assert np.array_equal(h.mode, oracle(x))


def test_fault_preempts_every_mode_and_recovery_restarts_rate_damping():
    for start in (RD, SUN, ORF, ROUTE):
        x = _inputs(10)
        x["rate_norm_rad_s"][3] = 1.0  # would send SUN/ORF/ROUTE to damping: the fault has priority
        x["fault"][3] = True
        x["recovered"][[1, 6]] = True  # a recovery command outside FAULT is ignored
        x["route_window"][:] = True  # with a large pointing error: ORF and ROUTE both stay put
        x["pointing_error_rad"][:] = 1.0
        h = md.run_modes(**x, initial_mode=start)
        assert h.event_t_s.tolist() == [3.0, 6.0] and h.event_to.tolist() == [FAULT, RD]


def test_condition_that_breaks_before_confirm_time_does_not_fire():
    x = _inputs(200)
    x["rate_norm_rad_s"][:] = np.where((x["t_s"] % 50) < 49, 0.0, 1.0)  # 49 s runs < 60 s confirm
    assert md.run_modes(**x).event_t_s.size == 0
    x["rate_norm_rad_s"][120:] = 0.0  # a run from t = 100 s (t = 99 s is high): fires at 160 s
    h = md.run_modes(**x)
    assert h.event_t_s.tolist() == [160.0]


def test_attitude_loss_held_sends_orf_back_to_sun_safe():
    x = _inputs(300)
    x["attitude_valid"][100:] = False
    h = md.run_modes(**x, initial_mode=ORF)
    assert h.event_t_s.tolist() == [160.0] and h.event_to.tolist() == [SUN]


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), initial=st.sampled_from([RD, SUN, ORF, ROUTE, FAULT]))
def test_property_transitions_happen_when_and_only_when_conditions_hold(seed, initial):
    rng = np.random.default_rng(seed)
    n = 400
    blocks = np.repeat(np.arange(40), rng.integers(1, 25, 40))[:n]  # piecewise-constant inputs
    pick = lambda values, p=None: np.asarray(values)[rng.choice(len(values), 40, p=p)][blocks]  # noqa: E731
    t = np.cumsum(rng.uniform(1.0, 20.0, blocks.size))
    x = {
        "t_s": t,
        "rate_norm_rad_s": pick([5e-4, 1e-2, 3e-2], [0.6, 0.3, 0.1]),
        "attitude_valid": pick([True, False], [0.8, 0.2]),
        "sun_error_rad": pick([0.01, 0.5]),
        "pointing_error_rad": pick([1e-4, 0.1]),
        "route_window": pick([True, False]),
        "fault": rng.random(blocks.size) < 0.01,
        "recovered": rng.random(blocks.size) < 0.05,
    }
    h = md.run_modes(**x, initial_mode=initial)
    expected = oracle(x, mode=initial)
    assert np.array_equal(h.mode, expected)
    changed = np.flatnonzero(np.diff(np.concatenate([[initial], h.mode])))
    assert np.array_equal(h.event_t_s, t[changed]) and np.array_equal(h.event_to, h.mode[changed])


def test_mode_step_kernel_keeps_state_between_calls():
    state, p = md.initial_state(RD, 0.0), TH.to_array()
    modes = [md.mode_step_1(state, p, float(t), 0.0, True, 1.0, 1.0, False, False, False) for t in range(0, 70, 10)]
    assert modes == [RD] * 6 + [SUN] and state[md.S_ENTERED] == 60.0


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"t_s": np.array([0.0, 0.0, 1.0])}, "t_s"),
        ({"fault": np.zeros(2, bool)}, "fault"),
        ({"sun_error_rad": np.array([0.0, np.nan, 0.0])}, "sun_error_rad"),
        ({"thresholds": md.ModeThresholds(rate_lost_rad_s=1e-4)}, "rate_lost_rad_s"),
        ({"thresholds": md.ModeThresholds(confirm_s=-1.0)}, "confirm_s"),
        ({"initial_mode": 7}, "mode"),
    ],
)
def test_bad_input_names_the_field(change, field):
    x = _inputs(3)
    with pytest.raises(ValueError, match=field):
        md.run_modes(**{**x, **change})
