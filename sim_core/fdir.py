"""Onboard fault detection, isolation and reconfiguration (FDIR) of wheels and attitude sensors.

Wheels (seed 000 eq 1–3, seed 002 eq 1–4): each wheel obeys its own momentum equation
ḣ_p = m_p − m^f_p(Ω_p), so a per-wheel residual over one control period T_u,

    r_p = J_p (ΔΩ̃_p + a_pᵗ Δω^pred) − T_u (m_p − ½(m^f_p(Ω̃_p(t_{k−1})) + m^f_p(Ω̃_p(t_k)))),

(Ω̃ the tachometer reading of the speed relative to the body, so that J_p(Ω_p + a_pᵗ ω) is the
wheel's absolute spin momentum; Δω^pred = J⁻¹(−A m − ω̂ × G + L × B) T_u the body-rate change the
model predicts from the commanded torques, the estimated momentum G and the known MD torque — a
prediction, not a gyro difference, so gyro noise (even seed 002's 50σ) cannot raise false alarms;
m_p the held command limited as the motor limits it, seed 000 eq 2) isolates the wheel by
construction. Its threshold is a *bound*, not a tuned number: the tachometer quantum q gives
|error of J ΔΩ̃| ≤ J q; the prediction misses the unmodelled torque (gravity gradient ≤ 3μ/r³
(J_max − J_min)) and the rate noise in ω̂ × G, at most J_p T_u (M_dist + δω |G|) / J_min; and
friction is monotonic in speed, so the true
mean friction over the period lies between m^f at the slowest and fastest speeds the readings
allow (± q/2); the trapezoid estimate lies there too. r_p exceeding ``WHEEL_SAFETY`` × that bound
is a detection, and so is Σ r_p over any window of up to ``WINDOW_PERIODS`` periods ending now exceeding
its own bound (one quantum J q, since readings telescope, + the other terms summed × ``WHEEL_SAFETY`` +
the noise bound below): a weak motor's missing momentum adds up while the quantisation error does not;
a period whose own model bound outweighs the floor every window carries (one quantum J q + one period's noise
bound a) — a seizure's kick — restarts the history instead (with a perfect tachometer the floor is a alone; were
it J q = 0, every period would restart it and only the one-period test would be left);
``CONFIRM_PERIODS`` consecutive detections isolate the wheel, which leaves the
availability mask, so that :func:`sim_core.allocation.allocate_1` passes 4 → 3 → 2 + MD; fewer
than two wheels left is the fault mode (no wheel law exists). Reconfiguration must not make the spacecraft
worse: a wheel that still delivers part of its torque (the period's delivered momentum T_u m_p + r_p clear of
zero and not beyond the command, :func:`_partial_loss_1`) leaves the mask only if the wheels left can still give
three-axis torque (three of rank 3, or two + MD with its geometric condition met, as the allocation's own status
says); otherwise it stays in the loop, untested, and the refusal is an event. Periods where the motor's momentum
limit may cut the torque are not tested (the residual is not defined there).

Seed 002 eq 4's noise torque M_x = K_x W/|W_max| (W white, uniform in [−1, 1], drawn afresh every
sample time τ) acts between rotor and body, so after the decoupling it is wheel p's own noise
momentum N_p = K_x τ Σ u_i over the T_u/τ samples of a period: zero mean, variance
σ_N² = K_x² τ T_u / 3, and sub-Gaussian with that variance as proxy (E e^{λu} = sinh λ / λ ≤ e^{λ²/6}),
so P(|N_p| > a) ≤ 2 exp(−a²/2σ_N²) for any number of samples. The bound a = σ_N √(2 ln(2/P_FA))
(:func:`wheel_noise_bound`) with P_FA = ``FALSE_ALARM_PROBABILITY`` / ``WINDOW_PERIODS`` (the windows
tested each period: union bound) is exceeded by a healthy wheel with probability ≤ P_FA per wheel and
period; over a window of n periods the variance is n σ_N², the bound a√n. It is a
probability bound, independent of the quantisation and model terms, so it adds to their bound outside
``WHEEL_SAFETY`` (the safety factor covers modelling error). For HR12 wheels (J_r = 0.019 kg·m²), K_x =
1e-4 N·m, τ = 0.05 s, T_u = 2 s: σ_N = 1.8e-5 N·m·s per period, a = 7.3 σ_N = 1.3e-4, against one
0.25 rpm quantum J_r q = 5.0e-4; over a 300 s window a√150 = 1.6e-3 — without it, the noise walked
the windows past the one-quantum bound within minutes (23 false alarms in 24 h).

The windows stop at ``WINDOW_PERIODS``, and a √n bound taken at P_FA/150 each costs a weak loss time; under
the noise a guarded Page CUSUM of the same residuals runs beside them (:func:`_cusum_1`): it subtracts a drift
ν = ``CUSUM_DRIFT_SIGMAS`` σ_N per period and tests against J_r q + h, h = σ_N ln(2/P_FA)/(2 ν/σ_N), which a healthy
wheel's noise crosses from a given start with probability ≤ P_FA (Ville's inequality), however long the window.
False-alarm budget per wheel and period: P_FA for the windows + P_FA for the CUSUM's windows starting then;
24 h × 4 wheels at T_u = 2 s is 1.7e5 periods → ≤ 3.5e-4 expected false alarms. A loss of w per period is
found by the CUSUM after ≈ (J_r q + h)/(w − ν) periods: 0.5 σ_N per period (5e-6 N·m withheld on HR12 with
K_x = 1e-4 N·m) in ≈ 215 periods, where no window of ≤ 150 periods reaches its bound.

Sensors (seed 000 §4 measurements, seed 003 §3.2 preprocessing flags):
- star tracker: the normalised innovation squared against the MEKF prediction (χ²(3)) above the
  ``FALSE_ALARM_PROBABILITY`` quantile, reached by a step from the last accepted innovation, is a
  jump; a reading bit-identical to the previous one is frozen (noise never repeats). Rejected
  samples are not used (gyro-only propagation). A *slow* star-tracker drift cannot be told from a
  gyro bias change with these two sensors: the gyro test below reports it (as gyro drift);
- gyros: the rotation the gyros integrate (trapezoid) over ``GYRO_WINDOW_S`` against the
  star tracker's relative rotation over the same window gives the mean rate error per axis; its
  change from the calibration windows beyond the noise bound is drift; on isolation the MEKF's bias
  process noise is widened to the observed drift, so the filter tracks it;
- magnetometer: the field magnitude against the onboard model's (attitude-free); spikes beyond
  the noise bound are replaced by the model field rotated by the estimated attitude;
- gyros and earth sensor without a star tracker (seed 002's observer, eq 15): the earth sample against the
  estimate is one residual for two sensors, so a third witness, the gyros against the rigid-body dynamics
  (:func:`rate_witness_step_1`: the body momentum from the tachometers, every wheel torque internal, propagated
  over windows of up to 600 s, its error bounded from the gyro noise and Markov drift), decides whom an earth alarm
  blames (:func:`earth_witness_check_1`): a gyro it isolated explains a slow disagreement; the earth sensor only
  when the gyro bias the disagreement needs is beyond what the witness allows, or the sample stands out from the
  running mean of the innovation (its own noise or jump); otherwise the alarm is ``fault_detected`` with
  :data:`AMBIGUOUS_ARG` (both candidates) and nothing is isolated. A tachometer fault looks like a gyro fault to it.

Events (codes of :data:`sim_core.trajectory.EVENT_NAMES`): ``fault_detected``, ``fault_isolated``
(argument: wheel index 0..3, or ``SENSOR_ARG + 10 · target code + axis`` for sensors, target codes
of :data:`sim_core.closed_loop.TARGET_CODES`), ``reconfigured`` (argument: the new wheel
availability bit mask, or ``SENSOR_ARG + 10 · target code`` for a sensor), ``reconfiguration_refused``
(argument: wheel index + 10 · the allocation status the wheels left would have: a partly working wheel is kept
where taking it out would lose three-axis torque), ``mode_change`` (argument: :data:`sim_core.modes.MODE_FAULT`).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.stats import chi2, norm

from sim_core import allocation
from sim_core.modes import MODE_FAULT
from sim_core.orbit import MU_EARTH_M3_S2
from sim_core.quaternion import conjugate_rotate_1, dot3_1
from sim_core.wheels import friction_torque_one_wheel, limited_motor_torque_1

__all__ = [
    "WHEEL_SAFETY",
    "CONFIRM_PERIODS",
    "FALSE_ALARM_PROBABILITY",
    "SENSOR_ARG",
    "GYRO_WINDOW_S",
    "GYRO_CALIBRATION_WINDOWS",
    "WHEEL_STATE_ROWS",
    "STAR_STATE_SIZE",
    "GYRO_STATE_SIZE",
    "MAG_STATE_SIZE",
    "star_nis_threshold",
    "gaussian_sigmas",
    "wheel_noise_sigma",
    "wheel_noise_bound",
    "wheel_state",
    "wheel_state_1",
    "star_state",
    "gyro_state",
    "mag_state",
    "WINDOW_PERIODS",
    "CUSUM_DRIFT_SIGMAS",
    "wheel_bound_1",
    "wheel_residual_1",
    "wheel_decoupling_1",
    "wheel_check_1",
    "wheel_hold_1",
    "star_innovation_1",
    "star_tracker_check_1",
    "star_readmit_1",
    "star_reset_1",
    "earth_sensor_check_1",
    "EARTH_STATE_SIZE",
    "WITNESS_STATE_SIZE",
    "AMBIGUOUS_ARG",
    "witness_state",
    "witness_state_1",
    "rate_witness_step_1",
    "earth_witness_check_1",
    "gyro_drift_step_1",
    "magnetometer_check_1",
    "wheel_residuals",
    "observable_time",
    "describe_event",
]

WHEEL_SAFETY = 2.0  # bound × 2: room for unmodelled speed reversals inside a period and RK4 error
CONFIRM_PERIODS = 2  # two consecutive periods: one isolated exceedance is a transient, not a fault
FALSE_ALARM_PROBABILITY = 1e-9  # per Gaussian test: 24 h × 4 Hz × 3 axes ≈ 1e6 tests → 1e-3 alarms expected
SENSOR_ARG = 100  # event arguments ≥ this name a sensor (SENSOR_ARG + 10·target + axis)
GYRO_WINDOW_S = 60.0  # ST noise 3″ → √2σ/W ≈ 3.5e-7 rad/s: drift of ~0.5°/h shows within a minute
GYRO_CALIBRATION_WINDOWS = 3  # the first windows fix the reference bias (post-launch calibration)
NUMERICAL_FLOOR_NMS = 1e-9  # momentum round-off of RK4 on N·m·s-sized states, a floor for perfect sensors
MAG_MODEL_ERROR_T = 20e-9  # onboard field table vs truth: linear interpolation of a 30 s table, a few nT

EV_MODE, EV_DETECTED, EV_ISOLATED, EV_RECONFIGURED, EV_REFUSED = 1, 4, 5, 6, 10
T_GYRO, T_STAR, T_EARTH, T_MAG = 1, 2, 3, 4  # sim_core.faults.TARGET_CODES

# Wheel state rows (WHEEL_STATE_ROWS × n_wheels).
WS_SPEED, WS_TORQUE, WS_COUNT, WS_VALID, WS_ISOLATED, WS_AXIAL, WS_AXIAL_ERR, WS_COUPLING, WS_W = range(9)
WS_N, WS_HEAD = 11, 12  # periods in the window history, its ring slot of the newest boundary
WS_HIST = 13  # ring of WINDOW_PERIODS + 1 boundaries: cumulative Σ r, then cumulative Σ bound without the quantum
WINDOW_PERIODS = 150  # longest window tested: 300 s at T_u = 2 s; every shorter one ending now is tested too
WS_CUSUM = WS_HIST + 2 * (WINDOW_PERIODS + 1)  # guarded CUSUM of d⁺, its last min(0, d⁺); then the same of d⁻
WS_GAIN = WS_CUSUM + 4  # a kept partly working wheel: the share of its command it delivers (0: not kept)
WHEEL_STATE_ROWS = WS_CUSUM + 5  # WS_W..WS_W+2: body rate at the hold
CUSUM_DRIFT_SIGMAS = 0.25  # ν = 0.25 σ_N per period: the CUSUM finds a withheld momentum > ν per period, any length
CUSUM_LIMIT_SIGMAS = float(np.log(2.0 / FALSE_ALARM_PROBABILITY) / (2.0 * CUSUM_DRIFT_SIGMAS))  # h / σ_N: Ville
WINDOW_NOISE_SIGMAS = float(np.sqrt(2.0 * np.log(2.0 * WINDOW_PERIODS / FALSE_ALARM_PROBABILITY)))  # a / σ_N
# Star-tracker state: previous reading, consecutive rejections, isolated flag, last accepted
# innovation (3), in-jump flag.
SS_PREV, SS_COUNT, SS_ISOLATED, SS_Z, SS_JUMP, SS_SCALE, SS_N, SS_SUM, SS_ZLAST = 0, 4, 5, 6, 9, 10, 11, 12, 15
STAR_STATE_SIZE = 18  # SS_SUM: squared consecutive innovation differences (3); SS_ZLAST: last innovation (3)
NOISE_WINDOW = 20  # samples (5 s at 4 Hz) before deciding noise vs jump: the scatter is then known to ±16 %
NOISE_RATIO = 2.0  # scatter above 2σ (well beyond ±16 %) is noise; a jumped tracker stays at σ
# Gyro state: integrated rotation, ST at window start, window start time, previous rate, reference
# bias, windows seen, consecutive exceedances, isolated flag, bias process noise, calibration end time.
GS_QINT, GS_QST0, GS_T0, GS_WPREV, GS_BREF = 0, 4, 8, 9, 12
GS_N, GS_COUNT, GS_ISOLATED, GS_SIGMA_U, GS_TREF = 15, 16, 17, 18, 19
GYRO_STATE_SIZE = 20
# Earth-sensor state: consecutive rejections, isolated flag.
ES_COUNT, ES_ISOLATED = 0, 1
EARTH_STATE_SIZE = 2
# Magnetometer state: time of the last rejected sample (NaN: none yet).
MS_LAST = 0
MAG_STATE_SIZE = 1
MAG_REARM_S = 60.0  # a new detection event only after a minute of clean samples (spikes come in bursts)


def gaussian_sigmas(probability: float = FALSE_ALARM_PROBABILITY) -> float:
    """Two-sided Gaussian threshold in σ for a per-test false-alarm probability (seed 002 noise model)."""
    if not 0.0 < probability < 1.0:
        raise ValueError("probability: must lie in (0, 1)")
    return float(norm.isf(0.5 * probability))


def wheel_noise_sigma(noise_nm: np.ndarray, sample_s: float, t_u: float) -> np.ndarray:
    """Per-wheel σ_N = K_x √(τ T_u / 3) of the noise momentum of one control period T_u, N·m·s: seed 002 eq 4's
    M_x = K_x W/|W_max|, W uniform in [−1, 1] drawn every ``sample_s`` τ (module docstring)."""
    k_x = np.asarray(noise_nm, dtype=float)
    if k_x.ndim != 1 or not np.all(np.isfinite(k_x)) or np.any(k_x < 0.0):
        raise ValueError("noise_nm: expected one finite non-negative K_x per wheel")
    if not (0.0 < sample_s <= t_u and np.isfinite(t_u)):
        raise ValueError("sample_s, t_u: expected 0 < sample_s ≤ t_u, finite")
    sigma: np.ndarray = k_x * np.sqrt(sample_s * t_u / 3.0)
    return sigma


def wheel_noise_bound(
    noise_nm: np.ndarray, sample_s: float, t_u: float, probability: float = FALSE_ALARM_PROBABILITY / WINDOW_PERIODS
) -> np.ndarray:
    """Per-wheel bound a = σ_N √(2 ln(2/P)) on the noise momentum of one control period T_u, N·m·s
    (σ_N from :func:`wheel_noise_sigma`; sub-Gaussian tail, module docstring)."""
    if not 0.0 < probability < 1.0:
        raise ValueError("probability: must lie in (0, 1)")
    bound: np.ndarray = wheel_noise_sigma(noise_nm, sample_s, t_u) * np.sqrt(2.0 * np.log(2.0 / probability))
    return bound


def star_nis_threshold(probability: float = FALSE_ALARM_PROBABILITY) -> float:
    """χ²(3) quantile of the star-tracker innovation test (seed 000 §4 measurement noise)."""
    if not 0.0 < probability < 1.0:
        raise ValueError("probability: must lie in (0, 1)")
    return float(chi2.isf(probability, 3))


def wheel_state(n_wheels: int) -> np.ndarray:
    """Fresh wheel FDIR state (rows WS_*, one column per wheel)."""
    if n_wheels < 1:
        raise ValueError("n_wheels: must be at least 1")
    return wheel_state_1(n_wheels)


@njit(cache=True)
def wheel_state_1(n_wheels: int) -> np.ndarray:
    """Compiled :func:`wheel_state`: zeros (an empty window history)."""
    return np.zeros((WHEEL_STATE_ROWS, n_wheels))


def star_state() -> np.ndarray:
    """Fresh star-tracker FDIR state (no previous reading)."""
    s = np.zeros(STAR_STATE_SIZE)
    s[SS_PREV : SS_PREV + 4] = np.nan
    return s


def gyro_state(sigma_u: float) -> np.ndarray:
    """Fresh gyro-drift FDIR state; ``sigma_u`` is the MEKF bias process noise (rad/s/√s)."""
    if not sigma_u >= 0.0:
        raise ValueError("sigma_u: must be non-negative")
    s = np.zeros(GYRO_STATE_SIZE)
    s[GS_T0] = np.nan
    s[GS_SIGMA_U] = sigma_u
    return s


def mag_state() -> np.ndarray:
    """Fresh magnetometer FDIR state."""
    return np.full(MAG_STATE_SIZE, np.nan)


@njit(cache=True)
def _emit(ev: np.ndarray, n_ev: np.ndarray, t: float, code: int, arg: int) -> None:
    if n_ev[0] < ev.shape[0]:
        ev[n_ev[0], 0], ev[n_ev[0], 1], ev[n_ev[0], 2] = t, code, arg
        n_ev[0] += 1


@njit(cache=True)
def wheel_bound_1(
    inertia: float,
    speed_prev: float,
    speed_now: float,
    tach_q: float,
    rate_noise: float,
    t_u: float,
    friction: np.ndarray,
    p: int,
) -> float:
    """Bound on |r_p| of a healthy wheel: J (q + δω) + T_u (m^f(Ω_hi) − m^f(Ω_lo)) (seed 000 eq 1, seed 002 eq 4)."""
    lo = min(speed_prev, speed_now) - 0.5 * tach_q
    hi = max(speed_prev, speed_now) + 0.5 * tach_q
    spread = friction_torque_one_wheel(hi, friction, p) - friction_torque_one_wheel(lo, friction, p)
    return inertia * (tach_q + rate_noise) + t_u * abs(spread) + NUMERICAL_FLOOR_NMS


@njit(cache=True)
def wheel_residual_1(
    inertia: float,
    speed_prev: float,
    speed_now: float,
    axial_rate_change: float,
    torque: float,
    t_u: float,
    friction: np.ndarray,
    p: int,
) -> float:
    """Momentum residual r_p of one wheel over one control period, N·m·s (seed 000 eq 1)."""
    f_mean = 0.5 * (
        friction_torque_one_wheel(speed_prev, friction, p) + friction_torque_one_wheel(speed_now, friction, p)
    )
    return inertia * (speed_now - speed_prev + axial_rate_change) - t_u * (torque - f_mean)


@njit(cache=True)
def wheel_decoupling_1(axes: np.ndarray, inertia: np.ndarray, j_inv: np.ndarray) -> np.ndarray:
    """(I + diag(J_r) Aᵗ J_e⁻¹ A)⁻¹: a torque error e on the wheels gives residuals r = T_u (I + D) e,
    since the body rate the prediction misses couples every wheel (seed 000 eq 1); this undoes it."""
    nw = inertia.shape[0]
    m = np.eye(nw)
    ja = j_inv @ axes
    for p in range(nw):
        for q in range(nw):
            m[p, q] += inertia[p] * (axes[0, p] * ja[0, q] + axes[1, p] * ja[1, q] + axes[2, p] * ja[2, q])
    return np.linalg.inv(m)


@njit(cache=True)
def _clear_windows_1(state: np.ndarray, p: int) -> None:
    """Restart wheel p's window history: the current boundary becomes the first one."""
    head = int(state[WS_HEAD, p])
    state[WS_N, p] = 0.0
    state[WS_HIST + head, p] = 0.0
    state[WS_HIST + WINDOW_PERIODS + 1 + head, p] = 0.0


@njit(cache=True)
def _scan_windows_1(state: np.ndarray, p: int, r: float, b_rest: float, b_quantum: float, b_noise: float) -> bool:
    """Add one period to wheel p's history and test every window ending now; True if one exceeds its bound.

    A window of n periods from boundary j holds Σ r and Σ (bound without the quantum). Over it the tachometer
    errors telescope (Σ J ΔΩ̃ = J (Ω̃_now − Ω̃_j), two readings each within ±q/2: at most one quantum J q,
    exactly, so it needs no safety factor), while the missing momentum of a dead or weak motor adds up; the
    other bound terms add up and keep WHEEL_SAFETY; the wheel's noise momentum over n periods has n times one
    period's variance, so its bound ``b_noise`` (one period) grows as √n. A window counts only together with
    the one a period longer: a single wrong reading at boundary j shows in the windows starting there but
    not in those straddling it, so it cannot isolate a wheel; a lasting fault pays one period for this."""
    size = WINDOW_PERIODS + 1
    head = int(state[WS_HEAD, p])
    now = (head + 1) % size
    s_now = state[WS_HIST + head, p] + r
    b_now = state[WS_HIST + size + head, p] + b_rest
    state[WS_HIST + now, p] = s_now
    state[WS_HIST + size + now, p] = b_now
    state[WS_HEAD, p] = now
    n = int(min(state[WS_N, p] + 1.0, WINDOW_PERIODS))
    state[WS_N, p] = n
    longer_hit = False
    for i in range(1, n + 1):
        j = (now - i) % size
        limit = WHEEL_SAFETY * (b_now - state[WS_HIST + size + j, p]) + b_quantum + b_noise * np.sqrt(i)
        hit = abs(s_now - state[WS_HIST + j, p]) > limit
        if hit and longer_hit:
            return True
        longer_hit = hit
    return False


@njit(cache=True)
def _cusum_side_1(state: np.ndarray, row: int, p: int, d: float, first: bool) -> float:
    """One side of wheel p's guarded CUSUM after a period with increment d: A_k = max(A_{k−1}, min(0, d_{k−1})) + d_k,
    the largest S_k − S_j − C(j, k) over boundaries j whose window one period longer exceeds as much (the windows'
    glitch guard: the window from j−1 adds d_j, so min of the two is W(j, k) + min(0, d_j)); −inf until a window
    one period longer exists (``first``: the history was just restarted)."""
    a = -np.inf if first else max(state[row, p], state[row + 1, p]) + d
    state[row, p] = a
    state[row + 1, p] = min(0.0, d)
    return a


@njit(cache=True)
def _cusum_1(state: np.ndarray, p: int, r: float, b_rest: float, b_quantum: float, sigma: float, first: bool) -> bool:
    """Page's CUSUM of wheel p's residuals, both signs: True when a withheld momentum exceeds its bound over any
    window ending now, however long (the windows stop at ``WINDOW_PERIODS``).

    Over the window (j, k] a healthy wheel's Σ r is at most J q (telescoping quantisation) + WHEEL_SAFETY Σ b_rest
    + its noise momentum N_{j,k}; the statistic subtracts the first two and a drift ν = ``CUSUM_DRIFT_SIGMAS`` σ per
    period. N is a sum of independent sub-Gaussian period momenta of variance proxy σ² (module docstring), so
    exp(λ(N − ν n)) with λ = 2ν/σ² is a supermartingale and, by Ville's inequality, N_{j,k} − ν (k − j) exceeds
    h = σ² ln(2/P_FA) / 2ν for some k ≥ j with probability ≤ P_FA/2 per side: P_FA per start j, the
    windows' budget per period again (seed 002 eq 4; wheel_noise_bound)."""
    cost = CUSUM_DRIFT_SIGMAS * sigma + WHEEL_SAFETY * b_rest
    up = _cusum_side_1(state, WS_CUSUM, p, r - cost, first)
    down = _cusum_side_1(state, WS_CUSUM + 2, p, -r - cost, first)
    return max(up, down) > b_quantum + CUSUM_LIMIT_SIGMAS * sigma


@njit(cache=True)
def _partial_loss_1(command_nms: float, residual_nms: float, band_nms: float) -> bool:
    """True if the wheel's motor still delivers part of its command over the period: the delivered momentum
    T_u m_p + r_p (the decoupled r_p is T_u times the torque error, wheel_decoupling_1), known to within the band
    ``band_nms`` a healthy residual stays in, lies with the command's sign between that band (so a dead or stuck
    motor, delivering 0, cannot pass) and the command plus the band (a seizure's kick, J Ω ≫ T_u m^max, or a gain
    above one overshoots it)."""
    delivered = np.sign(command_nms) * (command_nms + residual_nms)
    return command_nms != 0.0 and band_nms < delivered < abs(command_nms) + band_nms


@njit(cache=True)
def _status_without_1(
    p: int, axes: np.ndarray, available: np.ndarray, h_wheels: np.ndarray, mag: np.ndarray, params: np.ndarray
) -> int:
    """Allocation status of the available wheels without wheel p: ``allocate_1`` of a zero torque, whose status
    depends on the geometry only (rank of three wheels, the MD's condition for two, seed 000 §3)."""
    rest = available.copy()
    rest[p] = False
    nw = available.shape[0]
    return allocation.allocate_1(np.zeros(3), axes, rest, h_wheels, mag, params, np.zeros(nw), np.zeros(3))


@njit(cache=True)
def wheel_check_1(
    state: np.ndarray,
    speeds: np.ndarray,
    w_body: np.ndarray,
    inertia: np.ndarray,
    max_momentum: np.ndarray,
    friction: np.ndarray,
    tach_q: float,
    noise_sigma: np.ndarray,
    t_u: float,
    decouple: np.ndarray,
    available: np.ndarray,
    axes: np.ndarray,
    h_wheels: np.ndarray,
    mag: np.ndarray,
    alloc_params: np.ndarray,
    ev: np.ndarray,
    n_ev: np.ndarray,
    t: float,
) -> bool:
    """Test every available wheel's residual, isolate and drop confirmed faults; True if in fault mode.

    ``speeds``: tachometer readings at t (rad/s); ``noise_sigma`` each wheel's noise-momentum σ_N over one period
    (:func:`wheel_noise_sigma`, N·m·s; zeros without seed 002's noise torque), whose bound at the windows'
    false-alarm probability is σ_N ``WINDOW_NOISE_SIGMAS`` (:func:`wheel_noise_bound`'s default) and which the
    CUSUM takes as it is; ``state`` holds the previous reading, the
    predicted change of the body rate about each axis with its error bound, and the
    limited torque held since (see :func:`wheel_hold_1`); ``decouple`` from
    :func:`wheel_decoupling_1`, so that each decoupled residual answers for its own wheel only;
    ``w_body`` the estimated body rate now: the prediction held ω̂ × G constant over the period, so
    its error bound grows with the rate change |Δω̂| (a seizing wheel's kick, a manoeuvre).
    Writes fault_detected / fault_isolated / reconfigured / mode_change events (seed 000 §3
    reconfiguration 4 → 3 → 2 + MD). An isolated wheel with a partial loss (:func:`_partial_loss_1`) leaves the
    allocation only if the rest can still give three-axis torque: ``allocation.allocate_1`` of a zero torque on
    ``axes`` without it (``h_wheels``, magnetometer ``mag``, ``alloc_params``) returns the status the rest's
    geometry gives; any but ``STATUS_OK`` keeps the wheel in the loop and writes reconfiguration_refused (argument
    p + 10 · that status). A kept wheel stays monitored against what it still delivers, the share g = (T_u m_p +
    r_p)/(T_u m_p) of the isolating period (``WS_GAIN``): its residual is taken against g m_p, so that a later total
    loss (nothing delivered, within the band) is isolated again and the wheel dropped whatever the rest can do; a
    departure that still delivers, with the command's sign, re-estimates g (at most 1), without an event.
    """
    nw = speeds.shape[0]
    raw, bound, quantum = np.zeros(nw), np.zeros(nw), inertia * tach_q
    noise = noise_sigma * WINDOW_NOISE_SIGMAS
    tested = np.zeros(nw, dtype=np.bool_)
    dw = 0.0
    for i in range(3):
        dw += (w_body[i] - state[WS_W + i, 0]) ** 2
    dw = np.sqrt(dw)
    for p in range(nw):
        if state[WS_VALID, p] == 0.0:
            continue
        torque = state[WS_TORQUE, p]
        if state[WS_GAIN, p] > 0.0:
            torque *= state[WS_GAIN, p]  # a kept wheel: tested against what it still delivers
        if abs(inertia[p] * state[WS_SPEED, p]) + abs(torque) * t_u >= max_momentum[p]:
            bound[p] = abs(torque) * t_u  # the motor's momentum limit may cut the torque: untested
            continue
        # dropped wheels still enter the decoupling (a rubbing one still pushes); a kept one is tested at its share
        tested[p] = available[p]
        raw[p] = wheel_residual_1(
            inertia[p], state[WS_SPEED, p], speeds[p], state[WS_AXIAL, p], torque, t_u, friction, p
        )
        bound[p] = wheel_bound_1(
            inertia[p],
            state[WS_SPEED, p],
            speeds[p],
            tach_q,
            state[WS_AXIAL_ERR, p] + state[WS_COUPLING, p] * dw,
            t_u,
            friction,
            p,
        )
    changed = False
    for p in range(nw):
        if not tested[p]:
            state[WS_COUNT, p] = 0.0
            _clear_windows_1(state, p)
            continue
        r, b, bq, sigma = 0.0, 0.0, 0.0, 0.0
        for q in range(nw):
            r += decouple[p, q] * raw[q]
            b += abs(decouple[p, q]) * bound[q]
            bq += abs(decouple[p, q]) * quantum[q]
            sigma += abs(decouple[p, q]) * noise_sigma[q]  # ≥ the decoupled noise's σ
        # Not summed when the period's model bound outweighs the floor every window carries, one quantum + one
        # period's noise bound (a seizure's kick); with a perfect tachometer that floor is the noise bound alone.
        if b - bq > bq + noise[p]:
            _clear_windows_1(state, p)
            accumulated = False
        else:
            first = state[WS_N, p] == 0.0
            accumulated = _scan_windows_1(state, p, r, b - bq, bq, noise[p])
            if sigma > 0.0:  # without noise the windows' bound is exact and the CUSUM's h would be 0/0
                accumulated = _cusum_1(state, p, r, b - bq, bq, sigma, first) or accumulated
        band = WHEEL_SAFETY * b + noise[p]
        exceeded = accumulated or abs(r) > band
        if not exceeded:
            state[WS_COUNT, p] = 0.0
            continue
        state[WS_COUNT, p] += 1.0
        command = state[WS_TORQUE, p] * t_u * (state[WS_GAIN, p] if state[WS_GAIN, p] > 0.0 else 1.0)
        if state[WS_GAIN, p] > 0.0 and command != 0.0 and np.sign(command) * (command + r) > band:
            if state[WS_COUNT, p] >= CONFIRM_PERIODS:  # still delivering (a part): a new share, no event
                state[WS_GAIN, p] = min(state[WS_GAIN, p] * (command + r) / command, 1.0)
                state[WS_COUNT, p] = 0.0
                _clear_windows_1(state, p)
            continue
        if state[WS_COUNT, p] == 1.0:
            _emit(ev, n_ev, t, EV_DETECTED, p)
        if state[WS_COUNT, p] >= CONFIRM_PERIODS:
            _emit(ev, n_ev, t, EV_ISOLATED, p)
            state[WS_ISOLATED, p] = 1.0
            status = allocation.STATUS_OK
            if state[WS_GAIN, p] == 0.0 and _partial_loss_1(command, r, band):
                status = _status_without_1(p, axes, available, h_wheels, mag, alloc_params)
            if status == allocation.STATUS_OK:
                available[p] = False
                changed = True
            else:
                _emit(ev, n_ev, t, EV_REFUSED, p + 10 * status)
                state[WS_GAIN, p] = min((command + r) / command, 1.0)  # its share: > 0 by _partial_loss_1
                state[WS_COUNT, p] = 0.0
                _clear_windows_1(state, p)
    n_on = 0
    mask = 0
    for p in range(nw):
        if available[p]:
            n_on += 1
            mask |= 1 << p
    if changed:
        _emit(ev, n_ev, t, EV_RECONFIGURED, mask)
        if n_on < 2:
            _emit(ev, n_ev, t, EV_MODE, MODE_FAULT)
    return n_on < 2


@njit(cache=True)
def wheel_hold_1(
    state: np.ndarray,
    speeds: np.ndarray,
    w_body: np.ndarray,
    axes: np.ndarray,
    cmd: np.ndarray,
    inertia: np.ndarray,
    max_torque: np.ndarray,
    max_momentum: np.ndarray,
    friction: np.ndarray,
    j_body: np.ndarray,
    j_inv: np.ndarray,
    md_torque_b: np.ndarray,
    dist_torque: float,
    rate_noise: float,
    t_u: float,
) -> None:
    """Remember the readings, the torque the motor will deliver for ``cmd`` (seed 000 eq 2–3) and the body-rate
    change Δω^pred = J_e⁻¹(−A(m − m^f) − ω̂ × G + L × B) T_u the model predicts (seed 000 eq 1).

    ``j_body`` is J (wheels locked, as in G = Jω + A J_r Ω), ``j_inv`` the inverse of J_e = J − A J_r Aᵗ,
    the inertia that the body rate sees once the wheel equations are eliminated.
    """
    limited = limited_motor_torque_1(cmd, speeds, inertia, max_torque, max_momentum)
    nw = speeds.shape[0]
    g = j_body @ w_body
    torque = md_torque_b.copy()
    for p in range(nw):
        for i in range(3):
            g[i] += axes[i, p] * inertia[p] * speeds[p]
            torque[i] -= axes[i, p] * (limited[p] - friction_torque_one_wheel(speeds[p], friction, p))
    torque[0] -= w_body[1] * g[2] - w_body[2] * g[1]
    torque[1] -= w_body[2] * g[0] - w_body[0] * g[2]
    torque[2] -= w_body[0] * g[1] - w_body[1] * g[0]
    dw = (j_inv @ torque) * t_u
    j_inv_norm = 0.0
    for i in range(3):
        j_inv_norm = max(j_inv_norm, abs(j_inv[i, 0]) + abs(j_inv[i, 1]) + abs(j_inv[i, 2]))
    err = j_inv_norm * t_u * (dist_torque + rate_noise * np.sqrt(dot3_1(g, g)))
    for p in range(nw):
        state[WS_SPEED, p] = speeds[p]
        state[WS_AXIAL, p] = axes[0, p] * dw[0] + axes[1, p] * dw[1] + axes[2, p] * dw[2]
        state[WS_AXIAL_ERR, p] = err
        state[WS_COUPLING, p] = j_inv_norm * t_u * np.sqrt(dot3_1(g, g))  # |Δ(ω × G)| ≤ |Δω| |G| over the period
        state[WS_W : WS_W + 3, p] = w_body
        state[WS_TORQUE, p] = limited[p]
        state[WS_VALID, p] = 1.0


@njit(cache=True)
def _rotvec_between_1(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation vector of ã ∘ b (small-angle exact to second order via 2 atan2), rad."""
    a0, a1, a2, a3 = a[0], -a[1], -a[2], -a[3]
    d0 = a0 * b[0] - a1 * b[1] - a2 * b[2] - a3 * b[3]
    d1 = a0 * b[1] + a1 * b[0] + a2 * b[3] - a3 * b[2]
    d2 = a0 * b[2] - a1 * b[3] + a2 * b[0] + a3 * b[1]
    d3 = a0 * b[3] + a1 * b[2] - a2 * b[1] + a3 * b[0]
    if d0 < 0.0:
        d0, d1, d2, d3 = -d0, -d1, -d2, -d3
    s = np.sqrt(d1 * d1 + d2 * d2 + d3 * d3)
    out = np.zeros(3)
    if s > 0.0:
        k = 2.0 * np.arctan2(s, d0) / s
        out[0], out[1], out[2] = k * d1, k * d2, k * d3
    return out


@njit(cache=True)
def star_innovation_1(
    q_est: np.ndarray, p_cov: np.ndarray, q_meas: np.ndarray, sigma3: np.ndarray
) -> tuple[np.ndarray, float]:
    """Innovation z = rotvec(Λ̂̃ ∘ Λ^m) and zᵀ(P_θθ + diag σ²)⁻¹z, χ²(3) if consistent (seed 000 §4)."""
    z = _rotvec_between_1(q_est, q_meas)
    s = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s[i, j] = p_cov[i, j]
        s[i, i] += sigma3[i] * sigma3[i]
    return z, float(z @ np.linalg.solve(s, z))


@njit(cache=True)
def star_tracker_check_1(
    state: np.ndarray,
    q_est: np.ndarray,
    p_cov: np.ndarray,
    q_meas: np.ndarray,
    sigma3: np.ndarray,
    nis_max: float,
    gyro_suspect: bool,
    ev: np.ndarray,
    n_ev: np.ndarray,
    t: float,
) -> float:
    """Screen one star-tracker sample; returns the factor on σ to update with, or 0 to reject it.

    seed 000 §4: Λ^m = Λ ∘ Λ^n with σ per axis; the innovation z = rotvec(Λ̂̃ ∘ Λ^m) has covariance
    S = P_θθ + diag(σ²). A sample is a *jump* when zᵀS⁻¹z exceeds the limit and z also stepped from
    the last accepted innovation by more than the limit allows for two independent samples (2σ²;
    a gradual growth, e.g. an unmodelled gyro drift, is left to the gyro test); once jumped, samples
    stay rejected while either statistic stays beyond the limit, so that the covariance growing
    during gyro-only propagation does not let a lasting offset back in. Once isolated, a tracker whose
    consecutive innovations scatter beyond ``NOISE_RATIO`` σ is noisy, not jumped: σ is scaled to the
    scatter (seed 002's 10σ/50σ) and the sensor used again. With the gyro suspect
    (drift isolated) only freezes are rejected. A reading bit-identical to the previous one is frozen.
    """
    scale = max(1.0, state[SS_SCALE])
    sig = sigma3 * scale
    z, nis = star_innovation_1(q_est, p_cov, q_meas, sig)
    step = 0.0
    for i in range(3):
        d = z[i] - state[SS_Z + i]
        step += d * d / (2.0 * sig[i] * sig[i]) if sig[i] > 0.0 else 0.0
    frozen = (
        sigma3[0] > 0.0
        and q_meas[0] == state[SS_PREV]
        and q_meas[1] == state[SS_PREV + 1]
        and q_meas[2] == state[SS_PREV + 2]
        and q_meas[3] == state[SS_PREV + 3]
    )
    state[SS_PREV : SS_PREV + 4] = q_meas
    jumped = (nis > nis_max and step > nis_max) or (state[SS_JUMP] != 0.0 and (nis > nis_max or step > nis_max))
    if gyro_suspect:
        jumped = False
    if state[SS_ISOLATED] != 0.0 and not frozen:
        _noise_or_jump_1(state, z, p_cov, sigma3, ev, n_ev, t)
    if not frozen and not jumped:
        state[SS_COUNT] = 0.0
        state[SS_JUMP] = 0.0
        state[SS_Z : SS_Z + 3] = z
        return float(scale)
    state[SS_JUMP] = 1.0 if jumped else state[SS_JUMP]
    state[SS_COUNT] += 1.0
    arg = SENSOR_ARG + 10 * T_STAR
    if state[SS_COUNT] == 1.0 and state[SS_ISOLATED] == 0.0:
        _emit(ev, n_ev, t, EV_DETECTED, arg)
    if state[SS_COUNT] == CONFIRM_PERIODS and state[SS_ISOLATED] == 0.0:
        state[SS_ISOLATED] = 1.0
        state[SS_N] = 0.0
        _emit(ev, n_ev, t, EV_ISOLATED, arg)
        _emit(ev, n_ev, t, EV_RECONFIGURED, arg)
    return 0.0


@njit(cache=True)
def star_readmit_1(
    state: np.ndarray,
    q_est: np.ndarray,
    q_meas: np.ndarray,
    p_cov: np.ndarray,
    nadir_b: np.ndarray,
    nadir_ref_i: np.ndarray,
    sigma_earth: float,
    n_sigma: float,
    ev: np.ndarray,
    n_ev: np.ndarray,
    t: float,
) -> bool:
    """Third-sensor vote on a rejected star-tracker sample (seed 002 eq 14 earth sensor): if the earth
    sensor's nadir agrees with the star tracker and not with the estimate, the estimate was wrong (a
    kick the propagation missed), so the tracker is re-admitted and the attitude covariance opened."""
    if state[SS_JUMP] == 0.0:
        return False
    limit = n_sigma * np.sqrt(2.0) * sigma_earth
    ref = nadir_ref_i / np.sqrt(dot3_1(nadir_ref_i, nadir_ref_i))
    by_star = conjugate_rotate_1(q_meas, ref)
    by_est = conjugate_rotate_1(q_est, ref)
    if np.arccos(min(1.0, dot3_1(nadir_b, by_star))) > limit or np.arccos(min(1.0, dot3_1(nadir_b, by_est))) <= limit:
        return False
    z = _rotvec_between_1(q_est, q_meas)
    for i in range(3):
        p_cov[i, i] += dot3_1(z, z)
    state[SS_JUMP] = 0.0
    state[SS_COUNT] = 0.0
    state[SS_ISOLATED] = 0.0
    state[SS_Z : SS_Z + 3] = 0.0
    _emit(ev, n_ev, t, EV_RECONFIGURED, SENSOR_ARG + 10 * T_STAR + 2)
    return True


@njit(cache=True)
def _earth_rejected(state: np.ndarray, ev: np.ndarray, n_ev: np.ndarray, t: float) -> bool:
    """An earth-sensor sample rejected: ``fault_detected`` at the first rejection in a row, ``fault_isolated`` at
    ``CONFIRM_PERIODS`` in a row (event argument SENSOR_ARG + 10·T_EARTH). False: do not use it."""
    state[ES_COUNT] += 1.0
    if state[ES_COUNT] == 1.0:
        _emit(ev, n_ev, t, EV_DETECTED, SENSOR_ARG + 10 * T_EARTH)
    if state[ES_COUNT] == CONFIRM_PERIODS and state[ES_ISOLATED] == 0.0:
        state[ES_ISOLATED] = 1.0
        _emit(ev, n_ev, t, EV_ISOLATED, SENSOR_ARG + 10 * T_EARTH)
    return False


@njit(cache=True)
def earth_sensor_check_1(
    state: np.ndarray,
    q_est: np.ndarray,
    p_cov: np.ndarray,
    nadir_b: np.ndarray,
    nadir_ref_i: np.ndarray,
    sigma_earth: float,
    ev: np.ndarray,
    n_ev: np.ndarray,
    t: float,
) -> bool:
    """Screen an earth-sensor nadir (seed 002 eq 14) against the MEKF's prediction: the NIS of the two-axis
    angle |b̂ × b|² / (σ² + the largest attitude variance) above the χ²(2) quantile −2 ln P_FA is rejected;
    ``CONFIRM_PERIODS`` rejections in a row isolate it (event argument SENSOR_ARG + 10·T_EARTH). True: use it."""
    ref = nadir_ref_i / np.sqrt(dot3_1(nadir_ref_i, nadir_ref_i))
    pred = conjugate_rotate_1(q_est, ref)
    d = np.cross(pred, nadir_b)
    s2 = sigma_earth**2 + max(p_cov[0, 0], p_cov[1, 1], p_cov[2, 2])
    if dot3_1(d, d) / s2 <= -2.0 * np.log(FALSE_ALARM_PROBABILITY):
        state[ES_COUNT] = 0.0
        return True
    return _earth_rejected(state, ev, n_ev, t)


# --- gyro vs the rigid-body dynamics (a third witness where no star tracker flies) ------------------------------

RW_ANCHORS = 10  # windows ending now, starting every RW_EVERY_S: the oldest spans 540–600 s
RW_EVERY_S = 60.0
RW_INNOVATION_TAU_S = 10.0  # the earth innovation's running mean: σ_e √(T_q/2τ) = 0.07 σ_e at T_q = 0.1 s
RW_COUNT, RW_ISOLATED, RW_NEXT, RW_HEAD, RW_N, RW_AMBIGUOUS, RW_REACH, RW_NU_V, RW_NU_N = range(9)
RW_NU, RW_HWPREV, RW_KEEP, RW_AXIS = 9, 12, 15, 16  # mean earth innovation (3), previous wheel momentum (3), the
RW_SCATTER = 17  # the running mean of the oldest window's ρ steps squared (3)
RW_A0 = 20  # window kept and the axis replaced after an isolation (RW_KEEP < 0: none, a noisy gyro); the anchors
RW_ANCHOR_SIZE = 8  # anchor time, H_b propagated from it (3), the bound on √E of its error, its last ρ (3)
WITNESS_STATE_SIZE = RW_A0 + RW_ANCHORS * RW_ANCHOR_SIZE
CHI3_SIGMAS = float(np.sqrt(chi2.isf(FALSE_ALARM_PROBABILITY, 3)))  # |3-D Gaussian| / σ not exceeded but w.p. P_FA
AMBIGUOUS_ARG = SENSOR_ARG + 10 * T_EARTH + 9  # fault_detected: the earth sensor or a gyro, the evidence cannot tell


def witness_state() -> np.ndarray:
    """Fresh rate-witness state (no anchor yet, so no bias change excluded; :func:`rate_witness_step_1`)."""
    return witness_state_1()


@njit(cache=True)
def witness_state_1() -> np.ndarray:
    """Compiled :func:`witness_state`."""
    s = np.zeros(WITNESS_STATE_SIZE)
    s[RW_REACH] = np.inf
    return s


@njit(cache=True)
def _rotate_by_1(v: np.ndarray, w: np.ndarray, dt: float) -> np.ndarray:
    """v seen from a frame that turned by w dt (Rodrigues, angle −|w| dt): a body-fixed vector's new components."""
    n = np.sqrt(dot3_1(w, w))
    if n * dt == 0.0:
        return v.copy()
    k = w / n
    a = -n * dt
    out: np.ndarray = v * np.cos(a) + np.cross(k, v) * np.sin(a) + k * dot3_1(k, v) * (1.0 - np.cos(a))
    return out


@njit(cache=True)
def rate_witness_step_1(
    state: np.ndarray,
    t: float,
    dt: float,
    w_gyro: np.ndarray,
    speeds: np.ndarray,
    inertia: np.ndarray,
    axes: np.ndarray,
    wheel_inertia: np.ndarray,
    tach_q: float,
    sigma_g: float,
    sigma_b: float,
    r_b: np.ndarray,
    att_bound: float,
    n_sigma: float,
    ev: np.ndarray,
    n_ev: np.ndarray,
) -> None:
    """One T_q step of the gyro-vs-dynamics test (seed 000 eq 1, seed 002 eq 13): the body momentum
    H_b = J ω + A J_r Ω̃ (Ω̃ the tachometers, relative to the body) obeys Ḣ_b = M_gg − ω × H_b, every wheel torque
    (motor, friction, seed 002 noise, a fault) being internal; from an anchor H_b = J ω̃ + A J_r Ω̃ it is propagated
    with its own body rate ω_H = J⁻¹(H_b − A J_r Ω̃) (Heun, exact rotations; a gyro fault never enters it) and the
    gravity gradient at the estimated attitude (``r_b``, the position in estimated body axes), and ρ = ω̃ − ω_H.
    ω_H's error δω = J⁻¹δH starts as the anchor sample's (white noise + Markov drift, eq 13, Gaussian:
    |δω₀| ≤ χ₃ σ_r, σ_r = √(σ_g² + σ_b²), χ₃² the χ²(3) quantile at FALSE_ALARM_PROBABILITY) and evolves as
    δḢ = δM − δω × H − ω × δH: the second term keeps E = δHᵀJ⁻¹δH (the gyroscopic coupling only turns the error),
    the third changes √E by at most ½ λ √E, λ = |ω| (J_max − J_min)/J_min, and the gravity gradient's error over the
    attitude error δ = ``att_bound``, |δM| ≤ 3μ/r³ (J_max − J_min) δ, by |δM|/√J_min; so |δω| ≤ √(E/J_min) with
    √E ≤ e^{λa/2} (√J_max |δω₀| + ∫ |δM| dt/√J_min) over the window's age a.
    A healthy gyro keeps, per axis i, |ρ_i| ≤ n_σ σ_r + √(E/J_min) + Σ_p |(J⁻¹A)_ip| J_r q (two readings ± q/2).
    Windows start every ``RW_EVERY_S`` (``RW_ANCHORS`` of them); ``CONFIRM_PERIODS`` steps beyond the bound on any
    window isolate a gyro axis (a wheel fault cannot: its torque is internal): the one with the largest ratio in the
    oldest window (a window started after the fault starts from the drifted rate, and the nutation it then predicts
    spills to the other axes). ``state[RW_REACH]``: the gyro error the oldest window allows, max_i |ρ_i| + bound_i
    (what :func:`earth_witness_check_1` weighs). Reconfiguration: from the isolation on, that oldest window alone is
    propagated and its rate ω_H replaces the isolated axis of ``w_gyro`` in place (the observer and the law read it;
    its error, the anchor sample's, is the bound's, not the drift's); no window starts any more. Not for a noisy
    gyro (the oldest window's step-to-step scatter of ρ, √2 σ_g when healthy, beyond NOISE_RATIO times that): its
    anchor sample is as noisy, so the gyro is left as it is. Torques neither modelled nor bounded here (aerodynamic,
    solar pressure, a residual dipole) must be small against J_min times the bound over 600 s."""
    isolated = state[RW_ISOLATED] != 0.0
    if isolated and state[RW_KEEP] < 0.0:
        return
    j_inv = np.linalg.inv(inertia)
    eig = np.linalg.eigvalsh(inertia)
    hw = axes @ (wheel_inertia * speeds)
    ja = j_inv @ axes
    quant = np.zeros(3)
    for i in range(3):
        for p in range(wheel_inertia.shape[0]):
            quant[i] += abs(ja[i, p]) * wheel_inertia[p] * tach_q
    hw_prev = state[RW_HWPREV : RW_HWPREV + 3].copy()
    state[RW_HWPREV : RW_HWPREV + 3] = hw
    rn = np.sqrt(dot3_1(r_b, r_b))
    m_gg = 3.0 * MU_EARTH_M3_S2 / rn**5 * np.cross(r_b, inertia @ r_b)
    gg_err = 3.0 * MU_EARTH_M3_S2 / rn**3 * (eig[2] - eig[0]) * att_bound
    sigma_r = np.sqrt(sigma_g * sigma_g + sigma_b * sigma_b)
    lam = (np.sqrt(dot3_1(w_gyro, w_gyro)) + CHI3_SIGMAS * sigma_r) * (eig[2] - eig[0]) / eig[0]
    n = int(state[RW_N])
    worst, axis, reach, oldest_age, oldest = 0.0, 0, np.inf, -1.0, 0
    for s in range(n):
        if isolated and s != int(state[RW_KEEP]):
            continue
        o = RW_A0 + s * RW_ANCHOR_SIZE
        h_old = state[o + 1 : o + 4].copy()
        w_old = j_inv @ (h_old - hw_prev)  # the witness's own body rate (Heun): no gyro in the propagation
        w_new = j_inv @ (_rotate_by_1(h_old, w_old, dt) + dt * m_gg - hw)
        h = _rotate_by_1(h_old, 0.5 * (w_old + w_new), dt) + dt * m_gg
        state[o + 1 : o + 4] = h
        state[o + 4] += dt * (0.5 * lam * state[o + 4] + gg_err / np.sqrt(eig[0]))
        rho = w_gyro - j_inv @ (h - hw)
        if isolated:  # the kept window's rate replaces the isolated axis
            w_gyro[int(state[RW_AXIS])] -= rho[int(state[RW_AXIS])]
            return
        if s == int(state[RW_HEAD]) % n:  # the oldest window (the next to be replaced): its steps' scatter
            step = rho - state[o + 5 : o + 8]
            alpha = max(dt / max(t - state[o], dt), dt / RW_INNOVATION_TAU_S)  # a mean of all steps, then running
            state[RW_SCATTER : RW_SCATTER + 3] += alpha * (step * step - state[RW_SCATTER : RW_SCATTER + 3])
        state[o + 5 : o + 8] = rho
        age = t - state[o]
        r_max, w_worst, w_axis = 0.0, 0.0, 0
        for i in range(3):
            bound = n_sigma * sigma_r + state[o + 4] / np.sqrt(eig[0]) + quant[i] + NUMERICAL_FLOOR_NMS
            r_max = max(r_max, abs(rho[i]) + bound)
            if abs(rho[i]) / bound > w_worst:
                w_worst, w_axis = abs(rho[i]) / bound, i
        worst = max(worst, w_worst)
        if age > oldest_age:
            oldest_age, reach, axis, oldest = age, r_max, w_axis, s
    if isolated:
        return
    state[RW_REACH] = reach
    if t >= state[RW_NEXT]:  # a new window starts here (it replaces the oldest)
        o = RW_A0 + int(state[RW_HEAD]) * RW_ANCHOR_SIZE
        state[o] = t
        state[o + 1 : o + 4] = inertia @ w_gyro + hw
        state[o + 4] = np.sqrt(eig[2]) * CHI3_SIGMAS * sigma_r  # √E₀ bound
        state[o + 5 : o + 8] = 0.0  # ρ = 0 at the anchor
        state[RW_HEAD] = (state[RW_HEAD] + 1.0) % RW_ANCHORS
        state[RW_N] = min(n + 1, RW_ANCHORS)
        state[RW_NEXT] = t + RW_EVERY_S
    if worst <= 1.0:
        state[RW_COUNT] = 0.0
        return
    state[RW_COUNT] += 1.0
    arg = SENSOR_ARG + 10 * T_GYRO + axis
    if state[RW_COUNT] == 1.0:
        _emit(ev, n_ev, t, EV_DETECTED, arg)
    if state[RW_COUNT] >= CONFIRM_PERIODS:
        state[RW_ISOLATED], state[RW_KEEP], state[RW_AXIS] = 1.0, oldest, axis
        if np.sqrt(0.5 * state[RW_SCATTER + axis]) > NOISE_RATIO * max(sigma_g, NUMERICAL_FLOOR_NMS):
            state[RW_KEEP] = -1.0  # a noisy gyro: its anchor sample is as noisy, no better rate to give
        else:
            o = RW_A0 + oldest * RW_ANCHOR_SIZE
            w_gyro[axis] = (j_inv @ (state[o + 1 : o + 4] - hw))[axis]
        _emit(ev, n_ev, t, EV_ISOLATED, arg)
        _emit(ev, n_ev, t, EV_RECONFIGURED, SENSOR_ARG + 10 * T_GYRO)


@njit(cache=True)
def earth_witness_check_1(
    state: np.ndarray,
    witness: np.ndarray,
    q_est: np.ndarray,
    p_cov: np.ndarray,
    nadir_b: np.ndarray,
    nadir_ref_i: np.ndarray,
    sigma_earth: float,
    k_min: float,
    k_max: float,
    dt: float,
    ev: np.ndarray,
    n_ev: np.ndarray,
    t: float,
) -> bool:
    """The earth-sensor screen (:func:`earth_sensor_check_1`) where the gyros are its only partner (seed 002's
    observer, eq 15, gains K_min..K_max): one residual for two sensors, so a rejected sample blames the earth sensor
    only when the gyro is cleared. Cleared: (a) a gyro bias explaining the estimate's error ē (the running mean ν̄ of
    the innovation over ``RW_INNOVATION_TAU_S``, less its χ²(2) noise bound) needs, in the observer's steady state, a
    bias change K_min |ē|, more than the dynamics witness allows (``RW_REACH``: seen in a window of up to 600 s,
    ≥ 4.8/K_min for the song-table1 gains); or (b) this sample's innovation less its own noise bound exceeds what the
    estimate's error can be (|ν̄| + noise + what it can move in τ: τ (reach + K_max |ν̄|)) — a jump or noise of the
    sensor itself. A gyro the witness isolated explains any slow disagreement (the sample is used), not (b) (its
    reach frozen at the isolation). Neither cleared nor
    convicted: ``fault_detected`` with AMBIGUOUS_ARG (once), the sample used (as without FDIR). True: use it."""
    ref = nadir_ref_i / np.sqrt(dot3_1(nadir_ref_i, nadir_ref_i))
    pred = conjugate_rotate_1(q_est, ref)
    d = np.cross(pred, nadir_b)
    n = witness[RW_NU_N] + 1.0
    alpha = max(1.0 / n, min(1.0, dt / RW_INNOVATION_TAU_S))
    witness[RW_NU_N] = n
    witness[RW_NU : RW_NU + 3] += alpha * (d - witness[RW_NU : RW_NU + 3])
    witness[RW_NU_V] = (1.0 - alpha) ** 2 * witness[RW_NU_V] + alpha * alpha  # variance of ν̄ in σ_e² per axis
    s2 = sigma_earth**2 + max(p_cov[0, 0], p_cov[1, 1], p_cov[2, 2])
    chi = -2.0 * np.log(FALSE_ALARM_PROBABILITY)
    if dot3_1(d, d) / s2 <= chi:
        state[ES_COUNT] = 0.0
        return True
    nu = np.sqrt(dot3_1(witness[RW_NU : RW_NU + 3], witness[RW_NU : RW_NU + 3]))
    nu_noise = np.sqrt(chi * witness[RW_NU_V]) * sigma_earth
    reach = witness[RW_REACH]
    lag = RW_INNOVATION_TAU_S * (reach + k_max * (nu + nu_noise))
    by_sample = np.sqrt(dot3_1(d, d)) - np.sqrt(chi) * sigma_earth > nu + nu_noise + lag
    if witness[RW_ISOLATED] != 0.0 and not by_sample:
        state[ES_COUNT] = 0.0
        return True
    by_mean = reach < k_min * (nu - nu_noise)
    if not (by_mean or by_sample):
        if witness[RW_AMBIGUOUS] == 0.0:
            witness[RW_AMBIGUOUS] = 1.0
            _emit(ev, n_ev, t, EV_DETECTED, AMBIGUOUS_ARG)
        state[ES_COUNT] = 0.0
        return True
    return _earth_rejected(state, ev, n_ev, t)


@njit(cache=True)
def star_reset_1(state: np.ndarray, p_cov: np.ndarray, sigma_att: float) -> None:
    """After an actuator reconfiguration (a seizing wheel kicks the body faster than the filter models), trust
    the star tracker again: clear its rejection state and open the attitude covariance to ``sigma_att``."""
    if state[SS_JUMP] == 0.0 and state[SS_ISOLATED] == 0.0:
        return
    state[SS_JUMP] = 0.0
    state[SS_COUNT] = 0.0
    state[SS_ISOLATED] = 0.0
    state[SS_Z : SS_Z + 3] = 0.0
    for i in range(3):
        p_cov[i, i] += sigma_att * sigma_att


@njit(cache=True)
def _noise_or_jump_1(
    state: np.ndarray, z: np.ndarray, p_cov: np.ndarray, sigma3: np.ndarray, ev: np.ndarray, n_ev: np.ndarray, t: float
) -> None:
    """Noise or jump? While the tracker is suspect, the scatter of *consecutive* innovation differences
    (free of the estimate's own error) over NOISE_WINDOW samples: a self-consistent tracker (scatter
    within NOISE_RATIO of its σ) is offset — a jump, keep rejecting; a scattered one is noisy: σ is
    rescaled to the scatter and the tracker trusted again (in-jump and isolated flags cleared)."""
    n = state[SS_N]
    if n == 0.0:
        state[SS_SUM : SS_SUM + 3] = 0.0
        state[SS_ZLAST : SS_ZLAST + 3] = z
        state[SS_N] = 1.0
        return
    d = z - state[SS_ZLAST : SS_ZLAST + 3]
    state[SS_ZLAST : SS_ZLAST + 3] = z
    state[SS_SUM : SS_SUM + 3] += d * d
    state[SS_N] = n + 1.0
    if n < NOISE_WINDOW:
        return
    state[SS_N] = 0.0
    worst = 1.0
    for i in range(3):
        if sigma3[i] > 0.0:
            worst = max(worst, np.sqrt(state[SS_SUM + i] / (2.0 * n)) / sigma3[i])
    if worst <= NOISE_RATIO:
        return  # self-consistent readings: an offset, keep rejecting
    state[SS_SCALE] = max(worst, state[SS_SCALE])
    state[SS_JUMP] = 0.0
    state[SS_ISOLATED] = 0.0
    state[SS_COUNT] = 0.0
    _emit(ev, n_ev, t, EV_RECONFIGURED, SENSOR_ARG + 10 * T_STAR + 1)


@njit(cache=True)
def _integrate_rate_1(q: np.ndarray, w: np.ndarray, dt: float) -> None:
    """q ← q ∘ exp(½ w dt) in place (seed 000 eq 1 kinematics over one step of constant rate)."""
    n = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    c = np.cos(0.5 * n * dt)
    k = np.sin(0.5 * n * dt) / n if n > 0.0 else 0.5 * dt
    b0, b1, b2, b3 = c, k * w[0], k * w[1], k * w[2]
    a0, a1, a2, a3 = q[0], q[1], q[2], q[3]
    q[0] = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    q[1] = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    q[2] = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    q[3] = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0


@njit(cache=True)
def gyro_drift_step_1(
    state: np.ndarray,
    t: float,
    w_meas: np.ndarray,
    dt: float,
    q_star: np.ndarray,
    star_ok: bool,
    sigma_st: float,
    sigma_g: float,
    sigma_rw: float,
    n_sigma: float,
    ev: np.ndarray,
    n_ev: np.ndarray,
) -> float:
    """One T_q step of the gyro-vs-star-tracker drift test; returns the MEKF bias process noise to use.

    Seed 002 eq 13 gyro (bias + drift + noise) against seed 000 §4 star tracker: over a window W
    the unexplained rotation d = rotvec((∫ω̃)̃ ∘ Λ̃^m_0 ∘ Λ^m) gives the mean rate error −d/W per
    axis; its noise bound is n_σ √(2σ_st²/W² + σ_g² T_q/W + σ_rw² (t − t_ref)).
    """
    if np.isnan(state[GS_T0]):
        if star_ok:
            state[GS_QINT], state[GS_QINT + 1 : GS_QINT + 4] = 1.0, 0.0
            state[GS_QST0 : GS_QST0 + 4] = q_star
            state[GS_T0] = t
            state[GS_WPREV : GS_WPREV + 3] = w_meas
        return float(state[GS_SIGMA_U])
    q_int = state[GS_QINT : GS_QINT + 4].copy()
    w_mid = 0.5 * (w_meas + state[GS_WPREV : GS_WPREV + 3])
    _integrate_rate_1(q_int, w_mid, dt)
    state[GS_QINT : GS_QINT + 4] = q_int
    state[GS_WPREV : GS_WPREV + 3] = w_meas
    width = t - state[GS_T0]
    if width < GYRO_WINDOW_S or not star_ok:
        return float(state[GS_SIGMA_U])
    rel_st = np.empty(4)
    q0 = state[GS_QST0 : GS_QST0 + 4]
    rel_st[:] = _conj_mul_1(q0, q_star)
    d = _rotvec_between_1(q_int, rel_st)
    rate_err = -d / width
    state[GS_QINT], state[GS_QINT + 1 : GS_QINT + 4] = 1.0, 0.0
    state[GS_QST0 : GS_QST0 + 4] = q_star
    state[GS_T0] = t
    n = state[GS_N]
    if n < GYRO_CALIBRATION_WINDOWS:
        state[GS_BREF : GS_BREF + 3] = (state[GS_BREF : GS_BREF + 3] * n + rate_err) / (n + 1.0)
        state[GS_N] = n + 1.0
        state[GS_TREF] = t
        return float(state[GS_SIGMA_U])
    elapsed = t - state[GS_TREF]
    noise = np.sqrt(
        2.0 * sigma_st * sigma_st / (width * width)
        + sigma_g * sigma_g * dt / width
        + sigma_rw * sigma_rw * elapsed
        + sigma_g * sigma_g * dt / (width * GYRO_CALIBRATION_WINDOWS)
    )
    change = rate_err - state[GS_BREF : GS_BREF + 3]
    worst, axis = 0.0, 0
    for i in range(3):
        if abs(change[i]) > worst:
            worst, axis = abs(change[i]), i
    if worst <= n_sigma * noise:
        state[GS_COUNT] = 0.0
        return float(state[GS_SIGMA_U])
    state[GS_COUNT] += 1.0
    arg = SENSOR_ARG + 10 * T_GYRO + axis
    if state[GS_COUNT] == 1.0 and state[GS_ISOLATED] == 0.0:
        _emit(ev, n_ev, t, EV_DETECTED, arg)
    if state[GS_COUNT] >= CONFIRM_PERIODS and state[GS_ISOLATED] == 0.0:
        state[GS_ISOLATED] = 1.0
        state[GS_SIGMA_U] = max(state[GS_SIGMA_U], worst / np.sqrt(max(elapsed, width)))
        _emit(ev, n_ev, t, EV_ISOLATED, arg)
        _emit(ev, n_ev, t, EV_RECONFIGURED, SENSOR_ARG + 10 * T_GYRO)
    return float(state[GS_SIGMA_U])


@njit(cache=True)
def _conj_mul_1(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """ã ∘ b for unit quaternions."""
    a0, a1, a2, a3 = a[0], -a[1], -a[2], -a[3]
    out = np.empty(4)
    out[0] = a0 * b[0] - a1 * b[1] - a2 * b[2] - a3 * b[3]
    out[1] = a0 * b[1] + a1 * b[0] + a2 * b[3] - a3 * b[2]
    out[2] = a0 * b[2] - a1 * b[3] + a2 * b[0] + a3 * b[1]
    out[3] = a0 * b[3] + a1 * b[2] - a2 * b[1] + a3 * b[0]
    return out


@njit(cache=True)
def magnetometer_check_1(
    state: np.ndarray,
    b_meas: np.ndarray,
    b_model: np.ndarray,
    sigma_mag: float,
    n_sigma: float,
    ev: np.ndarray,
    n_ev: np.ndarray,
    t: float,
) -> bool:
    """Screen one magnetometer sample by its magnitude against the model's; replace a spike in place.

    Seed 003 eq 26 field B: | |B̃| − |B_model| | ≤ n_σ σ_mag + model error holds whatever the attitude
    (so an attitude-sensor fault is not blamed on the magnetometer); ``b_model`` is the model field
    rotated into body axes by the estimated attitude, used to name the axis and as the replacement.
    Returns True if the sample was accepted.
    """
    model = np.sqrt(b_model[0] ** 2 + b_model[1] ** 2 + b_model[2] ** 2)
    meas = np.sqrt(b_meas[0] ** 2 + b_meas[1] ** 2 + b_meas[2] ** 2)
    if abs(meas - model) <= n_sigma * sigma_mag + MAG_MODEL_ERROR_T:
        return True
    if np.isnan(state[MS_LAST]) or t - state[MS_LAST] > MAG_REARM_S:
        worst, axis = 0.0, 0
        for i in range(3):
            if abs(b_meas[i] - b_model[i]) > worst:
                worst, axis = abs(b_meas[i] - b_model[i]), i
        arg = SENSOR_ARG + 10 * T_MAG + axis
        _emit(ev, n_ev, t, EV_DETECTED, arg)
        _emit(ev, n_ev, t, EV_ISOLATED, arg)
        _emit(ev, n_ev, t, EV_RECONFIGURED, SENSOR_ARG + 10 * T_MAG)
    state[MS_LAST] = t
    b_meas[:] = b_model
    return False


def wheel_residuals(
    speed_rad_s: np.ndarray,
    torque_nm: np.ndarray,
    inertia_kg_m2: np.ndarray,
    friction: np.ndarray,
    tach_quantum_rad_s: float,
    control_dt_s: float,
    axial_rate_rad_s: np.ndarray | None = None,
    rate_noise_rad_s: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Residuals r_p and their healthy bounds × WHEEL_SAFETY for sampled tachometer data (seed 000 eq 1).

    ``speed_rad_s`` (n_samples, n_wheels) at the control instants (relative to the body),
    ``axial_rate_rad_s`` the body rate about each spin axis a_pᵗ ω at the same instants (default 0),
    ``torque_nm`` (n_samples − 1, n_wheels) the limited torque held over each period; ``friction`` the
    (4, n_wheels) table of
    :meth:`sim_core.wheels.WheelParams.friction_table`. Returns two (n_samples − 1, n_wheels) arrays, N·m·s.
    """
    w = np.asarray(speed_rad_s, dtype=float)
    m = np.asarray(torque_nm, dtype=float)
    j = np.asarray(inertia_kg_m2, dtype=float)
    f = np.ascontiguousarray(friction, dtype=float)
    if w.ndim != 2 or w.shape[0] < 2:
        raise ValueError("speed_rad_s: expected (n_samples ≥ 2, n_wheels)")
    if m.shape != (w.shape[0] - 1, w.shape[1]):
        raise ValueError(f"torque_nm: expected shape {(w.shape[0] - 1, w.shape[1])}, got {m.shape}")
    if j.shape != (w.shape[1],) or np.any(j <= 0):
        raise ValueError("inertia_kg_m2: expected one positive inertia per wheel")
    if f.shape != (4, w.shape[1]):
        raise ValueError("friction: expected the (4, n_wheels) friction table")
    if not (tach_quantum_rad_s >= 0.0 and control_dt_s > 0.0 and rate_noise_rad_s >= 0.0):
        raise ValueError("tach_quantum_rad_s, control_dt_s, rate_noise_rad_s: must be ≥ 0, > 0, ≥ 0")
    axial = np.zeros_like(w) if axial_rate_rad_s is None else np.asarray(axial_rate_rad_s, dtype=float)
    if axial.shape != w.shape:
        raise ValueError(f"axial_rate_rad_s: expected shape {w.shape}, got {axial.shape}")
    return _residual_table(w, axial, m, j, f, float(tach_quantum_rad_s), float(rate_noise_rad_s), float(control_dt_s))


@njit(cache=True)
def _residual_table(
    w: np.ndarray,
    axial: np.ndarray,
    m: np.ndarray,
    j: np.ndarray,
    f: np.ndarray,
    q: float,
    rate_noise: float,
    t_u: float,
) -> tuple[np.ndarray, np.ndarray]:
    n, nw = m.shape
    r, b = np.empty((n, nw)), np.empty((n, nw))
    for k in range(n):
        for p in range(nw):
            r[k, p] = wheel_residual_1(j[p], w[k, p], w[k + 1, p], axial[k + 1, p] - axial[k, p], m[k, p], t_u, f, p)
            b[k, p] = WHEEL_SAFETY * wheel_bound_1(j[p], w[k, p], w[k + 1, p], q, rate_noise, t_u, f, p)
    return r, b


def observable_time(
    t_s: np.ndarray,
    torque_cmd_nm: np.ndarray,
    torque_nm: np.ndarray,
    onset_s: float,
    inertia_kg_m2: float,
    tachometer_quantum_rad_s: float,
    noise_nms: float = 0.0,
    control_dt_s: float = 1.0,
) -> float | None:
    """When a wheel fault becomes observable: the first sample time t at which the momentum it withheld over some
    window [t₁, t] after ``onset_s``, |∫ (m_cmd − m_delivered) dt| from t₁ to t, reaches one tachometer quantum of
    momentum J_r q plus the noise-momentum bound over the window, ``noise_nms`` √((t − t₁)/T_u) (``noise_nms`` the
    bound over one control period ``control_dt_s``, :func:`wheel_noise_bound` at the false-alarm probability of
    one test; 0 without seed 002's noise torque): before that, quantisation and noise can make the readings of a
    healthy wheel show as much over every window. ``torque_nm`` is the motor torque without the noise. None if it
    never does. Series sampled uniformly at ``t_s``."""
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0.0):
        raise ValueError("t_s: expected at least two increasing sample times")
    if not (noise_nms >= 0.0 and control_dt_s > 0.0):
        raise ValueError("noise_nms, control_dt_s: expected ≥ 0 and > 0")
    after = t >= onset_s
    gap = np.asarray(torque_cmd_nm, dtype=float)[after] - np.asarray(torque_nm, dtype=float)[after]
    dt = t[1] - t[0]
    withheld = np.concatenate([[0.0], np.cumsum(gap) * dt])  # withheld[k]: over the first k samples after the onset
    quantum = inertia_kg_m2 * tachometer_quantum_rad_s
    for k, now in enumerate(t[after], start=1):
        floor = quantum + noise_nms * np.sqrt((k - np.arange(k)) * dt / control_dt_s)  # windows of k − j samples
        if np.any(np.abs(withheld[k] - withheld[:k]) >= floor):
            return float(now)
    return None


_TARGET_NAMES = {1: "gyro", 2: "star_tracker", 3: "earth_sensor", 4: "magnetometer"}


def describe_event(name: str, arg: int) -> str:
    """Human-readable subject of an FDIR event argument (wheel index, sensor axis, or wheel mask)."""
    if arg >= SENSOR_ARG:
        code, axis = divmod(arg - SENSOR_ARG, 10)
        sensor = _TARGET_NAMES.get(code, f"sensor {code}")
        if arg == AMBIGUOUS_ARG:
            return "earth_sensor or gyro (the evidence cannot tell which: none isolated)"
        return sensor if name == "reconfigured" or code in (T_STAR, T_EARTH) else f"{sensor} axis {'xyz'[axis]}"
    if name == "reconfigured":
        wheels = [str(p + 1) for p in range(8) if arg >> p & 1]
        return "wheels " + ",".join(wheels) if wheels else "no wheels"
    if name == "mode_change":
        return f"mode {arg}"
    if name == "reconfiguration_refused":
        p, status = arg % 10, arg // 10
        return f"wheel {p + 1} kept: without it the allocation status would be {status}"
    return f"wheel {arg + 1}"
