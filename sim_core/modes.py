"""Onboard mode logic (seed 001 §1, seed 003 §3): rate damping → Sun/safe → ORF → route, and a fault mode.

Seed 001 (AIST-2D): after separation or an unoriented flight the ACS starts in initial-rate damping,
then one-axis and three-axis orientation; programmed turns fly the routes; on errors control passes
to the fault mode. Seed 003: the safe-hold mode (SHM), B-dot damping down to a capture threshold.
The seeds give no thresholds; ours are in :class:`ModeThresholds` with their reasons.

Transitions, in priority order (the first that holds wins; "held" means continuously for
``confirm_s`` on the steps after entering the current mode):

====================  ===============  ===========================================================
from                  to               condition
====================  ===============  ===========================================================
any but FAULT         FAULT            fault flag (from FDIR)
FAULT                 RATE_DAMPING     recovery command (ground)
SUN_SAFE, ORF, ROUTE  RATE_DAMPING     |ω| > rate_lost_rad_s
ORF, ROUTE            SUN_SAFE         attitude invalid, held
RATE_DAMPING          SUN_SAFE         |ω| < rate_damped_rad_s, held
SUN_SAFE              ORF              attitude valid and Sun error < sun_capture_rad, held
ORF                   ROUTE            route window open and pointing error < pointing_ready_rad
ROUTE                 ORF              route window closed
====================  ===============  ===========================================================

The state is a small float64 array (mode, entry time, one timer per held condition; NaN = not
running) so :func:`mode_step_1` runs inside the engine's compiled loop; :func:`run_modes` runs the
machine over sampled inputs and returns the modes and the transition events with their times.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = [
    "MODE_RATE_DAMPING",
    "MODE_SUN_SAFE",
    "MODE_ORF",
    "MODE_ROUTE",
    "MODE_FAULT",
    "MODE_NAMES",
    "STATE_SIZE",
    "ModeThresholds",
    "ModeHistory",
    "initial_state",
    "mode_step_1",
    "run_modes",
]

MODE_RATE_DAMPING, MODE_SUN_SAFE, MODE_ORF, MODE_ROUTE, MODE_FAULT = 0, 1, 2, 3, 4
MODE_NAMES = ("rate_damping", "sun_safe", "orf_stabilisation", "route", "fault")

# State layout.
S_MODE = 0
S_ENTERED = 1  # time the current mode was entered (s)
S_TIMER_DAMPED = 2  # start of the current run of |ω| < rate_damped (s) or NaN
S_TIMER_SUN = 3  # start of the current run of "Sun acquired" (s) or NaN
S_TIMER_LOST = 4  # start of the current run of "attitude invalid" (s) or NaN
STATE_SIZE = 5

# Threshold array layout.
P_RATE_DAMPED, P_RATE_LOST, P_SUN_CAPTURE, P_POINTING_READY, P_CONFIRM = 0, 1, 2, 3, 4


class ModeThresholds(NamedTuple):
    """Transition thresholds (SI); defaults chosen for a 300–500 kg LEO imager, reasons inline."""

    rate_damped_rad_s: float = np.radians(0.1)  # wheels (0.2 N·m, ~4 N·m·s) capture 0.1 °/s easily
    rate_lost_rad_s: float = np.radians(1.0)  # 10× hysteresis: only a real tumble sends us back
    sun_capture_rad: float = np.radians(5.0)  # panels still give cos 5° = 99.6 % of their power
    pointing_ready_rad: float = np.radians(0.1)  # ORF settled before a route's first turn
    confirm_s: float = 60.0  # ≥ several B-dot / Sun-loop time constants of 5–20 s

    def to_array(self) -> np.ndarray:
        """Threshold array for :func:`mode_step_1`, validated (each must be finite, ≥ 0)."""
        a = np.array(self, dtype=float)
        for name, value in zip(self._fields, a):
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name}: must be a finite non-negative number, got {value!r}")
        if self.rate_lost_rad_s <= self.rate_damped_rad_s:
            raise ValueError("rate_lost_rad_s: must exceed rate_damped_rad_s (hysteresis)")
        return a


class ModeHistory(NamedTuple):
    """Mode at each sample and the transition events (time, from, to) as arrays."""

    mode: np.ndarray
    event_t_s: np.ndarray
    event_from: np.ndarray
    event_to: np.ndarray


def initial_state(mode: int = MODE_RATE_DAMPING, t_s: float = 0.0) -> np.ndarray:
    """State array of the mode machine entering ``mode`` at ``t_s`` with no timer running."""
    if mode not in range(len(MODE_NAMES)):
        raise ValueError(f"mode: expected one of 0..{len(MODE_NAMES) - 1} ({', '.join(MODE_NAMES)}), got {mode!r}")
    state = np.full(STATE_SIZE, np.nan)
    state[S_MODE], state[S_ENTERED] = mode, t_s
    return state


@njit(cache=True)
def _held_1(state: np.ndarray, slot: int, holds: bool, t: float, confirm: float) -> bool:
    """Advance the timer of one held condition; True once it has held for ``confirm`` seconds."""
    if not holds:
        state[slot] = np.nan
        return False
    if np.isnan(state[slot]):
        state[slot] = t
    return bool(t - state[slot] >= confirm)


@njit(cache=True)
def _next_mode_1(
    mode: int,
    p: np.ndarray,
    rate: float,
    fault: bool,
    recovered: bool,
    lost: bool,
    damped: bool,
    sun: bool,
    route_window: bool,
    pointing_error: float,
) -> int:
    """The transition table of the module docstring, in priority order."""
    if mode == MODE_FAULT:
        return MODE_RATE_DAMPING if recovered else MODE_FAULT
    if fault:
        return MODE_FAULT
    if mode != MODE_RATE_DAMPING and rate > p[P_RATE_LOST]:
        return MODE_RATE_DAMPING
    if (mode in (MODE_ORF, MODE_ROUTE)) and lost:
        return MODE_SUN_SAFE
    if mode == MODE_RATE_DAMPING and damped:
        return MODE_SUN_SAFE
    if mode == MODE_SUN_SAFE and sun:
        return MODE_ORF
    if mode == MODE_ORF and route_window and pointing_error < p[P_POINTING_READY]:
        return MODE_ROUTE
    if mode == MODE_ROUTE and not route_window:
        return MODE_ORF
    return mode


@njit(cache=True)
def mode_step_1(
    state: np.ndarray,
    thresholds: np.ndarray,
    t: float,
    rate_norm: float,
    attitude_valid: bool,
    sun_error: float,
    pointing_error: float,
    route_window: bool,
    fault: bool,
    recovered: bool,
) -> int:
    """One step of the seed 001/003 mode machine at time t (s); updates ``state``, returns the mode."""
    mode = int(state[S_MODE])
    confirm = thresholds[P_CONFIRM]
    damped = _held_1(state, S_TIMER_DAMPED, rate_norm < thresholds[P_RATE_DAMPED], t, confirm)
    sun = _held_1(state, S_TIMER_SUN, attitude_valid and sun_error < thresholds[P_SUN_CAPTURE], t, confirm)
    lost = _held_1(state, S_TIMER_LOST, not attitude_valid, t, confirm)
    new = _next_mode_1(mode, thresholds, rate_norm, fault, recovered, lost, damped, sun, route_window, pointing_error)
    if new != mode:
        state[S_MODE], state[S_ENTERED] = new, t
        state[S_TIMER_DAMPED:] = np.nan
    return new


@njit(cache=True)
def _run_1(
    state: np.ndarray,
    p: np.ndarray,
    t: np.ndarray,
    rate: np.ndarray,
    valid: np.ndarray,
    sun: np.ndarray,
    pointing: np.ndarray,
    window: np.ndarray,
    fault: np.ndarray,
    recovered: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    n = t.shape[0]
    modes = np.empty(n, dtype=np.int64)
    events = np.empty((n, 3))
    k = 0
    for i in range(n):
        before = int(state[S_MODE])
        modes[i] = mode_step_1(
            state, p, t[i], rate[i], valid[i], sun[i], pointing[i], window[i], fault[i], recovered[i]
        )
        if modes[i] != before:
            events[k, 0], events[k, 1], events[k, 2] = t[i], before, modes[i]
            k += 1
    return modes, events[:k]


def run_modes(
    t_s: np.ndarray,
    rate_norm_rad_s: np.ndarray,
    attitude_valid: np.ndarray,
    sun_error_rad: np.ndarray,
    pointing_error_rad: np.ndarray,
    route_window: np.ndarray,
    fault: np.ndarray,
    recovered: np.ndarray,
    thresholds: ModeThresholds = ModeThresholds(),
    initial_mode: int = MODE_RATE_DAMPING,
) -> ModeHistory:
    """Run the mode machine over sampled inputs (seed 001/003 modes); events carry their times."""
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0.0):
        raise ValueError("t_s: expected a finite, strictly increasing 1-D array of times")
    floats = {
        "rate_norm_rad_s": rate_norm_rad_s,
        "sun_error_rad": sun_error_rad,
        "pointing_error_rad": pointing_error_rad,
    }
    flags = {"attitude_valid": attitude_valid, "route_window": route_window, "fault": fault, "recovered": recovered}
    arrays = {}
    for name, x in {**floats, **flags}.items():
        x = np.asarray(x, dtype=bool if name in flags else float)
        if x.shape != t.shape or (name in floats and not np.all(np.isfinite(x))):
            raise ValueError(f"{name}: expected {t.size} finite samples, one per time in t_s")
        arrays[name] = x
    state = initial_state(initial_mode, float(t[0]) if t.size else 0.0)
    modes, events = _run_1(
        state,
        thresholds.to_array(),
        t,
        arrays["rate_norm_rad_s"],
        arrays["attitude_valid"],
        arrays["sun_error_rad"],
        arrays["pointing_error_rad"],
        arrays["route_window"],
        arrays["fault"],
        arrays["recovered"],
    )
    return ModeHistory(modes, events[:, 0], events[:, 1].astype(np.int64), events[:, 2].astype(np.int64))
