"""Automatic fault diagnosis from ACS housekeeping: detect, prune, estimate, rank (seed 000 §7 in-flight support).

Pipeline (DESIGN.md "Diagnosis"), pure numerics on telemetered arrays (:class:`Observations`):

1. **Residual channels.** Per wheel p, the momentum balance of seed 000 eq (1) row 3,
   J_r (Ω̇_p + a_pᵗ ω̇) = m_p − m^f_p, integrated between telemetry samples with the *telemetered*
   command (held at the control period T_u, the unseen commands between samples interpolated and their
   spread counted as process noise, its rounding as the held error it is), against the tachometer speed
   rounded to its quantum. Per gyro axis, the gyro rate against the rate of the telemetered attitude
   quaternions. Star-tracker validity. Per magnetometer axis, the field against the scenario's field model
   (when the telemetry carries it).
2. **Detection** (:func:`sim_core.fault_detection.window_alarm`): quantisation-bounded window tests on
   the open-loop residuals, false-alarm rate stated by :func:`detection_rate_per_day`; the alarm bounds
   the onset search.
3. **Pruning.** Wheels whose momentum balance never leaves PRUNE_SIGMA of what quantisation and noise
   explain inside the analysis window carry no fault hypothesis (pairs are built from survivors only).
4. **Estimation.** For every surviving hypothesis the likelihood of its channel is profiled over the
   onset (every sample of the search window) and the magnitude. A wheel's tachometer readings are
   taken as what they are, the speed rounded to its quantum (:func:`sim_core.fault_detection.count_loglik`):
   a small fault that shifts when the counts change is evidence, one that changes no reading is as
   likely as "none". The magnitude starts from the Gaussian model's exact maximum (rounding as white
   noise q²/12, :func:`sim_core.fault_detection.level_loglik`, quadratic in a remaining gain, an added
   friction torque or a bias) and is refined on the count likelihood. With nothing alarming, every
   wheel is fitted (a fault below the alarm is still a hypothesis) on records up to an hour.
5. **Ranking.** Evidence = log mean over onsets of the profiled likelihood (uniform onset prior, so
   searching many onsets is paid for) − ½ ln n per magnitude parameter (BIC), relative to "none";
   posterior probabilities with equal priors are the scores. Wheel channels are independent given the
   telemetered commands, so a pair's evidence is the sum of its members'.
6. **Replay** (:func:`_replayed`): the top hypotheses are flown as variants of one twin batch from a
   telemetry instant before the onset, and the fit of each to the commands and attitude is evidence.
   :func:`hypothesis_replay` builds the same batch for one ranked hypothesis, of any fault type (the simulated
   monitor flies it; :func:`hypothesis_faults` maps it to engine faults).

"No fault" is a hypothesis; the top score is a probability that says how far the data support it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from itertools import combinations

import numpy as np
import numpy.typing as npt

from sim_core import fault_detection as fd
from sim_core.scenario import FaultSpec, Scenario

__all__ = [
    "MIN_SAMPLES",
    "SENSOR_FAULTS",
    "WHEEL_FAULTS",
    "Diagnosis",
    "Hypothesis",
    "Observations",
    "WheelModel",
    "detection_rate_per_day",
    "diagnose",
    "flight_sensor_residuals",
    "hypothesis_faults",
    "hypothesis_replay",
    "tachometer_readings",
    "wheel_model",
]

WHEEL_FAULTS = ("failure", "gain_loss", "friction", "stuck", "speed_bias")
SENSOR_FAULTS = ("gyro_bias", "star_tracker_outage", "magnetometer_bias")
SENSOR_BIAS_TARGETS = {"gyro_bias": "gyro", "magnetometer_bias": "magnetometer"}  # engine fault targets, per body axis
MIN_SAMPLES = 60  # a minute at 1 Hz: shorter telemetry cannot separate a fault from quantisation
UNMODELLED_TORQUE_NM = 2e-6  # σ of wheel torque the balance does not model (bearing ripple, drag): 10 % of a GG command
NOMINAL_LEAD_S = 60.0  # nominal data kept before the onset search window
POST_ALARM_S = 20.0  # data after the alarm used to identify the fault (latency budget 30 s)
ONSET_MARGIN_S = 60.0  # an FDIR isolation follows the onset by at most this much
ONSET_SEARCH_S = 360.0  # the onset may precede the start of the alarming window by this much: a wheel commanded
# a few µN·m that fails moves its tachometer by the counts a window test needs only minutes later
PRUNE_SIGMA = 3.0  # a wheel whose balance stays within 3σ (+ quantisation) is not suspected
INVALID_PROBABILITY = 1e-4  # a healthy star tracker's invalid samples (Sun or Moon in the field of view)
MAX_REMAINING_GAIN = 0.95  # a gain loss smaller than 5 % is "none" at this resolution
MAX_LISTED = 12
UNRESOLVED_FRICTION_NM = 1.0  # no data after the onset: a friction would have to be absurd to show
PAIR_PRIOR_LOG_ODDS = math.log(100.0)  # two wheel faults within one diagnosis window: 1/100 the prior of one
FDIR_MISS_LOG_ODDS = math.log(1e4)  # the onboard FDIR isolates a healthy wheel at most once in 10^4 isolations
ROTOR_TOLERANCE = 0.02  # torque → speed known within 2 %: rotor inertia and motor torque constant tolerances
COUPLING_TOLERANCE = 0.5  # an estimated body rate lags a sudden change by up to half a sample at 1 Hz
SECOND_FAULT_S = 600.0  # alarms this soon after the first are diagnosed with it (issue 14: within 10 minutes)
REPLAYED = 3  # wheel hypotheses flown in the twin replay
REPLAY_ONSETS = 13  # onsets tried per replayed hypothesis
REPLAY_LEAD_S = 60.0  # the twin starts this long before the earliest onset tried
FLIGHT_AFTER_S = 600.0  # a hypothesis flown on the simulated monitor: this long after its onset (issue 14's 10 min)
RESOLVED_COUNTS = 2  # a reading that moves by one count may be the rounding of an arbitrarily small change:
# a speed bias, a friction or a gain loss is claimed only if it moves the tachometer by two counts or more
SUB_SAMPLE = 4  # onsets tried per telemetry interval (a fault starts between samples)
UNALARMED_FIT_SAMPLES = 3_600  # records up to this long are searched for a fault below the alarm (an hour at 1 Hz)
TACHOMETER_JITTER = 0.02  # σ of a reading's white error beyond its rounding, in counts (float telemetry, sampling
# instant); a slowly varying model error is the balance's process noise, not this: a white jitter repeated over
# hundreds of unchanged readings would tell a still speed from one a fraction of a count from the count's edge
MAGNITUDE_STEPS = (-0.25, 0.25)  # relative steps tried around the Gaussian model's magnitude
STEP_CANDIDATES = 3  # jumps per channel a strided onset grid adds onsets at: a step fault shows as one jump, the
# three largest leave room for two nominal ones as large (count transitions, a seizure's kick)
REFINEMENTS = 2  # step halvings around the best magnitude candidate (a gain to 0.025)
GAIN_GRID = tuple(float(g) for g in np.arange(0.0, 0.91, 0.1))  # remaining gains tried on the count likelihood
KINEMATIC_RATE_FLOOR_RAD_S = 2e-7  # float32 quaternion components (6e-8) differenced over 1 s, with margin


@dataclass(frozen=True)
class Observations:
    """Telemetered ACS housekeeping at times ``t_s`` after ``epoch_unix_s`` (engine frames, SI units).

    Required: estimated attitude, rates, wheel speeds and wheel torque commands; optional: measured
    (star-tracker) attitude, gyro rates, magnetometer field (NaN rows = no sample).
    """

    t_s: np.ndarray
    epoch_unix_s: float
    q_est_ib: np.ndarray
    omega_b_rad_s: np.ndarray
    wheel_speed_rad_s: np.ndarray
    wheel_torque_cmd_nm: np.ndarray
    speed_quantum_rad_s: float
    torque_quantum_nm: float = 0.0
    q_st_ib: np.ndarray | None = None
    q_prog_ib: np.ndarray | None = None
    omega_gyro_b_rad_s: np.ndarray | None = None
    b_mag_b_t: np.ndarray | None = None
    b_model_b_t: np.ndarray | None = None  # the field model at the telemetered attitude, same layout
    wheel_isolated: np.ndarray | None = None  # onboard FDIR's isolation flags per wheel (n, n_w), if telemetered

    def __post_init__(self) -> None:
        n = self.t_s.shape[0]
        if n < MIN_SAMPLES:
            raise ValueError(f"telemetry: {n} samples; the diagnosis needs at least {MIN_SAMPLES}")
        if np.any(np.diff(self.t_s) <= 0.0):
            raise ValueError("telemetry: sample times must increase")
        for name in ("q_est_ib", "omega_b_rad_s", "wheel_speed_rad_s", "wheel_torque_cmd_nm"):
            a = getattr(self, name)
            if a.shape[0] != n:
                raise ValueError(f"telemetry.{name}: {a.shape[0]} rows for {n} sample times")
        if self.wheel_speed_rad_s.shape != self.wheel_torque_cmd_nm.shape:
            raise ValueError("telemetry: wheel speeds and torque commands cover different wheels")
        if not self.speed_quantum_rad_s > 0.0:
            raise ValueError("telemetry.speed_quantum_rad_s: the tachometer resolution must be positive")

    @property
    def n_wheels(self) -> int:
        """Number of wheels telemetered."""
        return int(self.wheel_speed_rad_s.shape[1])


@dataclass(frozen=True)
class WheelModel:
    """What the momentum balance needs of the cluster: spin axes (3, n_w), rotor inertia, torque limit, dry friction."""

    axes_b: np.ndarray
    inertia_kg_m2: np.ndarray
    max_torque_nm: np.ndarray
    coulomb_nm: np.ndarray
    control_dt_s: float


def wheel_model(
    axes_b: np.ndarray,
    inertia_kg_m2: np.ndarray,
    max_torque_nm: np.ndarray,
    coulomb_nm: np.ndarray,
    control_dt_s: float,
) -> WheelModel:
    """A checked :class:`WheelModel` (arrays as float64)."""
    axes = np.asarray(axes_b, dtype=float)
    jr = np.asarray(inertia_kg_m2, dtype=float)
    if axes.ndim != 2 or axes.shape[0] != 3 or axes.shape[1] != jr.shape[0]:
        raise ValueError("wheel model: axes_b must be (3, n_wheels) with one inertia per wheel")
    return WheelModel(
        axes, jr, np.asarray(max_torque_nm, dtype=float), np.asarray(coulomb_nm, dtype=float), float(control_dt_s)
    )


@dataclass(frozen=True)
class Hypothesis:
    """One ranked explanation: fault name(s), wheel number(s) (1-based), onset, magnitude, score (posterior)."""

    fault: str
    wheel: int | list[int] | None
    onset_s: float | None
    onset_sigma_s: float | None
    magnitude: float | list[float | None] | None
    log_evidence: float
    score: float = 0.0
    # the momentum balance's onset log-likelihood (times s, profiled log-likelihood): the replay's onset prior
    onset_profile: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)


@dataclass
class Diagnosis:
    """The result: ranked hypotheses (best first), the detection and what was pruned."""

    hypotheses: list[Hypothesis]
    detected: bool
    alarm_s: float | None
    alarm_channel: str | None
    false_alarms_per_day: float
    window_s: tuple[float, float]
    suspected_wheels: list[int] = field(default_factory=list)
    untestable: dict[str, str] = field(default_factory=dict)

    @property
    def confidence(self) -> float:
        """Posterior probability of the top hypothesis."""
        return self.hypotheses[0].score


@dataclass
class _Channel:
    """One residual channel ready for the likelihood: signal, nominal drift, noise and the fault templates."""

    name: str
    y: np.ndarray
    drift: np.ndarray
    q_var: np.ndarray
    r_var: np.ndarray
    bound: float
    templates: dict[str, np.ndarray] = field(default_factory=dict)  # per-interval effect of a unit magnitude
    relative: np.ndarray | None = None  # bounded systematic error per interval (parameter tolerance × increment)


def _wheel_channels(obs: Observations, wm: WheelModel, sigma_torque_nm: float) -> list[_Channel]:
    """Momentum balance of every wheel (seed 000 eq 1 row 3) with the telemetered commands as input."""
    t = obs.t_s
    dt = np.diff(t)
    sub = np.maximum(1.0, np.round(dt / wm.control_dt_s))  # commands held per telemetry interval
    # the telemetered command's rounding error (uniform, variance q²/12) is one per command, held over T_u/Δt
    # intervals (two at 1 Hz, T_u = 2 s) or averaged over Δt/T_u commands: as white noise per interval, q²/12·T_u/Δt
    # gives the random walk it drives its variance over any long window (spectral density at zero: q²/12·T_u)
    rounding_var = obs.torque_quantum_nm**2 / 12.0 * wm.control_dt_s / dt
    d_omega = np.diff(obs.omega_b_rad_s, axis=0)
    out = []
    r_var = np.full(t.shape[0], obs.speed_quantum_rad_s**2 / 12.0)
    for p in range(obs.n_wheels):
        u = np.clip(np.nan_to_num(obs.wheel_torque_cmd_nm[:, p]), -wm.max_torque_nm[p], wm.max_torque_nm[p])
        du = np.diff(u)
        u_mean = u[:-1] + du * (sub - 1.0) / (2.0 * sub)  # unseen commands on the line between samples
        u_var = du**2 * (sub - 1.0) / sub**2 / 12.0 + rounding_var + sigma_torque_nm**2
        y = obs.wheel_speed_rad_s[:, p]
        spin = np.sign(np.nan_to_num(y[:-1]))
        jr = wm.inertia_kg_m2[p]
        coupling = np.nan_to_num(d_omega @ wm.axes_b[:, p])
        drift = dt * (u_mean - wm.coulomb_nm[p] * spin) / jr - coupling
        motor = dt * u_mean / jr
        templates = {"motor": motor, "friction": -dt * spin / jr, "coupling": coupling}
        q_var = (dt / jr) ** 2 * u_var + (0.5 * ROTOR_TOLERANCE * motor) ** 2 + (COUPLING_TOLERANCE * coupling) ** 2
        out.append(
            _Channel(
                f"wheel {p + 1}",
                y,
                drift,
                q_var,
                r_var,
                obs.speed_quantum_rad_s,
                templates,
                ROTOR_TOLERANCE * np.abs(motor) + COUPLING_TOLERANCE * np.abs(coupling),
            )
        )
    return out


def _robust_var(x: np.ndarray) -> float:
    """Mean square of the finite values without their largest 1 % (a fault's step is one value; the MAD would
    be fooled by sensors whose noise is not white, e.g. a star tracker's slowly varying error)."""
    x = np.sort(np.abs(x[np.isfinite(x)]))
    if x.size < 3:
        return 0.0
    return float(np.mean(x[: max(2, int(0.99 * x.size))] ** 2))


def _kinematic_rates(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Mean body rate between samples from Λ̇ = ½ Λ∘ω: 2 vec(Λ_k* ∘ Λ_{k+1}) / Δt (first order in the angle)."""
    qa, qb = q[:-1], q[1:]
    w0 = qa[:, 0:1] * qb[:, 1:] - qb[:, 0:1] * qa[:, 1:] - np.cross(qa[:, 1:], qb[:, 1:])
    scalar = np.sum(qa * qb, axis=1, keepdims=True)
    rate: npt.NDArray[np.float64] = 2.0 * np.sign(scalar) * w0 / np.diff(t)[:, None]
    return rate


def _gyro_channels(obs: Observations) -> list[_Channel]:
    """Gyro (or estimated) rate minus the rate of the attitude quaternions, per axis: a gyro bias is a step."""
    rates = obs.omega_gyro_b_rad_s if obs.omega_gyro_b_rad_s is not None else obs.omega_b_rad_s
    q = obs.q_st_ib if obs.q_st_ib is not None else obs.q_est_ib
    kin = _kinematic_rates(q, obs.t_s)
    valid = _star_tracker_valid(q) if obs.q_st_ib is not None else np.ones(q.shape[0], dtype=bool)
    kin[~(valid[1:] & valid[:-1])] = np.nan  # no attitude, no kinematic rate
    mean_rate = 0.5 * (rates[1:] + rates[:-1])
    turn = np.abs(np.diff(rates, n=2, axis=0))  # the trapezoid's error grows with the change of the rate change
    turn = np.concatenate([turn[:1], turn], axis=0)
    out = []
    for axis in range(3):
        y = mean_rate[:, axis] - kin[:, axis]
        r0 = max(_robust_var(np.diff(y)) / 2.0, KINEMATIC_RATE_FLOOR_RAD_S**2)
        r_var = r0 + (0.5 * turn[:, axis]) ** 2
        n = y.shape[0]
        out.append(_Channel(f"gyro {'xyz'[axis]}", y, np.zeros(n - 1), np.full(n - 1, 1e-4 * r0), r_var, 0.0))
    return out


def _magnetometer_channels(obs: Observations) -> list[_Channel]:
    """Measured minus modelled field per axis; the model's slow mismatch is a random walk, a bias a step."""
    y_all = obs.b_mag_b_t - obs.b_model_b_t  # type: ignore[operator]
    out = []
    for axis in range(3):
        y = y_all[:, axis]
        q_var = max(_robust_var(np.diff(y)), 1e-22)
        n = y.shape[0]
        out.append(
            _Channel(
                f"magnetometer {'xyz'[axis]}",
                y,
                np.zeros(n - 1),
                np.full(n - 1, 0.5 * q_var),
                np.full(n, 0.25 * q_var),
                0.0,
            )
        )
    return out


def _star_tracker_valid(q: np.ndarray) -> np.ndarray:
    """Valid star-tracker samples: finite, unit, and not a frozen repeat of the previous sample."""
    norm = np.linalg.norm(q, axis=1)
    ok = np.isfinite(norm) & (np.abs(norm - 1.0) < 1e-3)
    frozen = np.zeros(q.shape[0], dtype=bool)
    frozen[1:] = np.all(q[1:] == q[:-1], axis=1)
    usable: npt.NDArray[np.bool_] = ok & ~frozen
    return usable


def detection_rate_per_day(n_channels: int, dt_s: float) -> float:
    """Stated false-alarm rate of the detector over ``n_channels`` residual channels sampled every ``dt_s``."""
    return fd.false_alarms_per_day(n_channels, dt_s)


def _log_mean_exp(x: np.ndarray, weights: np.ndarray | None = None) -> float:
    """ln of the mean of exp(x), weighted by ``weights`` if given."""
    m = float(np.max(x))
    e = np.exp(x - m)
    return m + math.log(float(np.mean(e) if weights is None else np.average(e, weights=weights)))


def _onset_stats(t: np.ndarray, ll: np.ndarray, widths: np.ndarray | None = None) -> tuple[float, float, int]:
    """Maximum-likelihood onset, posterior σ under a uniform prior (each onset standing for ``widths`` of time if
    given), and its index."""
    w = np.exp(ll - ll.max()) * (1.0 if widths is None else widths)
    w /= w.sum()
    mean = float(w @ t)
    return float(t[int(np.argmax(ll))]), float(np.sqrt(max(w @ (t - mean) ** 2, 0.0))), int(np.argmax(ll))


@dataclass(frozen=True)
class _Fit:
    """A single-channel hypothesis fitted over the onset grid."""

    fault: str
    channel: int
    delta: float  # log evidence against the channel's nominal model (onset-marginal, BIC for the magnitude)
    onset_s: float
    onset_sigma_s: float
    magnitude: float | None
    credit: dict[int, float] = field(default_factory=dict)  # other channels' evidence included (seizure kick)
    profile: tuple[np.ndarray, np.ndarray] | None = None  # onset times (s) and the profiled log-likelihood there


def _profile(
    ch: _Channel, onsets: np.ndarray, kind: str, quadratic: bool, fraction: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Profiled log-likelihood over onset indices (and magnitude if ``quadratic``): (ll (G,), θ* (G,)).

    ``fraction`` of the interval before each onset sample is already faulty (the onset falls between samples:
    a motor dead for the last 0.4 s of an interval delivers 60 % of its command over it)."""
    n = ch.y.shape[0]
    g = onsets.shape[0]
    after = (np.arange(n - 1)[None, :] >= onsets[:, None]).astype(float)  # interval k → k+1 after onset
    if fraction > 0.0:
        after[np.arange(n - 1)[None, :] == onsets[:, None] - 1] = fraction
    after_sample = (np.arange(n)[None, :] >= onsets[:, None]).astype(float)
    zero_off = np.zeros((g, n))
    no_reset = np.zeros((g, n), dtype=np.bool_)
    base = np.broadcast_to(ch.drift, (g, n - 1))

    def run(
        drift: np.ndarray,
        offset: np.ndarray,
        reset: np.ndarray,
        gaussian: bool = False,
        floor: np.ndarray | None = None,
    ) -> np.ndarray:
        return _loglik(ch, drift, offset, reset, gaussian, floor)

    if kind == "stuck":
        reset = after_sample.astype(np.bool_)
        drift = base * (1.0 - after) - 0.0 * after
        return run(drift, zero_off, reset), np.full(g, np.nan)
    if kind in ("failure", "gain_loss"):
        lost = base - after * ch.templates["motor"]  # motor delivers nothing after the onset

        def at(theta: float | np.ndarray, gaussian: bool = False, floor: np.ndarray | None = None) -> np.ndarray:
            return run(lost + theta * after * ch.templates["motor"], zero_off, no_reset, gaussian, floor)

        if not quadratic:
            return at(0.0), np.full(g, np.nan)
        # the speed a gain loss takes off the wheel by sample k is (1 − g) Σ_{onset ≤ j < k} motor_j: a remaining gain
        # whose loss never reaches RESOLVED_COUNTS tachometer counts is not resolved (g = 0 if none reaches them)
        reach = np.abs(np.cumsum(after * ch.templates["motor"], axis=1)).max(axis=1)
        with np.errstate(divide="ignore"):
            resolved = np.clip(1.0 - RESOLVED_COUNTS * ch.bound / reach, 0.0, MAX_REMAINING_GAIN)
        return _profiled(ch, at, 0.0, MAX_REMAINING_GAIN, grid=GAIN_GRID, ceiling=resolved)
    if kind == "friction":

        def at(theta: float | np.ndarray, gaussian: bool = False, floor: np.ndarray | None = None) -> np.ndarray:
            return run(base + theta * after * ch.templates["friction"], zero_off, no_reset, gaussian, floor)

        # a friction that does not move the wheel by RESOLVED_COUNTS tachometer counts after its onset is not resolved
        per_nm = np.abs(after * ch.templates["friction"]).sum(axis=1)
        with np.errstate(divide="ignore"):
            resolvable = np.where(per_nm > 0.0, RESOLVED_COUNTS * ch.bound / per_nm, UNRESOLVED_FRICTION_NM)
        return _profiled(ch, at, 0.0, np.inf, scale=1e-3, min_abs=resolvable)

    def at_bias(theta: float | np.ndarray, gaussian: bool = False, floor: np.ndarray | None = None) -> np.ndarray:
        """A step ``theta`` in the measurement after the onset."""
        return run(base, theta * after_sample, no_reset, gaussian, floor)

    # a bias below RESOLVED_COUNTS of the sensor's resolution is not identifiable: rounding does as much
    return _profiled(
        ch,
        at_bias,
        -np.inf,
        np.inf,
        scale=max(ch.bound, math.sqrt(float(np.median(ch.r_var)))) * 10.0,
        min_abs=RESOLVED_COUNTS * ch.bound,
    )


def _loglik(
    ch: _Channel,
    drift: np.ndarray,
    offset: np.ndarray,
    reset: np.ndarray,
    gaussian: bool,
    floor: np.ndarray | None = None,
) -> np.ndarray:
    """Log-likelihood of the channel under each row's drift and offset: the tachometer's rounding taken exactly
    (:func:`sim_core.fault_detection.count_loglik`, rows below ``floor`` abandoned) for a quantised channel unless
    ``gaussian`` (rounding as white noise of variance q²/12, the quadratic model the magnitude search starts from)."""
    args = (np.ascontiguousarray(drift), ch.q_var)
    tail = (np.ascontiguousarray(offset), np.ascontiguousarray(reset))
    if ch.bound > 0.0 and not gaussian:
        return fd.count_loglik(ch.y, *args, ch.bound, (TACHOMETER_JITTER * ch.bound) ** 2, *tail, ch.drift, floor)
    return fd.level_loglik(ch.y, *args, ch.r_var, *tail)


def _profiled(
    ch: _Channel,
    at: Callable[..., np.ndarray],
    lo: float,
    hi: float,
    scale: float = 1.0,
    min_abs: float | np.ndarray = 0.0,
    grid: tuple[float, ...] = (),
    ceiling: float | np.ndarray = np.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Profile over the magnitude θ per onset: the Gaussian model's exact maximum (quadratic in θ); for a quantised
    channel the count likelihood is then maximised over that θ, θ·(1 ± MAGNITUDE_STEPS) and ``grid``, and the best
    of them refined by REFINEMENTS halvings of the step. θ ≤ ``ceiling`` (per onset) besides [lo, hi]. Each
    candidate's filtering stops where it falls below the best so far (``floor`` of
    :func:`sim_core.fault_detection.count_loglik`): the maximum is the same."""
    ll, theta = _quadratic_max(lambda th: at(th, True), lo, hi, scale, min_abs, ceiling)
    if ch.bound <= 0.0:
        return ll, theta
    upper = np.minimum(hi, ceiling)
    candidates = [theta] + [theta * (1.0 + f) for f in MAGNITUDE_STEPS] + [np.full_like(theta, v) for v in grid]
    thetas = np.stack([_clamped(c, lo, upper, min_abs) for c in candidates])
    lls = np.full(thetas.shape, -np.inf)
    cols = np.arange(theta.shape[0])
    for i, th in enumerate(thetas):
        # a candidate clamped onto an earlier one of its onset is that one (same rows, same likelihood): not filtered
        # again (an infinite floor abandons its row at once), its likelihood copied
        same = thetas[:i] == th
        again = same.any(axis=0)
        lls[i] = at(th[:, None], floor=np.where(again, np.inf, lls[:i].max(axis=0, initial=-np.inf)))
        if again.any():
            lls[i, again] = lls[np.argmax(same, axis=0)[again], cols[again]]
    best = np.argmax(lls, axis=0)
    ll, theta = lls[best, cols], thetas[best, cols]
    step = np.full_like(theta, np.diff(grid).min()) if len(grid) > 1 else np.abs(theta) * MAGNITUDE_STEPS[-1]
    for _ in range(REFINEMENTS):  # halve the step around the best candidate
        step = 0.5 * step
        for sign in (-1.0, 1.0):
            trial = _clamped(theta + sign * step, lo, upper, min_abs)
            same = trial == theta  # clamped back onto the best: no better, not filtered
            trial_ll = at(trial[:, None], floor=np.where(same, np.inf, ll))
            better = (trial_ll > ll) & ~same
            ll, theta = np.where(better, trial_ll, ll), np.where(better, trial, theta)
    return ll, theta


def _clamped(theta: np.ndarray, lo: float, hi: float | np.ndarray, min_abs: float | np.ndarray) -> np.ndarray:
    """θ within [lo, hi] and |θ| ≥ min_abs."""
    theta = np.clip(theta, lo, hi)
    out: npt.NDArray[np.float64] = np.where(np.abs(theta) < min_abs, np.where(theta < 0.0, -min_abs, min_abs), theta)
    return out


def _quadratic_max(
    at: Callable[[float], np.ndarray],
    lo: float,
    hi: float,
    scale: float = 1.0,
    min_abs: float | np.ndarray = 0.0,
    ceiling: float | np.ndarray = np.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact maximum of a log-likelihood quadratic in θ (affine model), θ clipped to [lo, min(hi, ceiling)] and
    |θ| ≥ min_abs."""
    if np.isfinite(hi) and np.isfinite(lo):
        p0, p1, p2 = lo, 0.5 * (lo + hi), hi
    else:
        p0, p1, p2 = 0.0, scale, -scale if not np.isfinite(lo) else 2.0 * scale
    f0, f1, f2 = at(p0), at(p1), at(p2)
    xs = np.array([p0, p1, p2])
    vand = np.vander(xs, 3)  # rows [θ², θ, 1]
    coef = np.linalg.solve(vand, np.stack([f0, f1, f2]))  # (3, G)
    a, b, c = coef
    with np.errstate(divide="ignore", invalid="ignore"):
        theta = np.where(a < 0.0, -b / (2.0 * a), np.where(b > 0.0, hi, lo))
    upper = np.minimum(hi, ceiling)
    theta = np.clip(theta, lo, upper)
    theta = _clamped(np.where(np.isfinite(theta), theta, p0), lo, upper, min_abs)
    ll = a * theta**2 + b * theta + c
    return ll, theta


def _fit(
    ch: _Channel,
    index: int,
    kind: str,
    onsets: np.ndarray,
    t_s: np.ndarray,
    nominal: float,
    n_params: int,
    others: dict[int, np.ndarray] | None = None,
    widths: np.ndarray | None = None,
) -> _Fit:
    """Onset-marginal, magnitude-penalised log evidence of one fault in one channel; the onset prior is uniform in
    time, sampled at SUB_SAMPLE fractions of the interval for faults whose effect is an integrated torque (``widths``:
    the samples each onset stands for on an uneven grid, :func:`_step_onsets`)."""
    quadratic = kind not in ("failure", "stuck")
    sub = SUB_SAMPLE if kind in ("failure", "gain_loss", "friction") and np.all(np.diff(onsets) == 1) else 1
    fractions = np.arange(sub) / sub  # a strided onset grid (no alarm) has no use for fractions of an interval
    lead = t_s[onsets] - t_s[np.maximum(onsets - 1, 0)]
    runs = [_profile(ch, onsets, kind, quadratic, float(phi)) for phi in fractions]
    ll = np.concatenate([r[0] for r in runs])
    theta = np.concatenate([r[1] for r in runs])
    others = others or {}
    for extra in others.values():  # the other channels' evidence under this hypothesis, per onset
        ll = ll + np.tile(extra, len(fractions))
    times = np.concatenate([t_s[onsets] - phi * lead for phi in fractions])
    cells = None if widths is None else np.tile(widths, len(fractions))
    onset, sigma, best = _onset_stats(times, ll, cells)
    k = best % onsets.shape[0]
    penalty = 0.5 * n_params * math.log(max(ch.y.shape[0] - int(onsets[k]), 2))
    magnitude = None if np.isnan(theta[best]) else float(theta[best])
    credit = {q: float(extra[k]) for q, extra in others.items()}
    sigma = max(sigma, _one_count_s(ch, int(onsets[k]), kind, magnitude, t_s) / math.sqrt(12.0))
    order = np.argsort(times, kind="stable")
    profile = (times[order], ll[order])
    return _Fit(kind, index, _log_mean_exp(ll, cells) - nominal - penalty, onset, sigma, magnitude, credit, profile)


def _one_count_s(ch: _Channel, k: int, kind: str, magnitude: float | None, t_s: np.ndarray) -> float:
    """Time the fault needs from onset index ``k`` to move the wheel by one tachometer count: the rounded readings
    are the same for any onset within it, so the onset is uniform over it whatever the Gaussian profile says (its
    white rounding noise is sure of an onset the rounding cannot place); the replay's onset grid spans it."""
    if kind in ("failure", "gain_loss"):
        effect = np.abs(ch.templates["motor"][k:]) * (1.0 - (magnitude or 0.0))
    elif kind == "friction":
        effect = np.abs(ch.templates["friction"][k:]) * abs(magnitude or 0.0)
    else:
        return 0.0
    reached = np.flatnonzero(np.cumsum(effect) >= ch.bound)
    end = k + (int(reached[0]) + 1 if reached.size else effect.shape[0])
    return float(t_s[min(end, t_s.shape[0] - 1)] - t_s[k])


def _kick_evidence(ch: _Channel, onsets: np.ndarray) -> np.ndarray:
    """Log evidence (G,) of a healthy wheel's balance, relative to its nominal model, when another rotor seizes
    between samples o−1 and o (per onset o): the seizure dumps the rotor's momentum into the body in one step,
    and the coupling term J_r aᵗΔω of that interval, taken from estimated rates that do not follow a step, is
    then known only to its own size. A level step δ ~ N(0, s²) at that interval, s = |coupling| of the
    interval and the next, is marginalised exactly (the log-likelihood is quadratic in δ)."""
    n = ch.y.shape[0]
    kick = (np.arange(n - 1)[None, :] == (onsets[:, None] - 1)).astype(float)
    coupling = np.abs(np.concatenate([ch.templates["coupling"], [0.0]]))
    s2 = (coupling[np.maximum(onsets - 1, 0)] + coupling[onsets]) ** 2
    h = ch.bound if ch.bound > 0.0 else 1.0
    zero_off = np.zeros((onsets.shape[0], n))
    no_reset = np.zeros((onsets.shape[0], n), dtype=np.bool_)

    def at(delta: float) -> np.ndarray:
        drift = np.ascontiguousarray(ch.drift[None, :] + delta * kick)
        return fd.level_loglik(ch.y, drift, ch.q_var, ch.r_var, zero_off, no_reset)

    f0, fp, fm = at(0.0), at(h), at(-h)
    a = np.minimum((fp + fm - 2.0 * f0) / (2.0 * h * h), 0.0)
    b = (fp - fm) / (2.0 * h)
    spread = 1.0 - 2.0 * a * s2
    loglik: npt.NDArray[np.float64] = b * b * s2 / (2.0 * spread) - 0.5 * np.log(spread)
    return loglik


def _window(alarm: fd.Alarm | None, later: list[int], n: int, dt: float) -> tuple[int, int, int]:
    """Analysis window [start, stop) and the first onset index searched: from before the first alarm to
    POST_ALARM_S after the last alarm (any channel, or an FDIR isolation) within SECOND_FAULT_S of the first,
    so that a second fault soon after the first is in the window its pair hypotheses are fitted on."""
    if alarm is None:
        return 0, n, 1
    first = max(1, alarm.index - alarm.window - int(ONSET_SEARCH_S / dt))
    last = max([k for k in later if k <= alarm.index + SECOND_FAULT_S / dt], default=alarm.index)
    return max(0, first - int(NOMINAL_LEAD_S / dt)), min(n, max(alarm.index, last) + int(POST_ALARM_S / dt) + 1), first


def _cut(ch: _Channel, a: int, b: int) -> _Channel:
    """The channel restricted to samples [a, b)."""
    return _Channel(
        ch.name,
        ch.y[a:b],
        ch.drift[a : b - 1],
        ch.q_var[a : b - 1],
        ch.r_var[a:b],
        ch.bound,
        {k: v[a : b - 1] for k, v in ch.templates.items()},
        None if ch.relative is None else ch.relative[a : b - 1],
    )


def _nominal(ch: _Channel) -> float:
    n = ch.y.shape[0]
    return float(_loglik(ch, ch.drift[None, :], np.zeros((1, n)), np.zeros((1, n), dtype=np.bool_), False)[0])


def _suspected(ch: _Channel) -> bool:
    """Cheap pruning: does the open-loop balance leave PRUNE_SIGMA of quantisation + noise anywhere in the window?"""
    r = fd.open_loop_residual(ch.y, ch.drift)[None, :]
    dt = 1.0
    rel = None if ch.relative is None else ch.relative[None, :]
    return (
        fd.window_alarm(
            r,
            ch.q_var[None, :],
            ch.r_var[None, :],
            ch.bound,
            dt,
            n_sigma=PRUNE_SIGMA,
            windows_s=tuple(float(w) for w in (1, 3, 10, 30, 100, 300)),
            relative=rel,
        )
        is not None
    )


def diagnose(
    obs: Observations,
    wm: WheelModel,
    scenario: Scenario | None = None,
    sigma_torque_nm: float = UNMODELLED_TORQUE_NM,
    flyer: Callable[[Scenario], object] | None = None,
) -> Diagnosis:
    """Detect, prune, fit and rank the fault hypotheses of the spacecraft on ``obs`` (module docstring);
    with ``scenario``, the top wheel hypotheses are replayed in the twin (``flyer``: how a batch is flown)."""
    if wm.axes_b.shape[1] != obs.n_wheels:
        raise ValueError(
            f"telemetry: {obs.n_wheels} wheels telemetered, the scenario's spacecraft has "
            f"{wm.axes_b.shape[1]} (telemetry from another spacecraft?)"
        )
    t = obs.t_s
    dt = float(np.median(np.diff(t)))
    wheels = _wheel_channels(obs, wm, sigma_torque_nm)
    sensors = {"gyro_bias": _gyro_channels(obs)}
    untestable: dict[str, str] = {}
    if obs.b_mag_b_t is not None and obs.b_model_b_t is not None:
        sensors["magnetometer_bias"] = _magnetometer_channels(obs)
    else:
        untestable["magnetometer_bias"] = (
            "no magnetometer field (b_mag_b_t_*) or GPS position (r_ecef_m_*) for the field model in the telemetry"
        )
    valid = _star_tracker_valid(obs.q_st_ib) if obs.q_st_ib is not None else None
    if valid is None:
        untestable["star_tracker_outage"] = "no star-tracker quaternion (q_st_ib_*) in the telemetry"

    # detection over the whole record: continuous channels by window tests, star tracker by invalid runs
    channels = wheels + [c for group in sensors.values() for c in group]
    alarms = _alarms(channels, dt)
    alarm = min(alarms, key=lambda a: a.index, default=None)
    st_alarm = _star_tracker_alarm(valid)
    if st_alarm is not None and (alarm is None or st_alarm < alarm.index):
        alarm = fd.Alarm(-1, st_alarm, 1, float("inf"))
    isolated = _isolations(obs)
    if isolated and (alarm is None or min(isolated.values()) < alarm.index):
        alarm = fd.Alarm(-2, min(isolated.values()), int(ONSET_MARGIN_S / dt), float("inf"))
    later = [a.index for a in alarms] + list(isolated.values())
    start, stop, first = _window(alarm, later, t.shape[0], dt)
    stride = 1 if alarm is not None else max(1, (stop - start) // 200)
    onsets = np.arange(first - start, stop - start - 1, stride)
    tw = t[start:stop]

    fits: list[_Fit] = []
    suspected = []
    cuts = [_cut(ch, start, stop) for ch in wheels]
    nominals = [_nominal(c) for c in cuts]
    kicks: dict[int, np.ndarray] = {}
    for p, cut in enumerate(cuts):
        if _suspected(cut) or (p in isolated and isolated[p] < stop):
            suspected.append(p + 1)
    # a fault too small to alarm is still a hypothesis: with nothing alarming, every wheel is fitted (the count
    # likelihood says how far the data tell it from "none"), on records short enough to search at that cost
    unalarmed = alarm is None and not suspected and t.shape[0] <= UNALARMED_FIT_SAMPLES
    for p, cut in enumerate(cuts):
        if not (unalarmed or p + 1 in suspected):
            continue
        for kind in WHEEL_FAULTS:
            others = None
            if kind == "stuck":
                for q in range(len(cuts)):
                    if q != p and q not in kicks:
                        kicks[q] = _kick_evidence(cuts[q], onsets)
                others = {q: kicks[q] for q in range(len(cuts)) if q != p}
            grid, widths = _step_onsets(onsets, [cut]) if kind == "speed_bias" else (onsets, None)
            n_params = 0 if kind in ("failure", "stuck") else 1
            fits.append(_fit(cut, p, kind, grid, tw, nominals[p], n_params, others, widths))
    sensor_fits = [_sensor_fit(kind, group, start, stop, onsets, tw) for kind, group in sensors.items()]
    if valid is not None:
        sensor_fits.append(_outage_fit(valid[start:stop], onsets, tw))
    flagged = {p: float(t[k]) for p, k in isolated.items() if k < stop}
    hyps = _rank(fits, [f for f in sensor_fits if f is not None], flagged, obs.n_wheels)
    if scenario is not None and (alarm is not None or hyps[0].wheel is not None):  # a fault below the alarm too
        hyps = _replayed(hyps, obs, scenario, start, stop, stop - 1 if alarm is None else alarm.index, flyer)
    name = None
    if alarm is not None:
        name = {-1: "star tracker", -2: "onboard FDIR isolation"}.get(alarm.channel) or channels[alarm.channel].name
    return Diagnosis(
        hypotheses=hyps,
        detected=alarm is not None,
        alarm_s=None if alarm is None else float(t[alarm.index]),
        alarm_channel=name,
        false_alarms_per_day=detection_rate_per_day(len(channels), dt),
        window_s=(float(t[start]), float(t[stop - 1])),
        suspected_wheels=suspected,
        untestable=untestable,
    )


def _isolations(obs: Observations) -> dict[int, int]:
    """Wheel index → first sample where the onboard FDIR flags it isolated (telemetered flags)."""
    if obs.wheel_isolated is None:
        return {}
    flags = np.nan_to_num(obs.wheel_isolated) > 0.5
    return {p: int(np.argmax(flags[:, p])) for p in range(flags.shape[1]) if flags[:, p].any()}


def _alarms(channels: list[_Channel], dt: float) -> list[fd.Alarm]:
    """The first window-test alarm of every continuous channel that alarms."""
    out = []
    for i, ch in enumerate(channels):
        r = fd.open_loop_residual(ch.y, ch.drift)[None, :]
        rel = None if ch.relative is None else ch.relative[None, :]
        a = fd.window_alarm(r, ch.q_var[None, :], ch.r_var[None, :], ch.bound, dt, relative=rel)
        if a is not None:
            out.append(fd.Alarm(i, a.index, a.window, a.ratio))
    return out


STAR_OUTAGE_RUN = 5  # consecutive invalid samples: P = (1e-4)^5 per sample for a healthy tracker


def _star_tracker_alarm(valid: np.ndarray | None) -> int | None:
    """Index completing the first run of STAR_OUTAGE_RUN invalid star-tracker samples."""
    if valid is None:
        return None
    bad = (~valid).astype(int)
    run = np.convolve(bad, np.ones(STAR_OUTAGE_RUN, dtype=int), mode="valid")
    hits = np.flatnonzero(run == STAR_OUTAGE_RUN)
    return int(hits[0] + STAR_OUTAGE_RUN - 1) if hits.size else None


def _sensor_fit(
    kind: str, group: list[_Channel], start: int, stop: int, onsets: np.ndarray, tw: np.ndarray
) -> _Fit | None:
    """A bias step common in onset to the three axes of a sensor: sum of per-axis profiles (onsets from
    :func:`_step_onsets`)."""
    cuts = [_cut(ch, start, min(stop, ch.y.shape[0])) for ch in group]
    onsets, widths = _step_onsets(onsets, cuts)
    total = None
    thetas = []
    nominal = 0.0
    for cut in cuts:
        if cut.y.shape[0] < 3:
            return None
        grid = onsets[onsets < cut.y.shape[0] - 1]
        ll, theta = _profile(cut, grid, "bias", True)
        nominal += _nominal(cut)
        total = ll if total is None else total[: ll.shape[0]] + ll[: total.shape[0]]
        thetas.append(theta)
    assert total is not None
    cells = None if widths is None else widths[: total.shape[0]]
    onset, sigma, best = _onset_stats(tw[onsets[: total.shape[0]]], total, cells)
    penalty = 0.5 * 3 * math.log(max(len(tw) - int(onsets[best]), 2))
    magnitude = float(np.linalg.norm([th[best] for th in thetas]))
    return _Fit(kind, -1, _log_mean_exp(total, cells) - nominal - penalty, onset, sigma, magnitude)


def _step_onsets(onsets: np.ndarray, channels: list[_Channel]) -> tuple[np.ndarray, np.ndarray | None]:
    """A strided onset grid (nothing alarms) with the samples around each channel's STEP_CANDIDATES largest jumps
    |Δy − drift| added, and the samples each onset stands for (the onset prior stays uniform in time): a step fault
    (a sensor bias) between two grid points fits neither, and its own jump places it. An unstrided grid is returned
    as it is (widths None: each onset stands for one sample)."""
    stride = int(onsets[1] - onsets[0]) if onsets.shape[0] > 1 else 1
    if stride == 1:
        return onsets, None
    extra = []
    for ch in channels:
        jump = np.nan_to_num(np.abs(np.diff(ch.y) - ch.drift))
        for k in np.argsort(jump)[-STEP_CANDIDATES:]:
            extra += [k, k + 1, k + 2]  # a step between samples k and k + 1 starts at sample k + 1; ±1 sample
    grid = np.unique(np.concatenate([onsets, extra]))
    last = min([onsets[-1] + stride - 1] + [ch.y.shape[0] - 2 for ch in channels])  # an onset needs a sample after it
    grid = grid[(grid >= onsets[0]) & (grid <= last)]
    edges = np.concatenate([[grid[0] - 0.5 * stride], 0.5 * (grid[1:] + grid[:-1]), [grid[-1] + 0.5 * stride]])
    return grid, np.diff(edges)


def _outage_fit(valid: np.ndarray, onsets: np.ndarray, tw: np.ndarray) -> _Fit:
    """Bernoulli change point: invalid samples rare before the onset, the rule after it."""
    eps = INVALID_PROBABILITY
    bad = ~valid
    ok_ll = np.where(bad, math.log(eps), math.log1p(-eps))
    out_ll = np.where(bad, math.log1p(-eps), math.log(eps))
    nominal = float(ok_ll.sum())
    head = np.concatenate([[0.0], np.cumsum(ok_ll)])
    tail = np.concatenate([np.cumsum(out_ll[::-1])[::-1], [0.0]])
    ll = head[onsets] + tail[onsets]
    onset, sigma, _ = _onset_stats(tw[onsets], ll)
    return _Fit("star_tracker_outage", -1, _log_mean_exp(ll) - nominal, onset, sigma, None)


def _replayed(
    hyps: list[Hypothesis],
    obs: Observations,
    scenario: Scenario,
    start: int,
    stop: int,
    alarm: int,
    flyer: Callable[[Scenario], object] | None,
) -> list[Hypothesis]:
    """Add the twin replay's evidence (commands and attitude) to the top wheel hypotheses and re-rank
    (:mod:`sim_core.twin_replay`).

    Each hypothesis flies at onsets spanning its own balance posterior (a coarse grid, then a fine one around
    its best joint onset). The balance's onset posterior is the replay's onset prior: the evidence added is
    ln E[exp(replay log-likelihood)] under it, and the onset reported is the maximum of the two together (the
    replay alone may prefer an onset the tachometer counts rule out: a twin that drifts from the spacecraft
    favours the onset whose fault best hides its drift)."""
    from sim_core.twin_replay import fault_specs  # the engine's kernels: loaded by a replay, not by an import

    t = obs.t_s
    chosen = [h for h in hyps if h.onset_s is not None and fault_specs(h.fault, h.wheel, 0.0, h.magnitude)][:REPLAYED]
    if not chosen:
        return hyps
    lo, hi = float(t[start + 1]), float(t[min(alarm, stop - 2)])  # the fault began before it was detected
    grids = np.stack([_onset_grid(h, lo, hi) for h in chosen])
    try:
        ll = _replay_grid(chosen, grids, obs, scenario, start, stop, flyer)
    except ValueError:  # the twin cannot restart there (inside a scheduled turn): the balance's ranking stands
        return hyps
    priors = [_onset_prior(h, grid, lo, hi) for h, grid in zip(chosen, grids)]
    fines = []
    for (times, log_w), grid, row in zip(priors, grids, ll):
        best = float(times[int(np.argmax(log_w + np.interp(times, grid, row)))])
        step = max(float(np.diff(grid).max(initial=0.0)), 1.0)
        fines.append(np.clip(best + np.linspace(-step, step, REPLAY_ONSETS), lo, hi))
    try:
        ll_fine = _replay_grid(chosen, np.stack(fines), obs, scenario, start, stop, flyer)
    except ValueError:  # the twin cannot restart before the fine grid (a scheduled turn): the coarse grid alone
        fines, ll_fine = [grid[:0] for grid in grids], ll[:, :0]
    evidence, onsets = [], []
    for i, (times, log_w) in enumerate(priors):
        taus = np.concatenate([grids[i], fines[i]])
        order = np.argsort(taus, kind="stable")
        joint = log_w + np.interp(times, taus[order], np.concatenate([ll[i], ll_fine[i]])[order])
        evidence.append(_log_sum_exp(joint))
        onset, sigma, _ = _onset_stats(times, joint)
        sigma = max(sigma, float(np.diff(fines[i]).min(initial=1.0)))
        if np.ptp(joint - log_w) < 1.0:  # the replay hardly tells the onsets apart: the balance's uncertainty stands
            sigma = max(sigma, chosen[i].onset_sigma_s or 0.0)
        onsets.append((onset, sigma))
    # the replay ranks the hypotheses it flies among themselves: the twin's own mismatch (inertia, alignments)
    # weighs on every variant, so its evidence against hypotheses it did not fly would not be fair
    top = max(evidence)
    updated = {
        id(h): replace(h, onset_s=onset, onset_sigma_s=sigma, log_evidence=h.log_evidence + ev - top)
        for h, ev, (onset, sigma) in zip(chosen, evidence, onsets)
    }
    return _scored([updated.get(id(h), h) for h in hyps])


def _onset_grid(h: Hypothesis, lo: float, hi: float) -> np.ndarray:
    """REPLAY_ONSETS onsets over the hypothesis's onset ± (3σ + 20 s), at least ± 30 s, at most ± 300 s."""
    assert h.onset_s is not None  # the replay flies hypotheses with an onset
    half = float(np.clip(3.0 * (h.onset_sigma_s or 0.0) + 20.0, 30.0, 300.0))
    grid: npt.NDArray[np.float64] = np.clip(h.onset_s + np.linspace(-half, half, REPLAY_ONSETS), lo, hi)
    return grid


def _onset_prior(h: Hypothesis, grid: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Onset times and normalised log weights the replay's likelihood is averaged over: the balance's onset
    posterior within [lo, hi] (the replay flies no onset after the alarm), else uniform over the grid."""
    if h.onset_profile is not None:
        times, ll = h.onset_profile
        inside = (times >= lo) & (times <= hi)
        if inside.any():
            return times[inside], ll[inside] - _log_sum_exp(ll[inside])
    return grid, np.full(grid.shape[0], -math.log(grid.shape[0]))


def _log_sum_exp(x: np.ndarray) -> float:
    return _log_mean_exp(x) + math.log(x.shape[0])


def _replay_grid(
    chosen: list[Hypothesis],
    grids: np.ndarray,
    obs: Observations,
    scenario: Scenario,
    start: int,
    stop: int,
    flyer: Callable[[Scenario], object] | None,
) -> np.ndarray:
    """Replay log-likelihood (hypotheses × onsets) relative to the no-fault variant, hypothesis i flown at the
    onsets grids[i]."""
    from sim_core.twin_replay import fault_specs, replay_scores

    t = obs.t_s
    scenario, first, reference = _replay_rows(obs, scenario, float(grids.min()), start, stop)
    candidates: list[list[FaultSpec]] = []
    for h, grid in zip(chosen, grids):
        for tau in grid:
            specs = fault_specs(h.fault, h.wheel, float(tau - t[first]), h.magnitude)
            if specs is None:  # _replayed chooses flyable hypotheses only
                raise ValueError(f"{h.fault}: not a flyable wheel hypothesis")
            candidates.append(specs)
    batch = _replay_batch(obs, scenario, candidates, first, stop, reference)
    ll = replay_scores(
        batch, t, obs.q_est_ib, obs.wheel_torque_cmd_nm, first, stop, reference, obs.torque_quantum_nm, flyer
    )
    relative: npt.NDArray[np.float64] = (ll[:-1] - ll[-1]).reshape(grids.shape)
    return relative


def _replay_rows(
    obs: Observations, scenario: Scenario, onset_s: float, start: int, stop: int
) -> tuple[Scenario, int, int]:
    """(scenario, first row, reference row) of a replay whose earliest onset is ``onset_s``: the twin starts
    REPLAY_LEAD_S before it (not before row ``start``), its mismatch is measured up to the onset, and it flies the
    onboard FDIR if the scenario does or the telemetry shows an isolation in [start, stop)."""
    t = obs.t_s
    fdir = scenario.fdir or (obs.wheel_isolated is not None and bool(np.any(obs.wheel_isolated[start:stop] > 0)))
    first = max(int(np.searchsorted(t, onset_s - REPLAY_LEAD_S)), start)
    reference = max(int(np.searchsorted(t, onset_s)), first + 2)
    return scenario.model_copy(update={"fdir": fdir}), first, reference


def _replay_batch(
    obs: Observations, scenario: Scenario, candidates: list[list[FaultSpec]], first: int, stop: int, reference: int
) -> Scenario:
    """The replay's batch (:func:`sim_core.twin_replay.replay_batch`) on the telemetered observations."""
    from sim_core.twin_replay import replay_batch

    return replay_batch(
        scenario,
        obs.t_s,
        obs.epoch_unix_s,
        obs.q_est_ib,
        obs.omega_b_rad_s,
        obs.wheel_speed_rad_s,
        obs.wheel_torque_cmd_nm,
        candidates,
        first,
        stop,
        reference,
        obs.q_prog_ib,
    )


def hypothesis_replay(
    obs: Observations,
    scenario: Scenario,
    fault: str,
    wheel: int | list[int] | None,
    onset_s: float | None,
    magnitude: float | list[float | None] | None,
    after_s: float = FLIGHT_AFTER_S,
) -> tuple[Scenario, int, int]:
    """The batch flying one diagnosed hypothesis (variant ``h0``) beside the no-fault twin (``none``), built as the
    diagnosis' replay builds it (:func:`_replay_rows`, :func:`sim_core.twin_replay.replay_batch`): from telemetry
    REPLAY_LEAD_S before the onset to ``after_s`` after it (or the telemetry's end); (batch, first row, stop row).

    Every fault of the fault space flies, as the engine faults :func:`hypothesis_faults` maps it to (wheel faults as
    the ranking's replay flies them; tachometer, gyro, magnetometer and star-tracker faults besides).
    ValueError naming what cannot be flown: "none", an unknown fault, an onset outside the telemetry."""
    if fault == "none":
        raise ValueError("hypothesis: 'none' is the nominal twin itself; fly a fault hypothesis")
    t = obs.t_s
    if onset_s is None or not t[0] <= onset_s <= t[-1]:
        raise ValueError(f"hypothesis: {fault} has no onset inside the telemetry ({onset_s})")
    stop = min(int(np.searchsorted(t, onset_s + after_s, side="right")), t.shape[0])
    scenario, first, reference = _replay_rows(obs, scenario, onset_s, 0, stop)
    if stop - first < 3:
        raise ValueError(f"hypothesis: the telemetry ends at the onset of {fault}; nothing to fly")
    specs = hypothesis_faults(obs, fault, wheel, onset_s, magnitude, first, stop)
    batch = _replay_batch(obs, scenario, [specs], first, stop, reference)
    return batch, first, stop


def hypothesis_faults(
    obs: Observations,
    fault: str,
    wheel: int | list[int] | None,
    onset_s: float,
    magnitude: float | list[float | None] | None,
    first: int,
    stop: int,
) -> list[FaultSpec]:
    """The engine faults (:mod:`sim_core.faults`) a diagnosed hypothesis flies as on the simulated monitor, onset
    ``onset_s`` after the telemetry epoch, for a twin started at row ``first`` and flown to row ``stop - 1``.

    - ``failure``, ``gain_loss``, ``friction``, ``stuck``: :func:`sim_core.twin_replay.fault_specs`, the faults the
      ranking's replay scores them with (that map is not changed: it would change the scores);
    - ``speed_bias``: a tachometer bias of that wheel, ``magnitude`` rad/s added to its readings (the diagnosis
      estimates it as a step of the tachometer channel, in rad/s, signed);
    - ``gyro_bias``, ``magnetometer_bias``: a bias per body axis, rad/s or T. The diagnosis reports the bias' norm
      only (``magnitude``); its direction is its own per-axis estimate (:func:`_sensor_bias_b`: the same channels
      and step model, at the reported onset, on the flown rows [first, stop)), scaled to that norm;
    - ``star_tracker_outage``: the star tracker failed (no valid sample) from the onset on;
    - pairs (``a+b``, ``wheel`` and ``magnitude`` lists): both members' faults, at the pair's one onset.

    ValueError for a fault outside the fault space, or a sensor bias the telemetry has no channel for."""
    from sim_core.twin_replay import FAULT_TYPES, fault_specs

    at = max(float(onset_s - obs.t_s[first]), 0.0)
    names = fault.split("+")
    wheels = wheel if isinstance(wheel, list) else [wheel] * len(names)
    mags = magnitude if isinstance(magnitude, list) else [magnitude] * len(names)
    out: list[FaultSpec] = []
    for name, w, m in zip(names, wheels, mags):
        if name in FAULT_TYPES and w is not None:
            specs = fault_specs(name, w, at, m)
            assert specs is not None  # a wheel fault with its wheel: always flyable
            out += specs
        elif name == "speed_bias" and w is not None:
            out.append(FaultSpec(target="tachometer", index=int(w) - 1, type="bias", onset_s=at, value=float(m or 0.0)))
        elif name in SENSOR_BIAS_TARGETS:
            bias = _sensor_bias_b(obs, name, onset_s, first, stop)
            norm = float(np.linalg.norm(bias))
            if m is not None and norm > 0.0:
                bias = bias * (float(m) / norm)
            target = SENSOR_BIAS_TARGETS[name]
            out += [FaultSpec(target=target, index=a, type="bias", onset_s=at, value=float(bias[a])) for a in range(3)]
        elif name == "star_tracker_outage":
            out.append(FaultSpec(target="star_tracker", type="failure", onset_s=at))
        else:
            raise ValueError(
                f"hypothesis: {fault} cannot be flown: {name!r} is not a fault of the diagnosis' fault space "
                f"({', '.join(WHEEL_FAULTS + SENSOR_FAULTS)}, with a wheel for a wheel fault)"
            )
    return out


def _sensor_bias_b(obs: Observations, kind: str, onset_s: float, first: int, stop: int) -> np.ndarray:
    """Per-axis bias step (3,) of a gyro or magnetometer at ``onset_s``: the diagnosis' own estimate (the
    channels of :func:`_gyro_channels` / :func:`_magnetometer_channels`, the step model of :func:`_profile`, its
    Gaussian maximum) on rows [first, stop)."""
    if kind == "magnetometer_bias":
        if obs.b_mag_b_t is None or obs.b_model_b_t is None:
            raise ValueError("hypothesis: magnetometer_bias cannot be flown: no magnetometer field in the telemetry")
        group = _magnetometer_channels(obs)
    else:
        group = _gyro_channels(obs)
    k = int(np.searchsorted(obs.t_s, onset_s - 1e-3)) - first  # the onset's sample (onsets are sample instants)
    bias = np.zeros(3)
    for axis, ch in enumerate(group):
        cut = _cut(ch, first, min(stop, ch.y.shape[0]))
        if not 0 < k < cut.y.shape[0] - 1:
            raise ValueError(f"hypothesis: {kind} has no samples on both sides of its onset to estimate it from")
        _, theta = _profile(cut, np.array([k]), "bias", True)
        bias[axis] = float(theta[0])
    return bias


def tachometer_readings(batch: Scenario, t_s: np.ndarray, wheel_speed_rad_s: np.ndarray) -> np.ndarray:
    """Wheel speeds (variant, sample, wheel) of a flown ``batch`` as each variant's tachometers read them: the
    rotors' under that variant's tachometer faults (:func:`sim_core.faults.tachometer_faults_1`, the loop's and the
    emulator's kernel); the rotors' themselves for a variant without one."""
    from sim_core import faults

    table, counts = faults.fault_table(batch.variants)
    out = np.array(wheel_speed_rad_s, dtype=float, order="C")
    for v in range(out.shape[0]):
        rows = np.ascontiguousarray(table[v, : counts[v]])
        if not np.any(rows[:, faults.F_TARGET] == faults.T_TACH):
            continue
        for k in range(t_s.shape[0]):
            faults.tachometer_faults_1(rows, float(t_s[k]), out[v, k])
    return out


def flight_sensor_residuals(
    obs: Observations, batch: Scenario, t_s: np.ndarray, series: dict[str, np.ndarray], first: int, onset_s: float
) -> list[dict[str, float]]:
    """What each variant's onboard estimator and sensors would have telemetered against the telemetry, over a flight
    of ``batch`` (:func:`hypothesis_replay`: started at row ``first``; ``t_s`` and ``series`` its trajectory's): RMS of
    the twin's value minus the telemetered one at the twin's output instants, less their mean difference before
    ``onset_s`` (the twin's own mismatch: a gyro bias or a field model the twin's scenario does not know, which no
    hypothesis claims to explain):

    - ``attitude_estimate_rms_arcsec``, ``rate_estimate_rms_deg_h``: the twin's onboard estimate (``q_est_ib``,
      ``omega_est_b_rad_s``) against the telemetered one (the what-if's residuals hold the twin's true attitude
      against it, which a sensor fault separates from its estimate);
    - ``gyro_rms_deg_h``: the twin's body rate + the scenario's gyro bias, under the variant's gyro faults;
    - ``magnetometer_rms_nt``: the field model at the telemetered GPS position (the diagnosis' ``b_model_b_t``)
      turned from the telemetered attitude into the twin's, under the variant's magnetometer faults;
    - ``star_tracker_mismatch``: the share of instants where the twin's star tracker has a valid sample and the
      telemetry's not, or the other way round (no offset to remove).

    A sensor fault the twin flies shows there; the flight's wheel speeds are its tachometers'
    (:func:`tachometer_readings`), so a speed bias shows in the wheel-speed residuals."""
    from sim_core import faults, quaternion

    tm = obs.t_s[first] + t_s
    k = np.clip(np.searchsorted(obs.t_s, tm - 1e-3), 0, obs.t_s.shape[0] - 1)
    same = np.abs(obs.t_s[k] - tm) <= 1e-3
    k, tw = k[same], np.ascontiguousarray(t_s[same])
    before = obs.t_s[k] < onset_s
    table, counts = faults.fault_table(batch.variants)
    bias0 = np.asarray(batch.sensors.gyro_bias_rad_s, dtype=float)

    def rms(diff: np.ndarray) -> float:
        ok = np.all(np.isfinite(diff), axis=1)
        if not ok.any():
            return float("nan")
        offset = np.mean(diff[ok & before], axis=0) if np.any(ok & before) else 0.0
        return float(np.sqrt(np.mean(np.sum((diff[ok] - offset) ** 2, axis=1))))

    out = []
    for v in range(len(batch.variants)):
        rows = np.ascontiguousarray(table[v, : counts[v]])
        zeros = np.zeros((tw.shape[0], 3))
        turn = quaternion.multiply(quaternion.conjugate(obs.q_est_ib[k]), series["q_est_ib"][v][same])
        attitude = 2.0 * np.sign(turn[:, :1] + 1e-300) * turn[:, 1:]  # small-angle rotation vector, rad
        rate = series["omega_est_b_rad_s"][v][same] - obs.omega_b_rad_s[k]
        found: dict[str, float] = {
            "attitude_estimate_rms_arcsec": math.degrees(rms(attitude)) * 3600.0,
            "rate_estimate_rms_deg_h": math.degrees(rms(rate)) * 3600.0,
        }
        if obs.omega_gyro_b_rad_s is not None:
            rate = np.ascontiguousarray(series["omega_b_rad_s"][v][same] + bias0)
            gyro, _ = faults.sensor_fault_series(rows, faults.T_GYRO, tw, rate, zeros)
            found["gyro_rms_deg_h"] = math.degrees(rms(gyro - obs.omega_gyro_b_rad_s[k])) * 3600.0
        if obs.b_mag_b_t is not None and obs.b_model_b_t is not None:
            b_i = quaternion.rotate(obs.q_est_ib[k], obs.b_model_b_t[k])
            b_twin = quaternion.rotate(quaternion.conjugate(series["q_ib"][v][same]), b_i)
            mag, _ = faults.sensor_fault_series(rows, faults.T_MAG, tw, np.ascontiguousarray(b_twin), zeros)
            found["magnetometer_rms_nt"] = rms(mag - obs.b_mag_b_t[k]) * 1e9
        if obs.q_st_ib is not None:
            q = np.ascontiguousarray(series["q_ib"][v][same])
            _, failed = faults.star_tracker_fault_series(rows, tw, q, zeros)
            found["star_tracker_mismatch"] = float(np.mean(failed == _star_tracker_valid(obs.q_st_ib)[k]))
        out.append(found)
    return out


def _scored(hyps: list[Hypothesis]) -> list[Hypothesis]:
    """Posterior probabilities (equal priors) from the log evidences, best first."""
    ev = np.array([h.log_evidence for h in hyps])
    post = np.exp(ev - ev.max())
    post /= post.sum()
    return sorted(
        (replace(h, score=float(s)) for h, s in zip(hyps, post)),
        key=lambda h: -h.log_evidence,
    )


def _rank(
    wheel_fits: list[_Fit], sensor_fits: list[_Fit], flagged: dict[int, float] | None = None, n_wheels: int = 4
) -> list[Hypothesis]:
    """Singles, pairs of wheel faults on different wheels (prior odds PAIR_PRIOR_LOG_ODDS), sensors and "none",
    scored by posterior probability. Prior: "none" as likely as some single fault of the fault space, which its
    n_wheels × WHEEL_FAULTS + SENSOR_FAULTS faults share equally (a fault the data cannot show leaves "none" on
    top, at a score that says how little the data rule the faults out). Each wheel the onboard FDIR isolated
    (``flagged``: wheel index → time) that a hypothesis leaves healthy costs FDIR_MISS_LOG_ODDS, unless the
    hypothesis seizes a rotor before that isolation: a seizure's kick (the rotor's momentum dumped into the body
    in one step) is outside the FDIR's body-rate prediction, so the isolations after it say nothing about the
    other wheels."""
    flagged = flagged or {}

    def unexplained(*fits: _Fit) -> float:
        kicks = [f.onset_s for f in fits if f.fault == "stuck"]
        healthy = [t for p, t in flagged.items() if p not in {f.channel for f in fits}]
        return -FDIR_MISS_LOG_ODDS * sum(not any(k <= t for k in kicks) for t in healthy)

    none_prior = math.log(n_wheels * len(WHEEL_FAULTS) + len(SENSOR_FAULTS))
    hyps = [Hypothesis("none", None, None, None, None, unexplained() + none_prior)]
    for f in wheel_fits:
        hyps.append(
            Hypothesis(
                f.fault,
                f.channel + 1,
                f.onset_s,
                f.onset_sigma_s,
                f.magnitude,
                f.delta + unexplained(f),
                onset_profile=f.profile,
            )
        )
    for f in sensor_fits:
        hyps.append(Hypothesis(f.fault, None, f.onset_s, f.onset_sigma_s, f.magnitude, f.delta + unexplained()))
    by_wheel: dict[int, list[_Fit]] = {}
    for f in wheel_fits:
        by_wheel.setdefault(f.channel, []).append(f)
    for p, q in combinations(sorted(by_wheel), 2):
        for a in by_wheel[p]:
            for b in by_wheel[q]:
                hyps.append(
                    Hypothesis(
                        f"{a.fault}+{b.fault}",
                        [p + 1, q + 1],
                        min(a.onset_s, b.onset_s),
                        max(a.onset_sigma_s, b.onset_sigma_s),
                        [a.magnitude, b.magnitude],
                        a.delta
                        + b.delta
                        - a.credit.get(q, 0.0)
                        - b.credit.get(p, 0.0)  # q, p fitted, not kicked
                        + unexplained(a, b)
                        - PAIR_PRIOR_LOG_ODDS,
                    )
                )
    return _scored(hyps)[:MAX_LISTED]
