"""FDIR kernels against independent truths: the exact solution of a wheel with viscous and dry
friction, the tachometer quantisation bound, χ² statistics of the star-tracker innovation, and
constant-rate kinematics for the gyro drift test; then the closed loop (detection delay, isolation
in all single-wheel cases and over random onsets, no false alarm in 24 h of nominal flight)."""

import numpy as np
import pytest

from sim_core import allocation, fdir
from sim_core.wheels import WheelParams, noise_torque

J_HR12 = 12.0 / (6000.0 * np.pi / 30.0)  # HR12 rotor inertia, kg·m²
T_U = 2.0  # seed 000 §5 control period
TACH_Q = 2 * np.pi / 60.0 * 0.1  # 0.1 rpm tachometer resolution, rad/s
VISCOUS = 2e-5  # N·m·s: ~0.013 N·m at 6,000 rpm, an HR12-class drag
COULOMB = 2e-3  # N·m dry friction
SAT_SPEED = 1.0  # rad/s, the dry-friction smoothing speed
N_TRIALS = 4000
W0 = np.zeros(3)  # body at rest: the tachometer reads the absolute spin
AXES4 = np.eye(3)[:, [0, 1, 2, 0]].copy()
# a body too heavy to turn: J, J_e⁻¹, MD torque, disturbance and rate-noise bounds, T_u
RIGID = (np.eye(3) * 1e12, np.eye(3) * 1e-12, np.zeros(3), 0.0, 0.0, T_U)
B_ORBIT = np.array([3e-5, 0.0, 0.0])  # magnetometer reading, T
ALLOC = allocation.AllocationConfig(law4=allocation.LAW_PSEUDO_INVERSE).as_array()
CLUSTER4 = (AXES4, np.zeros(4), B_ORBIT, ALLOC)  # wheel_check_1's allocation arguments for AXES4


def _friction() -> np.ndarray:
    w = WheelParams(np.array([J_HR12]), coulomb_nm=COULOMB, coulomb_sat_speed_rad_s=SAT_SPEED, viscous_nm_s=VISCOUS)
    return w.friction_table()


def _exact_speed(w0: float, m: float, t: float, sign: float) -> float:
    """Ω(t) of J Ω̇ = m − m_f sign − c Ω with the dry friction saturated (|Ω| > Ω° all along)."""
    tau = J_HR12 / VISCOUS
    w_inf = (m - COULOMB * sign) / VISCOUS
    return w_inf + (w0 - w_inf) * np.exp(-t / tau)


def test_healthy_wheel_residual_stays_inside_bound_for_exact_friction_solution():
    rng = np.random.default_rng(1)
    friction = _friction()
    worst = 0.0
    for _ in range(N_TRIALS):
        w0 = rng.uniform(5.0, 500.0) * rng.choice([-1.0, 1.0])
        m = rng.uniform(-0.2, 0.2)
        w1 = _exact_speed(w0, m, T_U, np.sign(w0))
        if np.sign(w1) != np.sign(w0) or abs(w1) < SAT_SPEED:
            continue
        read0, read1 = TACH_Q * np.round(w0 / TACH_Q), TACH_Q * np.round(w1 / TACH_Q)
        r = fdir.wheel_residual_1(J_HR12, read0, read1, 0.0, m, T_U, friction, 0)
        bound = fdir.wheel_bound_1(J_HR12, read0, read1, TACH_Q, 0.0, T_U, friction, 0)
        worst = max(worst, abs(r) / bound)
    assert worst <= 1.0


def test_quantisation_alone_never_exceeds_j_q():
    rng = np.random.default_rng(2)
    w0 = rng.uniform(-600, 600, N_TRIALS)
    m = rng.uniform(-0.2, 0.2, N_TRIALS)
    w1 = w0 + m * T_U / J_HR12
    r0, r1 = TACH_Q * np.round(w0 / TACH_Q), TACH_Q * np.round(w1 / TACH_Q)
    res, bound = fdir.wheel_residuals(
        np.stack([r0, r1]), m[None, :], np.full(N_TRIALS, J_HR12), np.zeros((4, N_TRIALS)), TACH_Q, T_U
    )
    assert np.max(np.abs(res)) <= J_HR12 * TACH_Q + fdir.NUMERICAL_FLOOR_NMS
    assert np.all(np.abs(res) <= bound / fdir.WHEEL_SAFETY)


def test_dead_motor_residual_is_the_missing_momentum():
    friction = np.zeros((4, 1))
    m = 0.01
    r = fdir.wheel_residual_1(J_HR12, 100.0, 100.0, 0.0, m, T_U, friction, 0)  # motor delivered nothing
    assert r == pytest.approx(-m * T_U, rel=1e-12)


def test_body_spinning_about_an_idle_wheel_is_no_residual():
    """Torque-free wheel: J(Ω + aᵗω) is conserved, so the tachometer sees −Δ(aᵗω), which is no fault."""
    axial = np.array([0.0, 0.01])
    speed = 300.0 - axial  # relative speed falls as the body spins up about the axis
    res, bound = fdir.wheel_residuals(
        speed[:, None], np.zeros((1, 1)), [J_HR12], np.zeros((4, 1)), 0.0, T_U, axial_rate_rad_s=axial[:, None]
    )
    assert abs(res[0, 0]) <= bound[0, 0]
    res_blind, _ = fdir.wheel_residuals(speed[:, None], np.zeros((1, 1)), [J_HR12], np.zeros((4, 1)), 0.0, T_U)
    assert abs(res_blind[0, 0]) > 1e3 * bound[0, 0]


def _hold(state: np.ndarray, speeds: np.ndarray, torque: float) -> None:
    """fdir.wheel_hold_1 for four frictionless HR12 wheels on AXES4 holding ``torque``, body at rest."""
    j, zeros = np.full(4, J_HR12), np.zeros((4, 4))
    fdir.wheel_hold_1(state, speeds, W0, AXES4, np.full(4, torque), j, np.full(4, 0.2), np.full(4, 12.0), zeros, *RIGID)


def _check(
    state: np.ndarray,
    speeds: np.ndarray,
    noise_sigma: np.ndarray,
    available: np.ndarray,
    ev: np.ndarray,
    n_ev: np.ndarray,
    t: float,
    tach_q: float = TACH_Q,
) -> None:
    """fdir.wheel_check_1 on the same four wheels, read by a ``tach_q`` tachometer, noise σ_N per wheel and period."""
    j, zeros = np.full(4, J_HR12), np.zeros((4, 4))
    fdir.wheel_check_1(
        state, speeds, W0, j, np.full(4, 12.0), zeros, tach_q, noise_sigma, T_U, np.eye(4), available, *CLUSTER4,
        ev, n_ev, t,
    )  # fmt: skip


def _check_sequence(deltas_nms: list[float], torque: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    state = fdir.wheel_state(4)
    speeds = np.full(4, 100.0)
    available = np.ones(4, dtype=np.bool_)
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    for k, dh in enumerate(deltas_nms):
        _hold(state, speeds, torque)
        speeds = speeds + torque * T_U / J_HR12
        speeds[2] += dh / J_HR12
        _check(state, speeds, np.zeros(4), available, ev, n_ev, (k + 1) * T_U)
    return available, ev[: n_ev[0]], state


def test_two_periods_beyond_bound_isolate_the_wheel_and_drop_it():
    big = 10 * J_HR12 * TACH_Q
    available, ev, _ = _check_sequence([0.0, big, big])
    assert list(available) == [True, True, False, True]
    assert [tuple(e[1:]) for e in ev] == [(4, 2), (5, 2), (6, 0b1011)]
    assert ev[1, 0] == 3 * T_U


def test_single_exceedance_is_a_transient_not_an_isolation():
    """A reading off by 1.5 quanta of momentum and back: the windows ending at it (one quantum, exact) see it for
    one period (a detection), the per-period test (2 × (quantum + rest)) never; afterwards only the windows
    starting at the wrong reading see it, not those straddling it: momentum given back is no fault."""
    glitch = 1.5 * J_HR12 * TACH_Q
    available, ev, _ = _check_sequence([0.0, 0.0, glitch, -glitch, 0.0, 0.0])
    assert available.all()
    assert set(ev[:, 1]) == {4}


def test_momentum_that_stays_missing_is_isolated_though_each_period_is_inside_its_bound():
    """Half a quantum of momentum missing each period: no single period exceeds, the accumulated sum does."""
    available, ev, _ = _check_sequence([-0.5 * J_HR12 * TACH_Q] * 6)
    assert list(available) == [True, True, False, True]
    assert [tuple(e[1:]) for e in ev][:2] == [(4, 2), (5, 2)]


def _gain_loss(
    axes: np.ndarray, gain: float, b_field: np.ndarray, l_max_am2: float = 25.0, later: tuple[float, ...] = ()
) -> tuple[np.ndarray, list]:
    """Availability and events after three periods in which every wheel holds 0.05 N·m and the last one delivers
    ``gain`` of it, then one period per entry of ``later`` delivering that share (frictionless HR12 wheels, 0.1 rpm
    tachometer, rigid body)."""
    nw, torque = axes.shape[1], 0.05
    state, speeds = fdir.wheel_state(nw), np.full(nw, 100.0)
    available = np.ones(nw, dtype=np.bool_)
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    params = allocation.AllocationConfig(law4=allocation.LAW_PSEUDO_INVERSE, l_max_am2=l_max_am2).as_array()
    j, zeros = np.full(nw, J_HR12), np.zeros((4, nw))
    for k, share in enumerate((gain, gain, gain) + later):
        fdir.wheel_hold_1(state, speeds, W0, axes, np.full(nw, torque), j, np.full(nw, 0.2), np.full(nw, 12.0), zeros,
                          *RIGID)  # fmt: skip
        speeds = speeds + torque * T_U / J_HR12
        speeds[-1] -= (1.0 - share) * torque * T_U / J_HR12
        fdir.wheel_check_1(
            state, speeds, W0, j, np.full(nw, 12.0), zeros, TACH_Q, np.zeros(nw), T_U, np.eye(nw), available, axes,
            j * speeds, b_field, params, ev, n_ev, (k + 1) * T_U,
        )  # fmt: skip
    return available, [(int(e[1]), int(e[2])) for e in ev[: n_ev[0]]]


ORTHOGONAL3 = np.eye(3)
B_ALONG_PAIR = np.array([3e-5, 3e-5, 0.0]) / np.sqrt(2.0)  # κ = ⟨e_12, b⟩ = 1 > 1/2: MD refused for wheels 1, 2
B_ACROSS_PAIR = np.array([3e-5, -3e-5, 0.0]) / np.sqrt(2.0)  # κ = 0, e^m = b × e_12 along wheel 3's axis


def test_partly_working_wheel_stays_in_the_loop_when_the_rest_cannot_give_three_axis_torque():
    """70 % of wheel 3's torque lost (seed 002's multiplicative fault) on three orthogonal wheels: isolated, but
    wheels 1 + 2 with the MD refused by κ (or no MD at all) give no torque about z, so it stays, with the reason."""
    available, ev = _gain_loss(ORTHOGONAL3, 0.3, B_ALONG_PAIR)
    assert available.all()
    assert ev == [(4, 2), (5, 2), (10, 2 + 10 * allocation.STATUS_KAPPA_REFUSED)]
    available, ev = _gain_loss(ORTHOGONAL3, 0.3, B_ACROSS_PAIR, l_max_am2=0.0)
    assert available.all() and ev[-1] == (10, 2 + 10 * allocation.STATUS_NO_DRIVER)


def test_kept_partly_working_wheel_stays_monitored_and_its_later_death_drops_it():
    """The kept 30 % wheel (973f486) is monitored against the share it still delivers: ten more periods at 30 % raise
    nothing; when it then dies (delivers nothing) it is detected and isolated again and dropped, though wheels 1 + 2
    cannot fly z — a dead wheel gives nothing to keep; the rest still counts two wheels, so no fault mode."""
    refused = (10, 2 + 10 * allocation.STATUS_KAPPA_REFUSED)
    available, ev = _gain_loss(ORTHOGONAL3, 0.3, B_ALONG_PAIR, later=(0.3,) * 10)
    assert available.all() and ev == [(4, 2), (5, 2), refused]
    available, ev = _gain_loss(ORTHOGONAL3, 0.3, B_ALONG_PAIR, later=(0.3,) * 10 + (0.0,) * 3)
    assert list(available) == [True, True, False]
    assert ev == [(4, 2), (5, 2), refused, (4, 2), (5, 2), (6, 0b011)]


def test_partly_working_wheel_is_dropped_where_the_rest_can_still_control():
    """The same loss with the MD's condition met (two wheels + MD), or on four wheels of rank 3 without it."""
    available, ev = _gain_loss(ORTHOGONAL3, 0.3, B_ACROSS_PAIR)
    assert list(available) == [True, True, False] and ev[-1] == (6, 0b011)
    skew4 = np.column_stack([np.eye(3), np.ones(3) / np.sqrt(3.0)])
    available, ev = _gain_loss(skew4, 0.3, B_ALONG_PAIR)
    assert list(available) == [True, True, True, False] and ev[-1] == (6, 0b0111)


def test_dead_wheel_is_dropped_even_where_the_rest_cannot_give_three_axis_torque():
    """A motor delivering nothing (gain 0) is no partial loss: dropped as before, whatever the rest can do."""
    available, ev = _gain_loss(ORTHOGONAL3, 0.0, B_ALONG_PAIR)
    assert list(available) == [True, True, False] and ev[-1] == (6, 0b011)


def test_healthy_sequence_raises_nothing():
    available, ev, _ = _check_sequence([0.0] * 20, torque=0.05)
    assert available.all() and ev.shape[0] == 0


def test_fewer_than_two_wheels_is_the_fault_mode():
    state = fdir.wheel_state(3)
    available = np.array([True, True, False])
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    j, zeros = np.full(3, J_HR12), np.zeros((4, 3))
    speeds = np.full(3, 50.0)
    faulty = False
    for k in range(3):
        fdir.wheel_hold_1(
            state,
            speeds,
            W0,
            AXES4[:, :3],
            np.array([0.1, 0.0, 0.0]),
            j,
            np.full(3, 0.2),
            np.full(3, 12.0),
            zeros,
            *RIGID,
        )
        faulty = fdir.wheel_check_1(
            state,
            speeds,
            W0,
            j,
            np.full(3, 12.0),
            zeros,
            0.0,
            np.zeros(3),
            T_U,
            np.eye(3),
            available,
            AXES4[:, :3],
            np.zeros(3),
            B_ORBIT,
            ALLOC,
            ev,
            n_ev,
            k * T_U,
        )
    assert faulty
    assert (1, 4) in [(int(e[1]), int(e[2])) for e in ev[: n_ev[0]]]  # mode_change → MODE_FAULT (4)


def test_wheel_near_momentum_limit_is_not_tested():
    state = fdir.wheel_state(1)
    j = np.array([J_HR12])
    speeds = np.array([11.99 / J_HR12])
    available = np.ones(1, dtype=np.bool_)
    ev, n_ev = np.zeros((4, 3)), np.zeros(1, dtype=np.int64)
    for k in range(3):
        fdir.wheel_hold_1(
            state,
            speeds,
            W0,
            AXES4[:, :1],
            np.array([0.2]),
            j,
            np.array([0.2]),
            np.array([12.0]),
            np.zeros((4, 1)),
            *RIGID,
        )
        fdir.wheel_check_1(
            state,
            speeds,
            W0,
            j,
            np.array([12.0]),
            np.zeros((4, 1)),
            0.0,
            np.zeros(1),
            T_U,
            np.eye(1),
            available,
            AXES4[:, :1],
            np.zeros(1),
            B_ORBIT,
            ALLOC,
            ev,
            n_ev,
            k * T_U,
        )
    assert available[0] and n_ev[0] == 0


def test_noise_momentum_bound_matches_seed002_noise_drawn_by_the_wheel_model():
    """Seed 002 eq 4's M_x drawn by sim_core.wheels.noise_torque once per 0.05 s step: the momentum of one 2 s
    period has the standard deviation K_x √(τ T_u/3) the bound is built on, and exceeds the bound (here at a
    measurable probability, 1e-3) no more often than that probability, for one period and for 50 periods."""
    k_x, tau, n_steps, n_periods, n_wheels = 1e-4, 0.05, 40, 50, 2000
    wheels = WheelParams(np.full(n_wheels, J_HR12), noise_nm=k_x)  # many wheels: one draw per wheel and step
    rng = np.random.default_rng(7)
    steps = np.stack([noise_torque(wheels, rng) for _ in range(n_steps * n_periods)])
    periods = steps.reshape(n_periods, n_steps, n_wheels).sum(axis=1) * tau  # momentum of each period and wheel
    assert periods.std() == pytest.approx(k_x * np.sqrt(tau * T_U / 3.0), rel=0.02)
    bound = fdir.wheel_noise_bound(np.array([k_x]), tau, T_U, probability=1e-3)[0]
    assert np.mean(np.abs(periods) > bound) <= 1e-3
    windows = periods.sum(axis=0)  # 50 periods of each wheel
    assert np.mean(np.abs(windows) > bound * np.sqrt(n_periods)) <= 1e-3 + 3 * np.sqrt(1e-3 / n_wheels)
    with pytest.raises(ValueError, match="sample_s"):
        fdir.wheel_noise_bound(np.array([k_x]), 3.0, T_U)


K_X, TAU = 1e-4, 0.05  # seed 002 eq 4 noise torque of song-table1's wheels, drawn every 0.05 s dynamics step


def _noisy_check(
    losses_nms: np.ndarray, torque: float, rng: np.random.Generator, tach_q: float = TACH_Q
) -> tuple[np.ndarray, np.ndarray]:
    """Four wheels at a held ``torque`` with seed 002's noise torque drawn by sim_core.wheels every τ, read by a
    ``tach_q`` tachometer (0: perfect), wheel 3 losing ``losses_nms[k]`` of momentum in period k; the wheel check
    told the noise σ_N (fdir.wheel_noise_sigma). Returns the availability and the events."""
    wheels = WheelParams(np.full(4, J_HR12), noise_nm=K_X)
    state, available = fdir.wheel_state(4), np.ones(4, dtype=np.bool_)
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    noise_sigma = fdir.wheel_noise_sigma(np.full(4, K_X), TAU, T_U)
    true = np.full(4, 100.0)
    steps = int(round(T_U / TAU))

    def read(speed: np.ndarray) -> np.ndarray:
        return speed.copy() if tach_q == 0.0 else tach_q * np.round(speed / tach_q)

    for k, loss in enumerate(losses_nms):
        _hold(state, read(true), torque)
        kicks = sum(noise_torque(wheels, rng) for _ in range(steps)) * TAU
        true = true + (torque * T_U + kicks) / J_HR12
        true[2] -= loss / J_HR12
        _check(state, read(true), noise_sigma, available, ev, n_ev, (k + 1) * T_U, tach_q)
    return available, ev[: n_ev[0]]


def test_healthy_wheels_under_seed002_noise_raise_nothing_in_2000_periods():
    """Seed 002's noise momentum walks a wheel's window sums by σ √n (σ = K_x √(τ T_u/3) per period): over 2000
    periods (67 min, 4 wheels) neither the windows nor the CUSUM, each at P_FA per period, raise anything."""
    available, ev = _noisy_check(np.zeros(2000), 0.01, np.random.default_rng(11))
    assert available.all() and ev.shape[0] == 0


def test_weak_loss_beyond_the_windows_is_isolated_by_the_cusum_when_its_bound_says():
    """A wheel losing 0.5 σ of momentum per period (σ the noise momentum's, seed 002 eq 4): no window of up to
    WINDOW_PERIODS reaches its bound J q + a √n, but the loss outgrows the CUSUM's drift ν = σ/4: the statistic
    (k − j)(0.5σ − ν) + rounding (≤ J q) + noise N crosses J q + h, h = σ ln(2/P_FA)/(2 · 1/4) (Ville's
    inequality), between (h − 4σ√k)/(0.5σ − ν) and (2 J q + h + 4σ√k)/(0.5σ − ν) periods (|N| ≤ 4σ√k); the
    healthy wheels stay. The wheel still delivers its torque, and wheels x, y, x cannot replace its z: it stays in
    the allocation (reconfiguration refused, the three left singular)."""
    sigma = K_X * np.sqrt(TAU * T_U / 3.0)
    loss = 0.5 * sigma
    a = fdir.wheel_noise_bound(np.array([K_X]), TAU, T_U)[0]
    n = np.arange(1, fdir.WINDOW_PERIODS + 1)
    assert np.all(loss * n < J_HR12 * TACH_Q + a * np.sqrt(n))  # beyond every window's reach
    rate = loss - fdir.CUSUM_DRIFT_SIGMAS * sigma
    h = sigma * np.log(2.0 / fdir.FALSE_ALARM_PROBABILITY) / (2.0 * fdir.CUSUM_DRIFT_SIGMAS)
    latest = (2.0 * J_HR12 * TACH_Q + h + 4.0 * sigma * np.sqrt(700.0)) / rate
    assert latest < 700.0
    available, ev = _noisy_check(np.full(int(latest) + 2, loss), 0.01, np.random.default_rng(12))
    isolated = [e for e in ev if e[1] == 5]
    assert [int(e[2]) for e in isolated] == [2]
    assert available.all() and (10, 2 + 10 * allocation.STATUS_SINGULAR) in [tuple(e[1:]) for e in ev]
    k = isolated[0][0] / T_U
    assert (h - 4.0 * sigma * np.sqrt(k)) / rate <= k - 1 <= latest


def test_perfect_tachometer_under_noise_sums_the_windows():
    """A perfect tachometer leaves each window the noise floor a √n alone (no quantum): a wheel withholding w = a/2
    per period, below the one-period test's a, is isolated once w k outgrows the floor and the noise, |N| ≤ 4σ√k:
    by k = ((a + 4σ)/w)² periods, + 1 for the longer window and + 1 to confirm (with J q = 0 the history used to
    restart every period, leaving only the one-period test, which such a loss never trips), and kept in the
    allocation as in the CUSUM test; the healthy wheels stay through 2000 periods."""
    sigma = fdir.wheel_noise_sigma(np.array([K_X]), TAU, T_U)[0]
    assert sigma == pytest.approx(K_X * np.sqrt(TAU * T_U / 3.0), rel=1e-12)
    a = fdir.wheel_noise_bound(np.array([K_X]), TAU, T_U)[0]
    loss = 0.5 * a
    latest = ((a + 4.0 * sigma) / loss) ** 2 + 2.0
    available, ev = _noisy_check(np.full(int(latest) + 2, loss), 0.01, np.random.default_rng(13), tach_q=0.0)
    isolated = [e for e in ev if e[1] == 5]
    assert [int(e[2]) for e in isolated] == [2] and isolated[0][0] / T_U <= latest
    assert available.all() and (10, 2 + 10 * allocation.STATUS_SINGULAR) in [tuple(e[1:]) for e in ev]
    available, ev = _noisy_check(np.zeros(2000), 0.01, np.random.default_rng(14), tach_q=0.0)
    assert available.all() and ev.shape[0] == 0


SIGMA_ST = 3.0 / 206265.0  # 3″ star tracker (seed 000 §5)
N_SAMPLES_CHI2 = 20000


def _star_sample(rng, q, sigma):
    from sim_core.sensors import star_tracker_1

    qm, _ = star_tracker_1(q, np.zeros(3), np.full(3, sigma), 1.0, rng.standard_normal(3))
    return qm


def test_star_tracker_innovation_is_chi2_and_consistent_samples_are_accepted():
    """Estimate and sample both scattered as P and R say: the NIS follows scipy's χ²(3) (KS p > 0.01)
    and the FDIR rejects none of 20,000 samples."""
    from scipy.stats import chi2, kstest

    rng = np.random.default_rng(3)
    q = np.array([0.9, 0.1, -0.3, 0.2])
    q /= np.linalg.norm(q)
    p = np.diag([SIGMA_ST**2] * 3 + [1e-12] * 3)
    sig = np.full(3, SIGMA_ST)
    ev, n_ev = np.zeros((8, 3)), np.zeros(1, dtype=np.int64)
    state, nis_max = fdir.star_state(), fdir.star_nis_threshold()
    nis, accepted = [], 0
    for i in range(N_SAMPLES_CHI2):
        q_est, q_meas = _star_sample(rng, q, SIGMA_ST), _star_sample(rng, q, SIGMA_ST)
        nis.append(fdir.star_innovation_1(q_est, p, q_meas, sig)[1])
        accepted += fdir.star_tracker_check_1(state, q_est, p, q_meas, sig, nis_max, False, ev, n_ev, float(i)) > 0
    assert kstest(nis, chi2(3).cdf).pvalue > 0.01
    assert accepted == N_SAMPLES_CHI2


def test_star_tracker_jump_and_freeze_are_rejected_and_isolated():
    rng = np.random.default_rng(4)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    p = np.diag([SIGMA_ST**2] * 3 + [1e-12] * 3)
    sig = np.full(3, SIGMA_ST)
    nis_max = fdir.star_nis_threshold()
    state = fdir.star_state()
    ev, n_ev = np.zeros((8, 3)), np.zeros(1, dtype=np.int64)
    jump = np.array([np.cos(0.5 * 20 * SIGMA_ST), np.sin(0.5 * 20 * SIGMA_ST), 0.0, 0.0])
    assert not fdir.star_tracker_check_1(state, q, p, jump, sig, nis_max, False, ev, n_ev, 1.0)
    assert not fdir.star_tracker_check_1(state, q, p, jump, sig, nis_max, False, ev, n_ev, 2.0)  # and frozen
    names = [int(e[1]) for e in ev[: n_ev[0]]]
    assert names == [4, 5, 6] and int(ev[0, 2]) == fdir.SENSOR_ARG + 10 * 2
    slow = fdir.star_state()  # the same offset reached gradually is no jump: left to the gyro-drift test
    for i in range(1, 41):
        offset = 20 * SIGMA_ST * i / 40
        grown = np.array([np.cos(0.5 * offset), np.sin(0.5 * offset), 0.0, 0.0])
        assert fdir.star_tracker_check_1(slow, q, p, grown, sig, nis_max, False, ev, n_ev, 10.0 + i)
    state = fdir.star_state()
    sample = _star_sample(rng, q, SIGMA_ST)
    assert fdir.star_tracker_check_1(state, q, p, sample, sig, nis_max, False, ev, n_ev, 3.0)
    assert not fdir.star_tracker_check_1(state, q, p, sample.copy(), sig, nis_max, False, ev, n_ev, 3.25)


def test_tenfold_star_tracker_noise_is_rescaled_not_locked_out():
    """Seed 002's 10σ: unbiased innovations are noise, so σ is rescaled to their scatter (≈ 10, within
    the 20-sample estimate) and the sensor used again; a 60″ offset stays a jump."""
    rng = np.random.default_rng(7)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    p = np.diag([SIGMA_ST**2] * 3 + [1e-12] * 3)
    sig = np.full(3, SIGMA_ST)
    ev, n_ev = np.zeros((32, 3)), np.zeros(1, dtype=np.int64)
    state, nis_max = fdir.star_state(), fdir.star_nis_threshold()
    scales = [
        fdir.star_tracker_check_1(
            state, q, p, _star_sample(rng, q, 10 * SIGMA_ST), sig, nis_max, False, ev, n_ev, 0.25 * i
        )
        for i in range(200)
    ]
    assert 6.0 < state[fdir.SS_SCALE] < 14.0
    assert np.mean(np.array(scales[-100:]) > 0) > 0.99
    jumped = fdir.star_state()
    offset = np.array([np.cos(0.5 * 60 / 206265), np.sin(0.5 * 60 / 206265), 0.0, 0.0])
    for i in range(200):
        sample = fdir.star_tracker_check_1(
            jumped,
            q,
            p,
            quaternion_mul(offset, _star_sample(rng, q, SIGMA_ST)),
            sig,
            nis_max,
            False,
            ev,
            n_ev,
            0.25 * i,
        )
    assert sample == 0.0 and jumped[fdir.SS_SCALE] <= 1.0


def quaternion_mul(a, b):
    from sim_core.quaternion import multiply

    return multiply(a, b)


OMEGA_ORF = 1.1e-3  # rad/s, the ORF pitch rate at 600 km
T_Q = 0.25
SIGMA_G = 2e-6


def _gyro_run(drift_rate_rad_s2: float, duration_s: float, onset_s: float, seed: int = 5):
    """Constant-rate rotation seen by a noisy gyro (bias + ramp) and a noisy star tracker."""
    from sim_core import quaternion

    rng = np.random.default_rng(seed)
    w_true = np.array([0.0, 0.0, OMEGA_ORF])
    bias = np.array([3e-6, -2e-6, 1e-6])
    state = fdir.gyro_state(1e-9)
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    n_sig = fdir.gaussian_sigmas()
    sigma_u = []
    for k in range(int(duration_s / T_Q)):
        t = k * T_Q
        q = quaternion.from_axis_angle(np.array([0.0, 0.0, 1.0]), OMEGA_ORF * t)
        drift = np.array([drift_rate_rad_s2 * max(t - onset_s, 0.0), 0.0, 0.0])
        w = w_true + bias + drift + SIGMA_G * rng.standard_normal(3)
        qm = _star_sample(rng, q, SIGMA_ST)
        sigma_u.append(fdir.gyro_drift_step_1(state, t, w, T_Q, qm, True, SIGMA_ST, SIGMA_G, 1e-9, n_sig, ev, n_ev))
    return ev[: n_ev[0]], sigma_u


def test_constant_bias_is_calibrated_not_a_drift():
    ev, sigma_u = _gyro_run(0.0, 3600.0, 0.0)
    assert ev.shape[0] == 0 and sigma_u[-1] == 1e-9


def test_gyro_ramp_drift_is_detected_on_its_axis_and_widens_the_bias_noise():
    rate = 1e-8  # rad/s², i.e. 0.5°/h of extra bias after 15 min
    onset = 600.0
    ev, sigma_u = _gyro_run(rate, 2400.0, onset)
    detected = [e for e in ev if int(e[1]) == 4]
    isolated = [e for e in ev if int(e[1]) == 5]
    assert detected and isolated
    assert int(isolated[0][2]) == fdir.SENSOR_ARG + 10 * 1 + 0  # gyro, axis x
    w = fdir.GYRO_WINDOW_S
    noise = fdir.gaussian_sigmas() * np.sqrt(2 * SIGMA_ST**2 / w**2 + SIGMA_G**2 * T_Q / w)
    expected = onset + noise / rate  # the drift reaches the noise bound (±1 window of averaging)
    assert abs(detected[0][0] - expected) <= 2 * fdir.GYRO_WINDOW_S
    assert sigma_u[-1] > 1e-9


B_FIELD_T = 3e-5
SIGMA_MAG = 50e-9


def test_magnetometer_spike_is_replaced_by_the_model_and_an_attitude_error_is_not_blamed_on_it():
    rng = np.random.default_rng(6)
    state = fdir.mag_state()
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    model = np.array([B_FIELD_T, -1e-5, 2e-5])
    n_sig = fdir.gaussian_sigmas()
    accepted = 0
    for i in range(20000):
        meas = model + SIGMA_MAG * rng.standard_normal(3)
        accepted += fdir.magnetometer_check_1(state, meas, model, SIGMA_MAG, n_sig, ev, n_ev, i * T_Q)
    assert accepted == 20000
    spike = model + np.array([0.0, -5e-6, 0.0])  # 5 µT on y: |B| changes by ~2 µT
    assert not fdir.magnetometer_check_1(state, spike, model, SIGMA_MAG, n_sig, ev, n_ev, 9e3)
    assert np.array_equal(spike, model)
    assert [int(e[2]) for e in ev[: n_ev[0]]][:2] == [fdir.SENSOR_ARG + 41] * 2
    turned = np.array([0.0, B_FIELD_T, 0.0]) * np.linalg.norm(model) / B_FIELD_T  # wrong attitude, right |B|
    assert fdir.magnetometer_check_1(state, turned, model, SIGMA_MAG, n_sig, ev, n_ev, 9.5e3)


J_SONG = np.diag([20.0, 18.0, 15.0])  # song-table1's bus, kg·m²; three orthogonal 0.01 kg·m² wheels
J_R3 = np.full(3, 0.01)
SIGMA_G = 1e-6  # gyro white noise per sample, rad/s


def _spin_up(
    drift_axis: int | None, drift: float = 1e-7, onset: float = 100.0, seconds: float = 600.0, noise: float = SIGMA_G
):
    """The rate witness over a torque-free body turning about its z principal axis while the z wheel speeds up
    (H_z = J_zz ω_z + J_r Ω_z conserved exactly, ω ∥ H: no precession; position along z: no gravity-gradient
    torque), read by gyros with white noise ``noise`` (the model says SIGMA_G) and, on ``drift_axis``, a bias ramp
    from ``onset``. Returns the state, the events and the last (true rate, gyro rate as the witness left it)."""
    rng = np.random.default_rng(13)
    state = fdir.witness_state()
    ev, n_ev = np.zeros((64, 3)), np.zeros(1, dtype=np.int64)
    h_z, r_b, n_sig = 0.2, np.array([0.0, 0.0, 7.0e6]), fdir.gaussian_sigmas()
    for k in range(int(seconds / T_Q) + 1):
        t = k * T_Q
        speeds = np.array([0.0, 0.0, 5.0 + 0.05 * t])  # the motor's torque is internal: it only moves momentum
        truth = np.array([0.0, 0.0, (h_z - J_R3[2] * speeds[2]) / J_SONG[2, 2]])
        w = truth + noise * rng.standard_normal(3)
        if drift_axis is not None and t > onset:
            w[drift_axis] += drift * (t - onset)
        fdir.rate_witness_step_1(
            state, t, T_Q, w, speeds, J_SONG, np.eye(3), J_R3, 0.0, SIGMA_G, 0.0, r_b, 0.0, n_sig, ev, n_ev
        )
    return state, [(float(e[0]), int(e[1]), int(e[2])) for e in ev[: n_ev[0]]], (truth, w)


def test_gyros_that_agree_with_the_dynamics_raise_nothing_while_a_wheel_moves_momentum():
    state, events, _ = _spin_up(None)
    assert events == []
    assert np.isfinite(state[fdir.RW_REACH])


@pytest.mark.parametrize("axis", [0, 2])
def test_gyro_drift_against_the_dynamics_is_isolated_on_its_axis(axis):
    """A 1e-7 rad/s² ramp from 100 s: isolated on its axis (the oldest window's, started before the onset), after the
    onset and within the windows' span of it."""
    _, events, (truth, w) = _spin_up(axis)
    arg = fdir.SENSOR_ARG + 10 * fdir.T_GYRO + axis
    isolated = [t for t, code, a in events if code == fdir.EV_ISOLATED]
    assert len(isolated) == 1 and {a for _, code, a in events if code != fdir.EV_RECONFIGURED} == {arg}
    assert 100.0 < isolated[0] < 100.0 + fdir.RW_ANCHORS * fdir.RW_EVERY_S
    # reconfigured: the axis reads the dynamics' rate, off by the anchor sample's error (its bound), not the drift
    n_sig, chi3 = fdir.gaussian_sigmas(), fdir.CHI3_SIGMAS
    lam = abs(truth[2]) * 5.0 / 15.0 * fdir.RW_ANCHORS * fdir.RW_EVERY_S  # λ a: |ω| (J_max − J_min)/J_min × 600 s
    bound = n_sig * SIGMA_G + np.sqrt(20.0 / 15.0) * chi3 * SIGMA_G * np.exp(0.5 * lam)
    assert abs(w[axis] - truth[axis]) < bound < 1e-7 * (600.0 - 100.0)


def test_a_noisy_gyro_is_isolated_but_not_replaced_by_a_rate_anchored_on_its_own_noisy_sample():
    """Ten times the model's white noise: the witness sees it at once, the oldest window's ρ steps scatter 10 √2 σ_g
    (beyond NOISE_RATIO × √2 σ_g), so no rate anchored on one of its samples is better: the gyro is left as it is."""
    state, events, (truth, w) = _spin_up(None, seconds=20.0, noise=10.0 * SIGMA_G)
    assert any(code == fdir.EV_ISOLATED for _, code, _ in events)
    assert state[fdir.RW_KEEP] < 0.0


def _earth_samples(witness: np.ndarray, n: int, offset_rad: float = 0.02):
    """``n`` earth samples 20σ off the estimate's nadir (σ_e = 1e-3 rad), screened against the gyro witness."""
    state, ev, n_ev = np.zeros(fdir.EARTH_STATE_SIZE), np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    q, ref = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, -7.0e6])
    nadir = np.array([0.0, np.sin(offset_rad), -np.cos(offset_rad)])
    used = [
        fdir.earth_witness_check_1(
            state, witness, q, np.zeros((6, 6)), nadir, ref, 1e-3, 0.008, 0.012, T_Q, ev, n_ev, i * T_Q
        )
        for i in range(n)
    ]
    return used, [(int(e[1]), int(e[2])) for e in ev[: n_ev[0]]]


def test_earth_residual_without_the_witness_evidence_is_ambiguous_and_isolates_nothing():
    """No window yet: no gyro bias change is excluded, so the earth sensor's offset could be a gyro's doing —
    detected as ambiguous (once), both candidates named, the samples used as without FDIR."""
    used, events = _earth_samples(fdir.witness_state(), 50)
    assert all(used)
    assert events == [(fdir.EV_DETECTED, fdir.AMBIGUOUS_ARG)]
    assert "earth_sensor or gyro" in fdir.describe_event("fault_detected", fdir.AMBIGUOUS_ARG)


def test_earth_residual_the_gyro_cannot_explain_isolates_the_earth_sensor():
    """The dynamics allow a gyro bias change of 1e-6 rad/s; the observer would need K_min · 0.02 rad = 1.6e-4 rad/s
    to hold the mean innovation: the gyro is cleared, the earth sensor rejected and isolated."""
    witness = fdir.witness_state()
    witness[fdir.RW_REACH] = 1e-6
    used, events = _earth_samples(witness, 50)
    assert not any(used[1:])
    assert events[:2] == [(fdir.EV_DETECTED, fdir.SENSOR_ARG + 30), (fdir.EV_ISOLATED, fdir.SENSOR_ARG + 30)]


def test_earth_residual_after_the_gyro_is_isolated_is_the_gyros():
    witness = fdir.witness_state()
    witness[fdir.RW_ISOLATED] = 1.0
    used, events = _earth_samples(witness, 20)
    assert all(used) and events == []


def test_describe_event_names_subjects():
    assert fdir.describe_event("fault_isolated", 2) == "wheel 3"
    assert fdir.describe_event("reconfigured", 0b1010) == "wheels 2,4"
    assert fdir.describe_event("fault_detected", fdir.SENSOR_ARG + 12) == "gyro axis z"
    assert fdir.describe_event("fault_isolated", fdir.SENSOR_ARG + 20) == "star_tracker"
    refused = fdir.describe_event("reconfiguration_refused", 2 + 10 * allocation.STATUS_KAPPA_REFUSED)
    assert refused == f"wheel 3 kept: without it the allocation status would be {allocation.STATUS_KAPPA_REFUSED}"


def test_bad_inputs_name_the_field():
    with pytest.raises(ValueError, match="torque_nm"):
        fdir.wheel_residuals(np.zeros((3, 2)), np.zeros((3, 2)), [1.0, 1.0], np.zeros((4, 2)), 0.0, 2.0)
    with pytest.raises(ValueError, match="probability"):
        fdir.star_nis_threshold(0.0)
    with pytest.raises(ValueError, match="sigma_u"):
        fdir.gyro_state(-1.0)


# ---- the FDIR in the closed loop (somov-ge4-scan: T_u = 2 s, MEKF on 3″ star tracker + gyros) ----

from sim_core import engine, faults, scenario_library  # noqa: E402
from sim_core.scenario import FaultSpec, Scenario, VariantSpec  # noqa: E402

DETECTION_DELAY_MAX_S = 10.0  # issue 4 figure at T_u = 2 s
ISOLATION_RATE_MIN = 0.95  # issue 4 figure over 100 random onsets/wheels
ARCSEC = np.pi / 180.0 / 3600.0
ONSET_S = 331.3  # between two control instants, in the first scanning course
ST_JUMP_ARCSEC = 60.0  # 20σ: a jump must exceed √(2·χ²) σ ≈ 9.5σ between two samples to be seen as one
SENSOR_ONSET_S = 580.0  # in the second scanning course, the loop settled after the turn


def _scan(variants: list[VariantSpec], **changes) -> Scenario:
    s = scenario_library.get("somov-ge4-scan")
    return Scenario.model_validate({**s.model_dump(), **changes, "variants": [v.model_dump() for v in variants]})


def _first(events, name: str):
    return next(((t, arg) for t, n, arg in events if n == name), (None, None))


@pytest.fixture(scope="module")
def loop_run():
    """One batch: nominal, the four single-wheel failures, and sensor faults with and without FDIR."""
    jump = FaultSpec(
        target="star_tracker",
        index=0,
        type="bias",
        onset_s=SENSOR_ONSET_S,
        duration_s=60.0,
        value=ST_JUMP_ARCSEC * ARCSEC,
    )
    st = {"target": "star_tracker", "onset_s": SENSOR_ONSET_S}
    variants = [VariantSpec(name="nominal")]
    variants += [VariantSpec(name=f"wheel {p + 1}", faults=[faults.wheel_failure(p, ONSET_S)]) for p in range(4)]
    variants += [
        VariantSpec(name="st jump", faults=[jump]),
        VariantSpec(name="st jump, no fdir", faults=[jump]),
        VariantSpec(name="st frozen", faults=[FaultSpec(**st, type="frozen", duration_s=30.0)]),
        VariantSpec(
            name="gyro drift", faults=[FaultSpec(target="gyro", index=1, type="drift", onset_s=400.0, value=2e-8)]
        ),
        VariantSpec(name="st failed", faults=[FaultSpec(**st, type="failure")]),
        VariantSpec(name="wheel 2 seized", faults=[faults.wheel_failure(1, ONSET_S, "stuck")]),
        VariantSpec(name="wheel 4 friction", faults=[faults.wheel_failure(3, ONSET_S, "friction", value=5e-3)]),
        VariantSpec(name="wheel 1 half torque", faults=[faults.wheel_failure(0, ONSET_S, "gain", gain=0.5)]),
        VariantSpec(
            name="mag spikes",
            faults=[
                FaultSpec(
                    target="magnetometer",
                    index=2,
                    type="intermittent",
                    onset_s=SENSOR_ONSET_S,
                    duration_s=100.0,
                    value=5e-6,
                    period_s=20.0,
                    duty=0.1,
                )
            ],
        ),
    ]
    flags = [v.name != "st jump, no fdir" for v in variants]
    s = _scan(variants)
    return s, engine.simulate(s, fdir=flags)


def test_abrupt_wheel_failure_is_detected_within_10_s_and_isolated_right_in_all_four_cases(loop_run):
    _, traj = loop_run
    delays = []
    for p in range(4):
        events = traj.events[1 + p]
        t_det, w_det = _first(events, "fault_detected")
        t_iso, w_iso = _first(events, "fault_isolated")
        assert w_det == p and w_iso == p
        assert t_iso - ONSET_S < DETECTION_DELAY_MAX_S
        delays.append(t_det - ONSET_S)
        assert not traj["wheel_available"][1 + p, -1, p] and traj["wheel_available"][1 + p, -1].sum() == 3
    assert max(delays) < DETECTION_DELAY_MAX_S


@pytest.mark.parametrize(
    ("name", "wheel"), [("wheel 2 seized", 1), ("wheel 4 friction", 3), ("wheel 1 half torque", 0)]
)
def test_seized_rubbing_and_weak_wheels_are_isolated_too(loop_run, name, wheel):
    _, traj = loop_run
    events = [e for e in traj.events[traj.variant_names.index(name)] if e[2] < fdir.SENSOR_ARG]
    t_iso, w = _first(events, "fault_isolated")
    assert w == wheel and t_iso - ONSET_S < DETECTION_DELAY_MAX_S
    assert traj["wheel_available"][traj.variant_names.index(name), -1].sum() == 3


def test_nominal_flight_raises_no_event_and_keeps_all_wheels(loop_run):
    _, traj = loop_run
    assert traj.events[0] == [] and traj["wheel_available"][0].all()


def test_star_tracker_jump_is_rejected_and_the_pointing_kept(loop_run):
    s, traj = loop_run
    names = traj.variant_names
    with_fdir, without = names.index("st jump"), names.index("st jump, no fdir")
    t_iso, arg = _first(traj.events[with_fdir], "fault_isolated")
    assert arg == fdir.SENSOR_ARG + 20 and SENSOR_ONSET_S <= t_iso < SENSOR_ONSET_S + 1.0
    # by then a filter that took the jump has followed it
    window = (traj.t_s >= SENSOR_ONSET_S + 20.0) & (traj.t_s < SENSOR_ONSET_S + 60.0)
    err = traj.pointing_error_rad() / ARCSEC
    assert np.max(err[without, window]) > 0.7 * ST_JUMP_ARCSEC  # the loop without FDIR follows the jump
    assert np.max(err[with_fdir, window]) < 0.5 * np.max(err[without, window])


def test_frozen_star_tracker_is_isolated(loop_run):
    _, traj = loop_run
    t_iso, arg = _first(traj.events[traj.variant_names.index("st frozen")], "fault_isolated")
    assert arg == fdir.SENSOR_ARG + 20 and SENSOR_ONSET_S <= t_iso < SENSOR_ONSET_S + 1.0


def test_gyro_ramp_is_isolated_on_its_axis(loop_run):
    _, traj = loop_run
    t_iso, arg = _first(traj.events[traj.variant_names.index("gyro drift")], "fault_isolated")
    assert arg == fdir.SENSOR_ARG + 10 + 1  # gyro, axis y
    assert 400.0 < t_iso < 900.0


def test_magnetometer_spikes_are_screened(loop_run):
    _, traj = loop_run
    t_iso, arg = _first(traj.events[traj.variant_names.index("mag spikes")], "fault_isolated")
    assert arg == fdir.SENSOR_ARG + 40 + 2 and SENSOR_ONSET_S <= t_iso < SENSOR_ONSET_S + 1.0


@pytest.mark.slow
def test_random_onsets_and_wheels_are_isolated_right_in_at_least_95_percent():
    variants = faults.random_wheel_failures(100, (20.0, 840.0), seed=11)
    traj = engine.simulate(_scan(variants, output_dt_s=1.0), fdir=True)
    right = 0
    for v, spec in enumerate(variants):
        t_iso, w = _first(traj.events[v], "fault_isolated")
        onset = spec.faults[0].onset_s
        right += w == spec.faults[0].index and t_iso is not None and t_iso - onset < DETECTION_DELAY_MAX_S
    assert right / len(variants) >= ISOLATION_RATE_MIN


TACH_025_RPM = 0.25 * np.pi / 30.0  # our telemetry's resolution
QUANTISED_CASES = 12  # per fault kind here; benchmarks/fdir_campaign.py flies 200 of each
OBSERVABLE_WINDOW_S = 60.0


def _quantised(variants: list[VariantSpec], **changes) -> Scenario:
    d = _scan(variants, **changes).model_dump()
    d["sensors"]["tachometer_quantum_rad_s"] = TACH_025_RPM
    return Scenario.model_validate(d)


@pytest.mark.parametrize(("kind", "params"), [("failure", {}), ("gain", {"gain": 0.5})])
def test_quantised_tachometer_dead_and_weak_wheels_are_isolated_within_60_s_of_observability(kind, params):
    """0.25 rpm tachometer, 2e-6 rad/s gyro noise, MEKF, random wheels and onsets along the route: each fault is
    isolated on its own wheel within 60 s of withholding one quantum of momentum J_r q (fdir.observable_time)."""
    drawn = faults.random_wheel_failures(QUANTISED_CASES, (20.0, 840.0), seed=5 + len(params))
    variants = [
        VariantSpec(name=v.name, faults=[faults.wheel_failure(v.faults[0].index, v.faults[0].onset_s, kind, **params)])
        for v in drawn
    ]
    s = _quantised(variants, duration_s=1200.0, output_dt_s=1.0)
    traj = engine.simulate(s, fdir=True)
    j_r = engine.plant_params(s).wheels.inertia_kg_m2
    for v, spec in enumerate(variants):
        f = spec.faults[0]
        isolated = [(t, w) for t, name, w in traj.events[v] if name == "fault_isolated" and w < fdir.SENSOR_ARG]
        assert isolated and {w for _, w in isolated} == {f.index}, (spec.name, traj.events[v])
        seen = fdir.observable_time(
            traj.t_s,
            traj["wheel_torque_cmd_nm"][v, :, f.index],
            traj["wheel_torque_nm"][v, :, f.index],
            f.onset_s,
            j_r[f.index],
            TACH_025_RPM,
        )
        assert seen is None or isolated[0][0] - seen <= OBSERVABLE_WINDOW_S, spec.name


def test_seed002_wheel_noise_with_quantised_tachometer_dead_wheel_isolated_and_no_false_alarm():
    """Seed 002's wheel noise torque K_x = 1e-4 N·m on every wheel (song-table1's value), 0.25 rpm tachometer,
    gyro noise, MEKF, 20 min of the scanning route: a wheel dying in the first course is isolated on its own wheel
    within 60 s of withholding one quantum of momentum J_r q; the healthy spacecraft raises nothing (before the
    noise bound, the noise walked the window sums past one quantum: 12 fault events in the first 6 min)."""
    onset = 380.0
    variants = [VariantSpec(name="nominal"), VariantSpec(name="wheel 3 dead", faults=[faults.wheel_failure(2, onset)])]
    s = _quantised(variants, duration_s=1200.0, output_dt_s=1.0)
    for w in s.spacecraft.cluster.wheels:
        w.noise_nm = scenario_library.SONG_WHEEL_TERMS["noise_nm"]
    traj = engine.simulate(s, fdir=True)
    assert traj.events[0] == []
    isolated = [(t, w) for t, name, w in traj.events[1] if name == "fault_isolated" and w < fdir.SENSOR_ARG]
    assert [w for _, w in isolated] == [2], traj.events[1]
    cmd = traj["wheel_torque_cmd_nm"][1, :, 2]
    delivered = np.where(traj.t_s >= onset, 0.0, cmd)  # a dead motor delivers nothing (the record adds the noise)
    j_r = engine.plant_params(s).wheels.inertia_kg_m2[2]
    seen = fdir.observable_time(traj.t_s, cmd, delivered, onset, j_r, TACH_025_RPM)
    assert seen is not None and isolated[0][0] - seen <= OBSERVABLE_WINDOW_S


@pytest.mark.slow
@pytest.mark.parametrize("tach_q", [0.0, TACH_025_RPM])
def test_no_false_alarm_in_24_hours_of_nominal_scan_with_sensor_noise(tach_q):
    s = _quantised([VariantSpec(name="nominal")], duration_s=86400.0, output_dt_s=60.0)
    s.sensors.tachometer_quantum_rad_s = tach_q
    sn = s.sensors
    assert sn.star_tracker_sigma_arcsec > 0 and sn.gyro_noise_rad_s > 0 and sn.magnetometer_noise_t > 0
    traj = engine.simulate(s, fdir=True)
    assert traj.events[0] == []


@pytest.mark.slow
def test_no_false_alarm_in_24_hours_of_song_table1_with_seed002_wheel_noise():
    """song-table1 (perfect tachometer, seed 002's K_x = 1e-4 N·m on three wheels, T_u = 0.1 s, gyro Markov drift,
    Earth pointing on the eq-15 observer, its earth sensor screened) holding for 24 h under FDIR: the wheels' windows
    and CUSUM are summed every period (the floor a, no quantum), 2.6e6 wheel-periods at ≤ 2 P_FA each → ≤ 5e-3 false
    alarms expected; none, no earth-sensor alarm, and the gyros against the dynamics (fdir.rate_witness_step_1, ten
    windows tested every 0.1 s) neither alarm nor leave an earth alarm ambiguous."""
    s = scenario_library.get("song-table1").model_copy(update={"duration_s": 86400.0, "output_dt_s": 60.0})
    assert s.sensors.tachometer_quantum_rad_s == 0.0 and all(w.noise_nm > 0 for w in s.spacecraft.cluster.wheels)
    traj = engine.simulate(s, fdir=True)
    assert traj.events[0] == []


EARTH_SENSOR_HOLD_ARCSEC = 30.0  # gyros + 0.05° earth sensor + field direction keep a few-arcsec estimate for minutes


def test_star_tracker_failure_falls_back_to_earth_sensor_and_magnetometer(loop_run):
    _, traj = loop_run
    v = traj.variant_names.index("st failed")
    after = traj.t_s >= SENSOR_ONSET_S
    est_err = quaternion_angle_between(traj["q_est_ib"][v, after], traj["q_ib"][v, after]) / ARCSEC
    assert np.max(est_err) < EARTH_SENSOR_HOLD_ARCSEC


def quaternion_angle_between(a, b):
    from sim_core import quaternion

    return quaternion.angle(quaternion.multiply(quaternion.conjugate(a), b))


def test_earth_sensor_bias_during_a_star_tracker_outage_pulls_the_estimate_by_the_bias_order():
    """With the star tracker failed, the earth sensor is the only absolute pitch/roll reference: a 0.2°
    bias on it ends up in the estimate (between half and twice the bias after 40 min)."""
    bias_rad = np.radians(0.2)
    outage = [FaultSpec(target="star_tracker", type="failure", onset_s=SENSOR_ONSET_S)]
    earth = FaultSpec(target="earth_sensor", index=0, type="bias", onset_s=SENSOR_ONSET_S, value=bias_rad)
    s = _scan(
        [VariantSpec(name="outage", faults=outage), VariantSpec(name="outage + earth bias", faults=outage + [earth])],
        duration_s=3000.0,
        output_dt_s=5.0,
    )
    traj = engine.simulate(s, fdir=True)
    err = [quaternion_angle_between(traj["q_est_ib"][v, -1], traj["q_ib"][v, -1]) for v in range(2)]
    assert err[0] < EARTH_SENSOR_HOLD_ARCSEC * ARCSEC
    assert 0.5 * bias_rad < err[1] < 2.0 * bias_rad


def test_earth_sensor_jump_during_a_star_tracker_outage_is_screened_like_the_others():
    """A 1° jump of the earth sensor's roll while it is the only absolute reference: rejected (NIS ≈ 1,300 against
    the χ²(2) limit of 41), isolated, and the estimate is not pulled by it (without FDIR it follows the jump)."""
    jump_rad = np.radians(1.0)
    outage = [FaultSpec(target="star_tracker", type="failure", onset_s=SENSOR_ONSET_S)]
    earth = FaultSpec(target="earth_sensor", index=0, type="bias", onset_s=SENSOR_ONSET_S + 60.0, value=jump_rad)
    s = _scan(
        [VariantSpec(name="screened", faults=[*outage, earth]), VariantSpec(name="no fdir", faults=[*outage, earth])],
        duration_s=SENSOR_ONSET_S + 300.0,
        output_dt_s=5.0,
    )
    traj = engine.simulate(s, fdir=[True, False])
    t_iso, arg = _first(traj.events[0], "fault_isolated")
    assert arg == fdir.SENSOR_ARG + 30 and SENSOR_ONSET_S + 60.0 <= t_iso < SENSOR_ONSET_S + 61.0
    assert fdir.describe_event("fault_isolated", arg) == "earth_sensor"
    err = [quaternion_angle_between(traj["q_est_ib"][v, -1], traj["q_ib"][v, -1]) for v in range(2)]
    assert err[0] < EARTH_SENSOR_HOLD_ARCSEC * ARCSEC < 0.25 * jump_rad < err[1]


def test_observable_time_is_the_first_window_whose_withheld_momentum_reaches_its_floor():
    """Withheld momentum of 1e-4 N·m from onset 10 s, 1 s samples, J q = 1e-3 N·m·s: observable once 10 samples are
    withheld (the sample at 19 s); a loss that reverses (+0.6 J q then −0.6 J q) never withholds J q from the onset,
    but does over the window from its peak; under noise a per period (T_u = 1 s) the floor over n samples is
    J q + a √n: with a = J q the 1e-4 N·m loss needs 1e-4 n ≥ 1e-3 (1 + √n), n ≥ 119.2: 120 samples."""
    t = np.arange(0.0, 400.0, 1.0)
    cmd = np.full(t.shape, 1e-4)
    dead = np.where(t >= 10.0, 0.0, cmd)
    assert fdir.observable_time(t, cmd, dead, 10.0, 1.0, 1e-3) == 19.0
    gap = np.where((t >= 10.0) & (t < 16.0), 1e-4, np.where((t >= 16.0) & (t < 28.0), -1e-4, 0.0))
    assert fdir.observable_time(t, gap, np.zeros_like(t), 10.0, 1.0, 1e-3) == 25.0  # 6 up, then 10 down from the peak
    n = int(np.ceil(((1.0 + np.sqrt(1.4)) / 0.2) ** 2))  # 0.1 n − √n − 1 ≥ 0
    assert fdir.observable_time(t, cmd, dead, 10.0, 1.0, 1e-3, 1e-3, 1.0) == 10.0 + n - 1
