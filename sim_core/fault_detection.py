"""Residual statistics for fault detection: a local-level Kalman likelihood and a quantisation-aware window test.

Every diagnosis channel (a wheel's momentum balance, a gyro axis against the attitude kinematics) is
a scalar signal y_k = x_k + o_k + v_k with x_{k+1} = x_k + d_k + w_k: a known drift d (the commanded
wheel torque integrated, or zero), an offset o (a sensor bias after its onset), white measurement
noise v ~ N(0, R) (a tachometer's rounding to a quantum q is taken as R = q²/12, Widrow's model) and
process noise w ~ N(0, Q_k) (what the drift does not know: the commands between telemetry samples,
unmodelled torques). :func:`level_loglik` is the exact Gaussian log-likelihood of that model (the
innovations of its Kalman filter), batched over hypotheses; a seized rotor is a reset of x to 0.
:func:`count_loglik` is the same model with the rounding taken exactly (a reading says the speed lies in
its count's interval): the white-noise model is sure that nothing happened when a small fault moves the
speed by less than a count, and cannot place an onset while the reading does not move.

Detection (:func:`window_alarm`) does not trust R to be Gaussian: a rounding error is bounded,
|e| ≤ q/2, and strongly correlated on a slow ramp, so a CUSUM of normalised innovations alarms on a
slowly turning wheel. Instead the open-loop residual r_k = y_k − y_0 − Σ d is differenced over a
bank of window lengths L, and a window alarms when |r_k − r_{k−L}| > q + n σ_L, with σ_L² the
process and white-noise variance accumulated over the window. The rounding part never exceeds q,
so the false-alarm probability per test is at most 2Φ(−n) (Gaussian process noise), and by the union
bound the rate per sample is at most (windows × channels) × 2Φ(−n) (:func:`false_alarms_per_day`).
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_core.threads import thread_budget

__all__ = [
    "N_SIGMA",
    "WINDOWS_S",
    "Alarm",
    "count_loglik",
    "false_alarms_per_day",
    "level_loglik",
    "open_loop_residual",
    "window_alarm",
]

WINDOWS_S = (10.0, 30.0, 100.0, 300.0, 1000.0)  # a failed wheel commanded 1e-5 N·m shows one 0.25 rpm count in ~30 s
N_SIGMA = 6.5  # 2Φ(−6.5) = 8e-11 per test: with 5 windows × 10 channels at 1 Hz, ≤ 3.5e-4 false alarms a day


@dataclass(frozen=True)
class Alarm:
    """First window test that failed: channel, sample index, window length (samples) and the test ratio."""

    channel: int
    index: int
    window: int
    ratio: float


@njit(cache=True)
def level_loglik(
    y: np.ndarray, drift: np.ndarray, q_var: np.ndarray, r_var: np.ndarray, offset: np.ndarray, reset: np.ndarray
) -> np.ndarray:
    """Log-likelihood (B,) of y (n,) under B local-level models x_{k+1} = x_k + drift[b, k] (+ N(0, q_var[k])),
    y_k = x_k + offset[b, k] + N(0, r_var[k]); reset[b, k] forces x_k = 0 exactly (seized rotor). NaN y: no update.

    Diffuse start: x = y − offset at the first finite sample, which carries no likelihood.
    """
    n_b, n = drift.shape[0], y.shape[0]
    out = np.zeros(n_b)
    for b in range(n_b):
        x = y[0] - offset[b, 0]
        p = r_var[0]
        started = not np.isnan(x)
        ll = 0.0
        for k in range(1, n):
            x += drift[b, k - 1]
            p += q_var[k - 1]
            if reset[b, k]:
                x = 0.0
                p = 0.0
            if np.isnan(y[k]):
                continue
            if not started:
                x, p, started = y[k] - offset[b, k], r_var[k], True
                continue
            nu = y[k] - x - offset[b, k]
            s = p + r_var[k]
            ll -= 0.5 * (math.log(2.0 * math.pi * s) + nu * nu / s)
            gain = p / s
            x += gain * nu
            p *= 1.0 - gain
        out[b] = ll
    return out


_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
COUNT_COMPONENTS = 4  # slices of the first reading's count carried by :func:`count_loglik`
INSIDE_SIGMAS = 8.0  # a state this many σ inside its reading's count: the reading's probability is 1 − 1e-15
NEGLIGIBLE_TAIL_SIGMAS = 9.5  # Φ(−9.5) = 1e-21: next to a probability ≥ ½ it is below a double's resolution
THREAD_ROWS = 64  # likelihood rows per thread at least: fewer are not worth a thread's start
EXP_UNDERFLOW = -746.0  # e^x below this is 0.0 in double precision (the least subnormal is e^-744.4)
FAR_EDGE_LOG_RATIO = 50.0  # ln Φ(near) − ln Φ(far) beyond this: the far edge's tail is not computed
ABANDON_MARGIN = 1e-6  # a row abandoned this far below its floor: ≫ the round-off a record's readings can add back


@njit(cache=True)
def _exp(x: float) -> float:
    """e^x, bit for bit, without the call where it is known: 1 at 0, 0 below EXP_UNDERFLOW (a dead slice, −∞)."""
    if x == 0.0:
        return 1.0
    if x < EXP_UNDERFLOW:
        return 0.0
    return math.exp(x)


@njit(cache=True)
def _log_phi_cdf(x: float) -> float:
    """ln Φ(x), accurate in the far lower tail (asymptotic series where erfc underflows)."""
    if x > -20.0:
        return math.log(0.5 * math.erfc(-x / math.sqrt(2.0)))
    x2 = x * x
    return -0.5 * x2 - math.log(-x) - _LOG_SQRT_2PI + math.log1p(-1.0 / x2 + 3.0 / (x2 * x2))


@njit(cache=True)
def _log_interval(alpha: float, beta: float) -> float:
    """ln(Φ(β) − Φ(α)), α < β, without cancellation in either tail; a tail beyond NEGLIGIBLE_TAIL_SIGMAS is not
    computed where the other side holds ½ or more."""
    if beta <= 0.0 or alpha >= 0.0:
        near, far = (beta, alpha) if beta <= 0.0 else (-alpha, -beta)
        hi = _log_phi_cdf(near)
        if -0.5 * far * far - _LOG_SQRT_2PI - hi < -FAR_EDGE_LOG_RATIO:
            return hi  # Φ(far) < φ(far) ≤ e^-50 Φ(near) (Mills, |far| > 1): below half an ulp of ln Φ(near) ≤ −ln 2
        lo = _log_phi_cdf(far)
    else:
        upper = 0.5 * math.erfc(beta / math.sqrt(2.0)) if beta < NEGLIGIBLE_TAIL_SIGMAS else 0.0
        lower = 0.5 * math.erfc(-alpha / math.sqrt(2.0)) if alpha > -NEGLIGIBLE_TAIL_SIGMAS else 0.0
        return math.log(1.0 - upper - lower)
    return hi + math.log1p(-math.exp(lo - hi))


@njit(cache=True)
def _truncated_moments(alpha: float, beta: float, log_z: float) -> tuple[float, float]:
    """Mean and variance of a standard normal truncated to [α, β] (Z = Φ(β) − Φ(α) given as ln Z); an edge beyond
    NEGLIGIBLE_TAIL_SIGMAS on the far side of 0 (Z > ½) adds nothing."""
    far_a, far_b = alpha < -NEGLIGIBLE_TAIL_SIGMAS and beta > 0.0, beta > NEGLIGIBLE_TAIL_SIGMAS and alpha < 0.0
    pa = 0.0 if far_a else _exp(-0.5 * alpha * alpha - _LOG_SQRT_2PI - log_z)  # φ(α)/Z
    pb = 0.0 if far_b else _exp(-0.5 * beta * beta - _LOG_SQRT_2PI - log_z)
    mean = pa - pb
    var = 1.0 + alpha * pa - beta * pb - mean * mean
    width = beta - alpha  # a variable on [α, β] has variance ≤ width²/4; round-off in the far tail can break it
    return min(max(mean, alpha), beta), min(max(var, 1e-12 * width * width), 0.25 * width * width)


@njit(cache=True)
def _count_update(x: float, p: float, y: float, half: float, sensor_var: float) -> tuple[float, float, float]:
    """One reading y of a state N(x, p) (offset removed): ln P(reading), and the moment-matched posterior."""
    s = math.sqrt(p + sensor_var)
    alpha = (y - half - x) / s
    beta = (y + half - x) / s
    log_z = _log_interval(alpha, beta)
    mean, var = _truncated_moments(alpha, beta, log_z)
    gain = p / (s * s)  # x given the reading's sum z = x + o + v, then z's truncated moments
    return log_z, x + gain * s * mean, p * (1.0 - gain) + gain * gain * s * s * var


def count_loglik(
    y: np.ndarray,
    drift: np.ndarray,
    q_var: np.ndarray,
    quantum: float,
    sensor_var: float,
    offset: np.ndarray,
    reset: np.ndarray,
    nominal_drift: np.ndarray | None = None,
    floor: np.ndarray | None = None,
) -> np.ndarray:
    """Log-likelihood (B,) of tachometer readings y (n,), each the speed rounded to a multiple of ``quantum``,
    under the local-level models of :func:`level_loglik` with the rounding taken exactly: a reading says
    x_k + o_k + v_k ∈ [y_k − q/2, y_k + q/2] (v ~ N(0, sensor_var) > 0), probability Φ(β) − Φ(α) under the
    predicted N(x̂, P + sensor_var). A reading that cannot tell two speeds apart gives them the same
    probability; a count transition earlier or later than predicted is evidence.

    The state density is a sum of Gaussians, each matched to its truncated posterior's mean and variance
    after every reading (assumed-density filtering); the start, uniform over the first reading's count,
    is COUNT_COMPONENTS equal slices (variance of each: its slice's, (q/K)²/12), carrying no likelihood.
    ``reset`` as in :func:`level_loglik`, but the first reset sample reads the rotor braking, uniform between its
    speed and 0 (a count is exact: a rotor seized between samples is not read at 0 at once).

    ``nominal_drift`` (n−1,): a row that equals it (with zero offset and no reset) up to some sample continues
    from the nominal model's filter state there instead of filtering that prefix again (a fault hypothesis is
    the nominal model before its onset); the result is the same, bit for bit.

    ``floor`` (B,): a reading's log-probability is never positive, so a row's log-likelihood only falls as it is
    filtered; a row is abandoned once it lies ABANDON_MARGIN below ``floor[b]`` and its value is then that partial
    log-likelihood, below ``floor[b]`` as the full one would be (a profile keeping the best of its candidates, the
    best so far as the floor, chooses the same rows and the same values).

    Rows are filtered independently, in blocks of at least THREAD_ROWS on one thread per core (this process' share
    of them, :func:`sim_core.threads.thread_budget`; the kernel releases the GIL); the result does not depend on the
    split.
    """
    nominal = np.full(y.shape[0] - 1, np.nan) if nominal_drift is None else np.ascontiguousarray(nominal_drift)
    lowest = np.full(drift.shape[0], -np.inf) if floor is None else np.ascontiguousarray(floor, dtype=np.float64)

    def block(rows: slice) -> np.ndarray:
        out: npt.NDArray[np.float64] = _count_loglik(
            y, drift[rows], q_var, quantum, sensor_var, offset[rows], reset[rows], nominal, lowest[rows]
        )
        return out

    n_blocks = max(1, min(thread_budget(), drift.shape[0] // THREAD_ROWS))
    if n_blocks == 1:
        return block(slice(None))
    edges = np.linspace(0, drift.shape[0], n_blocks + 1).astype(int)
    with ThreadPoolExecutor(max_workers=n_blocks) as pool:
        return np.concatenate(list(pool.map(block, [slice(a, b) for a, b in zip(edges[:-1], edges[1:])])))


@njit(cache=True)
def _count_step(
    k: int,
    y: np.ndarray,
    drift_in: float,
    q_in: float,
    reset_now: bool,
    reset_before: bool,
    offset: float,
    quantum: float,
    sensor_var: float,
    xs: np.ndarray,
    ps: np.ndarray,
    lw: np.ndarray,
    started: bool,
) -> tuple[bool, float]:
    """Propagate the mixture over interval k−1 → k and read sample k (in place); (started, ln P(reading))."""
    m = xs.shape[0]
    half = 0.5 * quantum
    if k > 0:
        for i in range(m):
            xs[i] += drift_in
            ps[i] += q_in
            if reset_now and not reset_before:  # seized between samples: read braking, 0 to x
                ps[i] += xs[i] * xs[i] / 12.0
                xs[i] *= 0.5
            elif reset_now:
                xs[i] = 0.0
                ps[i] = 0.0
    if np.isnan(y[k]):
        return started, 0.0
    if not started:
        for i in range(m):
            xs[i] = y[k] - offset + quantum * ((i + 0.5) / m - 0.5)
            ps[i] = (quantum / m) ** 2 / 12.0
            lw[i] = -math.log(m)
        return True, 0.0
    top = -np.inf
    reading = y[k] - offset
    for i in range(m):
        if lw[i] <= -50.0:  # a slice this unlikely adds nothing to the sum
            lw[i] = -np.inf
        elif half - abs(reading - xs[i]) > INSIDE_SIGMAS * math.sqrt(ps[i] + sensor_var):
            pass  # deep inside the count: probability 1 − 2Φ(−INSIDE_SIGMAS), the state unchanged
        else:
            log_z, xs[i], ps[i] = _count_update(xs[i], ps[i], reading, half, sensor_var)
            lw[i] += log_z
        top = max(top, lw[i])
    total = 0.0
    for i in range(m):
        total += _exp(lw[i] - top)
    log_sum = top + (0.0 if total == 1.0 else math.log(total))  # ln 1 = 0 exactly: one slice left
    for i in range(m):
        lw[i] -= log_sum
    return True, log_sum


@njit(cache=True, nogil=True)
def _count_loglik(
    y: np.ndarray,
    drift: np.ndarray,
    q_var: np.ndarray,
    quantum: float,
    sensor_var: float,
    offset: np.ndarray,
    reset: np.ndarray,
    nominal: np.ndarray,
    floor: np.ndarray,
) -> np.ndarray:
    """:func:`count_loglik`'s kernel: the nominal model filtered once, its state kept after every reading; rows
    abandoned below their floor."""
    n_b, n = drift.shape[0], y.shape[0]
    m = COUNT_COMPONENTS
    out = np.zeros(n_b)
    xs = np.empty(m)
    ps = np.empty(m)
    lw = np.empty(m)
    kept_x = np.empty((n, m))
    kept_p = np.empty((n, m))
    kept_w = np.empty((n, m))
    kept_ll = np.empty(n)
    kept_started = np.zeros(n, dtype=np.bool_)
    shared = not np.isnan(nominal).any()
    if shared:
        started, ll = False, 0.0
        for k in range(n):
            d_in = nominal[k - 1] if k > 0 else 0.0
            q_in = q_var[k - 1] if k > 0 else 0.0
            started, step = _count_step(k, y, d_in, q_in, False, False, 0.0, quantum, sensor_var, xs, ps, lw, started)
            ll += step
            kept_x[k], kept_p[k], kept_w[k], kept_ll[k], kept_started[k] = xs, ps, lw, ll, started
    for b in range(n_b):
        first = 0  # first sample whose step differs from the nominal model's
        if shared:
            while first < n and offset[b, first] == 0.0 and not reset[b, first]:
                if first > 0 and drift[b, first - 1] != nominal[first - 1]:
                    break
                first += 1
        if first == 0:
            started, ll = False, 0.0
        else:
            xs[:], ps[:], lw[:] = kept_x[first - 1], kept_p[first - 1], kept_w[first - 1]
            started, ll = kept_started[first - 1], kept_ll[first - 1]
        for k in range(first, n):
            d_in = drift[b, k - 1] if k > 0 else 0.0
            q_in = q_var[k - 1] if k > 0 else 0.0
            reset_before = reset[b, k - 1] if k > 0 else False
            started, step = _count_step(
                k, y, d_in, q_in, reset[b, k], reset_before, offset[b, k], quantum, sensor_var, xs, ps, lw, started
            )
            ll += step
            if ll < floor[b] - ABANDON_MARGIN:
                break
        out[b] = ll
    return out


def open_loop_residual(y: np.ndarray, drift: np.ndarray) -> np.ndarray:
    """r_k = y_k − y_0 − Σ_{j<k} d_j: what the drift model leaves unexplained, from the first finite sample."""
    r = y - np.concatenate([[0.0], np.cumsum(drift)])
    finite = np.flatnonzero(np.isfinite(r))
    unexplained: npt.NDArray[np.float64] = r - (r[finite[0]] if finite.size else 0.0)
    return unexplained


def window_alarm(
    residual: np.ndarray,
    q_var: np.ndarray,
    r_var: np.ndarray,
    bound: float,
    dt_s: float,
    n_sigma: float = N_SIGMA,
    windows_s: tuple[float, ...] = WINDOWS_S,
    relative: np.ndarray | None = None,
) -> Alarm | None:
    """First k where |r_k − r_{k−L}| > bound + |Σ_L relative| + n σ_L for some window L (residual, r_var (n_ch, n),
    q_var (n_ch, n−1)); ``relative`` (n_ch, n−1) is a bounded systematic error per interval (e.g. a parameter
    tolerance times the modelled increment), summed over the window."""
    best: Alarm | None = None
    n_ch, n = residual.shape
    cum_q = np.concatenate([np.zeros((n_ch, 1)), np.cumsum(q_var, axis=1)], axis=1)
    rel = np.zeros((n_ch, n - 1)) if relative is None else relative
    cum_rel = np.concatenate([np.zeros((n_ch, 1)), np.cumsum(rel, axis=1)], axis=1)
    for w_s in windows_s:
        lag = max(1, round(w_s / dt_s))
        if lag >= n:
            continue
        diff = residual[:, lag:] - residual[:, :-lag]
        sigma = np.sqrt(cum_q[:, lag:] - cum_q[:, :-lag] + r_var[:, lag:] + r_var[:, :-lag])
        ratio = (np.abs(diff) - bound - np.abs(cum_rel[:, lag:] - cum_rel[:, :-lag])) / sigma
        hit = np.nan_to_num(ratio, nan=-np.inf) > n_sigma
        if not hit.any():
            continue
        ch, k = np.unravel_index(np.argmax(hit), hit.shape) if hit.shape[0] == 1 else _first_hit(hit)
        index = int(k) + lag
        if best is None or index < best.index:
            best = Alarm(int(ch), index, lag, float(ratio[ch, k]))
    return best


def _first_hit(hit: np.ndarray) -> tuple[int, int]:
    """(channel, column) of the earliest True over all channels."""
    cols = np.where(hit.any(axis=1), hit.argmax(axis=1), hit.shape[1])
    ch = int(np.argmin(cols))
    return ch, int(cols[ch])


def false_alarms_per_day(
    n_channels: int, dt_s: float, n_sigma: float = N_SIGMA, n_windows: int = len(WINDOWS_S)
) -> float:
    """Union bound on window-test false alarms per day: 86,400/dt × windows × channels × 2Φ(−n)."""
    tail = math.erfc(n_sigma / math.sqrt(2.0))
    return 86_400.0 / dt_s * n_windows * n_channels * tail
