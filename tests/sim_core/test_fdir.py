"""FDIR kernels against independent truths: the exact solution of a wheel with viscous and dry
friction, the tachometer quantisation bound, χ² statistics of the star-tracker innovation, and
constant-rate kinematics for the gyro drift test; then the closed loop (detection delay, isolation
in all single-wheel cases and over random onsets, no false alarm in 24 h of nominal flight)."""

import numpy as np
import pytest

from sim_core import fdir
from sim_core.wheels import WheelParams

J_HR12 = 12.0 / (6000.0 * np.pi / 30.0)  # HR12 rotor inertia, kg·m²
T_U = 2.0  # seed 000 §5 control period
TACH_Q = 2 * np.pi / 60.0 * 0.1  # 0.1 rpm tachometer resolution, rad/s
VISCOUS = 2e-5  # N·m·s: ~0.013 N·m at 6,000 rpm, an HR12-class drag
COULOMB = 2e-3  # N·m dry friction
SAT_SPEED = 1.0  # rad/s, the dry-friction smoothing speed
N_TRIALS = 4000
W0 = np.zeros(3)  # body at rest: the tachometer reads the absolute spin
AXES4 = np.eye(3)[:, [0, 1, 2, 0]].copy()


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
    res, bound = fdir.wheel_residuals(np.stack([r0, r1]), m[None, :], np.full(N_TRIALS, J_HR12),
                                      np.zeros((4, N_TRIALS)), TACH_Q, T_U)
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
    res, bound = fdir.wheel_residuals(speed[:, None], np.zeros((1, 1)), [J_HR12], np.zeros((4, 1)), 0.0, T_U,
                                      axial_rate_rad_s=axial[:, None])
    assert abs(res[0, 0]) <= bound[0, 0]
    res_blind, _ = fdir.wheel_residuals(speed[:, None], np.zeros((1, 1)), [J_HR12], np.zeros((4, 1)), 0.0, T_U)
    assert abs(res_blind[0, 0]) > 1e3 * bound[0, 0]


def _check_sequence(deltas_nms: list[float], torque: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    state = fdir.wheel_state(4)
    speeds = np.full(4, 100.0)
    available = np.ones(4, dtype=np.bool_)
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    j = np.full(4, J_HR12)
    zeros = np.zeros((4, 4))
    for k, dh in enumerate(deltas_nms):
        fdir.wheel_hold_1(state, speeds, W0, AXES4, np.full(4, torque), j, np.full(4, 0.2), np.full(4, 12.0))
        speeds = speeds + torque * T_U / J_HR12
        speeds[2] += dh / J_HR12
        fdir.wheel_check_1(state, speeds, W0, AXES4, j, np.full(4, 12.0), zeros, TACH_Q, 0.0, T_U, available, ev, n_ev,
                           (k + 1) * T_U)
    return available, ev[: n_ev[0]], state


def test_two_periods_beyond_bound_isolate_the_wheel_and_drop_it():
    big = 10 * J_HR12 * TACH_Q
    available, ev, _ = _check_sequence([0.0, big, big])
    assert list(available) == [True, True, False, True]
    assert [tuple(e[1:]) for e in ev] == [(4, 2), (5, 2), (6, 0b1011)]
    assert ev[1, 0] == 3 * T_U


def test_single_exceedance_is_a_transient_not_an_isolation():
    big = 10 * J_HR12 * TACH_Q
    available, ev, _ = _check_sequence([big, 0.0, big, 0.0])
    assert available.all()
    assert set(ev[:, 1]) == {4}


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
        fdir.wheel_hold_1(state, speeds, W0, AXES4[:, :3], np.array([0.1, 0.0, 0.0]), j, np.full(3, 0.2), np.full(3, 12.0))
        faulty = fdir.wheel_check_1(state, speeds, W0, AXES4[:, :3], j, np.full(3, 12.0), zeros, 0.0, 0.0, T_U, available,
                                     ev, n_ev, k * T_U)
    assert faulty
    assert (1, 4) in [(int(e[1]), int(e[2])) for e in ev[: n_ev[0]]]  # mode_change → MODE_FAULT (4)


def test_wheel_near_momentum_limit_is_not_tested():
    state = fdir.wheel_state(1)
    j = np.array([J_HR12])
    speeds = np.array([11.99 / J_HR12])
    available = np.ones(1, dtype=np.bool_)
    ev, n_ev = np.zeros((4, 3)), np.zeros(1, dtype=np.int64)
    for k in range(3):
        fdir.wheel_hold_1(state, speeds, W0, AXES4[:, :1], np.array([0.2]), j, np.array([0.2]), np.array([12.0]))
        fdir.wheel_check_1(state, speeds, W0, AXES4[:, :1], j, np.array([12.0]), np.zeros((4, 1)), 0.0, 0.0, T_U, available,
                           ev, n_ev, k * T_U)
    assert available[0] and n_ev[0] == 0


SIGMA_ST = 3.0 / 206265.0  # 3″ star tracker (seed 000 §5)
N_SAMPLES_CHI2 = 20000


def _star_sample(rng, q, sigma):
    from sim_core.sensors import star_tracker_1

    qm, _ = star_tracker_1(q, np.zeros(3), np.full(3, sigma), 1.0, rng.standard_normal(3))
    return qm


def test_star_tracker_innovation_is_chi2_and_accepts_consistent_samples():
    """Estimate and sample both scattered as P and R say: rejections at the 10 % χ²(3) quantile are
    10 % (± 4 binomial σ over 20,000 samples); at the FDIR quantile none are."""
    from scipy.stats import chi2

    rng = np.random.default_rng(3)
    q = np.array([0.9, 0.1, -0.3, 0.2])
    q /= np.linalg.norm(q)
    p = np.diag([SIGMA_ST**2] * 3 + [1e-12] * 3)
    sig = np.full(3, SIGMA_ST)
    ev, n_ev = np.zeros((8, 3)), np.zeros(1, dtype=np.int64)
    rejected = {0.1: 0, fdir.FALSE_ALARM_PROBABILITY: 0}
    for level in rejected:
        state, limit = fdir.star_state(), chi2.isf(level, 3)
        for i in range(N_SAMPLES_CHI2):
            q_est = _star_sample(rng, q, SIGMA_ST)
            rejected[level] += not fdir.star_tracker_check_1(state, q_est, p, _star_sample(rng, q, SIGMA_ST), sig,
                                                             limit, ev, n_ev, float(i))
    spread = 4 * np.sqrt(0.1 * 0.9 / N_SAMPLES_CHI2)
    assert abs(rejected[0.1] / N_SAMPLES_CHI2 - 0.1) <= spread
    assert rejected[fdir.FALSE_ALARM_PROBABILITY] == 0


def test_star_tracker_jump_and_freeze_are_rejected_and_isolated():
    rng = np.random.default_rng(4)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    p = np.diag([SIGMA_ST**2] * 3 + [1e-12] * 3)
    sig = np.full(3, SIGMA_ST)
    nis_max = fdir.star_nis_threshold()
    state = fdir.star_state()
    ev, n_ev = np.zeros((8, 3)), np.zeros(1, dtype=np.int64)
    jump = np.array([np.cos(0.5 * 20 * SIGMA_ST), np.sin(0.5 * 20 * SIGMA_ST), 0.0, 0.0])
    assert not fdir.star_tracker_check_1(state, q, p, jump, sig, nis_max, ev, n_ev, 1.0)
    assert not fdir.star_tracker_check_1(state, q, p, jump, sig, nis_max, ev, n_ev, 2.0)  # and frozen
    names = [int(e[1]) for e in ev[: n_ev[0]]]
    assert names == [4, 5, 6] and int(ev[0, 2]) == fdir.SENSOR_ARG + 10 * 2
    state = fdir.star_state()
    sample = _star_sample(rng, q, SIGMA_ST)
    assert fdir.star_tracker_check_1(state, q, p, sample, sig, nis_max, ev, n_ev, 3.0)
    assert not fdir.star_tracker_check_1(state, q, p, sample.copy(), sig, nis_max, ev, n_ev, 3.25)


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
    noise = fdir.gaussian_sigmas() * np.sqrt(2 * SIGMA_ST**2 / fdir.GYRO_WINDOW_S**2 + SIGMA_G**2 * T_Q / fdir.GYRO_WINDOW_S)
    expected = onset + noise / rate  # the drift reaches the noise bound (±1 window of averaging)
    assert abs(detected[0][0] - expected) <= 2 * fdir.GYRO_WINDOW_S
    assert sigma_u[-1] > 1e-9


B_FIELD_T = 3e-5
SIGMA_MAG = 50e-9


def test_magnetometer_spike_is_replaced_by_the_model_and_noise_is_kept():
    rng = np.random.default_rng(6)
    state = fdir.mag_state()
    ev, n_ev = np.zeros((16, 3)), np.zeros(1, dtype=np.int64)
    model = np.array([B_FIELD_T, -1e-5, 2e-5])
    n_sig = fdir.gaussian_sigmas()
    accepted = 0
    for i in range(20000):
        meas = model + SIGMA_MAG * rng.standard_normal(3)
        accepted += fdir.magnetometer_check_1(state, meas, model, SIGMA_MAG, SIGMA_ST, n_sig, ev, n_ev, i * T_Q)
    assert accepted == 20000
    spike = model + np.array([0.0, 5e-6, 0.0])
    assert not fdir.magnetometer_check_1(state, spike, model, SIGMA_MAG, SIGMA_ST, n_sig, ev, n_ev, 9e3)
    assert np.array_equal(spike, model)
    assert [int(e[2]) for e in ev[: n_ev[0]]][:2] == [fdir.SENSOR_ARG + 41] * 2


def test_describe_event_names_subjects():
    assert fdir.describe_event("fault_isolated", 2) == "wheel 3"
    assert fdir.describe_event("reconfigured", 0b1010) == "wheels 2,4"
    assert fdir.describe_event("fault_detected", fdir.SENSOR_ARG + 12) == "gyro axis z"
    assert fdir.describe_event("fault_isolated", fdir.SENSOR_ARG + 20) == "star_tracker"


def test_bad_inputs_name_the_field():
    with pytest.raises(ValueError, match="torque_nm"):
        fdir.wheel_residuals(np.zeros((3, 2)), np.zeros((3, 2)), [1.0, 1.0], np.zeros((4, 2)), 0.0, 2.0)
    with pytest.raises(ValueError, match="probability"):
        fdir.star_nis_threshold(0.0)
    with pytest.raises(ValueError, match="sigma_u"):
        fdir.gyro_state(-1.0)
