"""Every fault type and switchable seed model acts on the flight: effect against nominal, sign and size
from the physics (seed 002 §3.2 outage and gain loss, residual dipole m × B, gyro Markov drift, Sun sensor)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sim_core import engine, environment, faults, quaternion, scenario_library, sensors
from sim_core.closed_loop import SUN_AXIS_B
from sim_core.scenario import FaultSpec, Scenario, VariantSpec
from telemetry import emulator

ONSET_S = faults.SEED002_ONSET_S


def _with(s: Scenario, **fields) -> Scenario:
    return Scenario.model_validate({**s.model_dump(), **fields})


def _variants(*named: tuple[str, list[FaultSpec]]) -> list[dict]:
    return [VariantSpec(name=n, faults=f).model_dump() for n, f in named]


# --- grammar ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text",
    [
        "wheel:1:failure@600",
        "gyro:2:bias@10.5,value=0.0001",
        "controller:0:intermittent@7+1,period_s=0.5,duty=0.25",
        "md_rod:2:gain@3,gain=0.5",
        "sun_sensor:0:drift@1.25+100.0,value=-2e-05",
    ],
)
def test_grammar_round_trips_and_is_the_emulators(text):
    f = faults.parse_fault(text)
    assert faults.parse_fault(faults.format_fault(f)) == f
    assert emulator.parse_fault is faults.parse_fault


def test_table_codes_each_fault_of_each_variant():
    vs = [VariantSpec(name="a", faults=[faults.parse_fault("wheel:3:stuck@5+2")]), VariantSpec(name="b")]
    table, counts = faults.fault_table(vs)
    assert counts.tolist() == [1, 0] and table.shape == (2, 1, faults.FAULT_COLUMNS)
    row = table[0, 0]
    assert row[faults.F_TARGET] == faults.TARGET_CODES["wheel"] and row[faults.F_INDEX] == 3
    assert row[faults.F_TYPE] == faults.TYPE_CODES["stuck"] and (row[faults.F_ONSET], row[faults.F_END]) == (5.0, 7.0)


# --- seed 002 outage and gain loss on its bus --------------------------------------------------------


PITCH = 2  # body z: the orbit-frame pitch axis, wheel 3's (seed 002 Figs 29–30 fault wheel 3)


def _pitch(traj, v: int, series: str = "q_ib") -> np.ndarray:
    """Pitch angle 2 e_z (e = Λ̃^p ∘ Λ about the orbit frame, small angles) of ``series`` (the flown attitude or the
    estimate the law reads) of variant v."""
    e = quaternion.multiply(quaternion.conjugate(traj["q_prog_ib"][v]), traj[series][v])
    e *= np.sign(e[:, :1])
    return 2.0 * e[:, 1 + PITCH]


def _pd_response(
    y0: tuple[float, float],
    inertia: float,
    kp: float,
    kd: float,
    gain: float,
    t: np.ndarray,
    friction: float,
    sensed: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """Small-angle response J θ̈ = −g (k_p (θ + e)/2 + k_d (θ̇ + b)) + m_f of seed 002's quaternion PD (eq 18) from
    y0 = (θ0, θ̇0), m_f the wheel's friction torque the body receives (constant while the wheel spins beyond Ω°), the
    law reading the attitude with the observer's error e(t) and the rate with the gyro's error b(t) (``sensed``, as
    recorded at the times t)."""
    e, b = sensed

    def rhs(tt: float, y: np.ndarray) -> list[float]:
        law = kp * (y[0] + np.interp(tt, t, e)) / 2 + kd * (y[1] + np.interp(tt, t, b))
        return [y[1], (friction - gain * law) / inertia]

    sol = solve_ivp(rhs, (t[0], t[-1]), list(y0), t_eval=t, rtol=1e-9, atol=1e-12, max_step=0.05)
    return sol.y[0]


def test_seed002_wheel_outage_and_gain_loss_follow_the_axis_dynamics():
    """Wheel 3 (pitch axis) of song-table1 at 7 s, in the transient from its 5° start: an outage leaves the axis to
    the wheel's friction alone (seed 002 eq 4: the rotor, still spinning ≫ Ω°, hands the body m_f = K_nl sign Ω +
    K_l Ω + K_a Ω√|Ω|, so θ = θ0 + θ̇0 Δt + m_f Δt²/2J), a 70 % gain loss slows its PD by g = 0.3 against the same
    m_f; each predicted from its own state at the onset. The pitch axis of the Earth-pointing spacecraft is decoupled
    from roll and yaw (its gravity-gradient stiffness 3 ω_o² (J_x − J_y) ≈ 7e-6 N·m/rad is 1e-5 of K_p/2). The law
    reads the eq-15 observer, which starts from one earth-sensor sample (σ = 1 mrad) and corrects at K_θ = 0.01/s,
    and the gyro: the prediction feeds it the recorded estimate errors, e = θ̂ − θ and b = ω̂ − ω."""
    s = scenario_library.get("song-table1")
    gain = faults.SEED002_MAGNITUDES["wheel_gain"]
    s = _with(
        s,
        duration_s=60.0,
        variants=_variants(
            ("nominal", []),
            ("outage", [faults.wheel_failure(PITCH, ONSET_S)]),
            ("gain loss", [faults.wheel_failure(PITCH, ONSET_S, "gain", gain=gain)]),
        ),
    )
    traj = engine.simulate(s)
    j, kp, kd = s.spacecraft.inertia_kg_m2[PITCH][PITCH], s.controller.pd_kp_nm, s.controller.pd_kd_nms
    at = round(ONSET_S / s.output_dt_s)
    t = traj.t_s[at:]
    theta = [_pitch(traj, v)[at:] for v in range(3)]
    law_error = [_pitch(traj, v, "q_est_ib")[at:] for v in range(3)]  # θ + e: what the PD drives to zero
    rate = [traj["omega_b_rad_s"][v, at:, PITCH] - traj["omega_prog_b_rad_s"][v, at:, PITCH] for v in range(3)]
    gyro_error = [traj["omega_est_b_rad_s"][v, at:, PITCH] - traj["omega_b_rad_s"][v, at:, PITCH] for v in range(3)]
    assert abs(theta[0][0]) > np.radians(0.5)  # the pitch transient is still under way at the onset
    scale = abs(theta[0][0])
    w, speed = s.spacecraft.cluster.wheels[PITCH], traj["wheel_speed_rad_s"][0, at, PITCH]
    assert abs(speed) > 10.0 * w.coulomb_sat_speed_rad_s
    m_f = w.coulomb_nm * np.sign(speed) + w.viscous_nm_s * speed + w.aero_drag_nm_s15 * speed * np.sqrt(abs(speed))
    free = theta[1][0] + rate[1][0] * (t - t[0]) + 0.5 * m_f / j * (t - t[0]) ** 2
    assert np.max(np.abs(theta[1] - free)) <= 0.05 * scale
    for v, g in ((0, 1.0), (2, gain)):
        sensed = (law_error[v] - theta[v], gyro_error[v])
        predicted = _pd_response((theta[v][0], rate[v][0]), j, kp, kd, g, t, m_f, sensed)
        assert np.max(np.abs(theta[v] - predicted)) <= 0.05 * scale
    # effect against nominal over the last 20 s, on the error the law sees: nominal has settled (envelope
    # e^{−k_d t/2J} < e^{−8} of the scale) onto its friction floor, the standing error 2|m_f|/k_p at which the PD
    # supplies m_f; the weak wheel still lags above it (envelope e^{−g k_d t/2J}: e^{−2.6}…e^{−4.2} of the scale);
    # the outage runs away
    tail = t >= t[-1] - 20.0
    rms = [float(np.sqrt(np.mean(err[tail] ** 2))) for err in law_error]
    floor = 2.0 * abs(m_f) / kp
    assert rms[0] <= floor < rms[2] < 0.1 * rms[1]


# --- residual dipole ------------------------------------------------------------------------------


def _quiet(**fields) -> Scenario:
    """somov-ge4-scan, no gravity gradient, truth navigation, no rods: no external torque but the one tested."""
    s = scenario_library.get("somov-ge4-scan")
    d = s.model_dump()
    d.update(gravity_gradient=False, **fields)
    d["estimator"]["kind"] = "truth"
    d["spacecraft"]["md_max_dipole_am2"] = 0.0
    return Scenario.model_validate(d)


def _h_inertial(traj, s: Scenario) -> np.ndarray:
    p = engine.plant_params(s)
    h_body = (
        traj["omega_b_rad_s"][0] @ p.inertia_kg_m2.T
        + (traj["wheel_speed_rad_s"][0] * p.wheels.inertia_kg_m2) @ p.wheel_axes_b.T
    )
    return quaternion.rotate(traj["q_ib"][0], h_body)


def test_residual_dipole_changes_the_momentum_by_the_integral_of_m_cross_b():
    m_res = [1.0, -2.0, 3.0]  # A·m², a small satellite's uncompensated harness and magnet loops
    nominal = _quiet(duration_s=600.0)
    dipole = _quiet(duration_s=600.0, spacecraft={**nominal.spacecraft.model_dump(), "residual_dipole_am2": m_res})
    h_nom, traj = _h_inertial(engine.simulate(nominal), nominal), engine.simulate(dipole)
    h = _h_inertial(traj, dipole)
    t0 = traj.extra["epoch_unix_s"]
    b_eci = environment.magnetic_field_eci_t(traj["r_eci_m"][0], t0 + traj.t_s, dipole.magnetic_model)
    b_body = quaternion.rotate(quaternion.conjugate(traj["q_ib"][0]), b_eci)
    torque_i = quaternion.rotate(traj["q_ib"][0], np.cross(np.array(m_res), b_body))
    expected = np.concatenate(
        [np.zeros((1, 3)), np.cumsum(0.5 * (torque_i[1:] + torque_i[:-1]), axis=0) * np.diff(traj.t_s)[:, None]]
    )
    scale = np.max(np.linalg.norm(expected, axis=1))
    assert scale > 1e-3  # N·m·s: ~1e-4 N·m of m × B over ten minutes
    assert np.max(np.linalg.norm((h - h[0]) - expected, axis=1)) <= 0.02 * scale
    assert np.max(np.linalg.norm(h_nom - h_nom[0], axis=1)) <= 1e-3 * scale


# --- gyro Markov drift ----------------------------------------------------------------------------


def test_gyro_markov_drift_has_its_sigma_and_correlation_time_in_the_twin_and_the_emulator():
    sigma, tau = 2e-5, 60.0
    base = scenario_library.get("somov-ge4-scan")
    sn = base.sensors.model_dump()
    nominal = _with(base, duration_s=1800.0, estimator={"kind": "star_tracker"})
    drifting = _with(nominal, sensors={**sn, "gyro_markov_sigma_rad_s": sigma, "gyro_markov_tau_s": tau})
    errors = []
    for s in (nominal, drifting):
        traj = engine.simulate(s)
        errors.append(traj["omega_est_b_rad_s"][0, 1:] - traj["omega_b_rad_s"][0, 1:])
    noise = base.sensors.gyro_noise_rad_s
    assert np.std(errors[0]) == pytest.approx(noise, rel=0.1)
    assert np.std(errors[1]) == pytest.approx(np.hypot(sigma, noise), rel=0.25)
    lag = int(tau / drifting.output_dt_s)
    e = errors[1] - errors[1].mean(axis=0)
    rho = np.sum(e[lag:] * e[:-lag]) / np.sum(e * e)
    assert rho == pytest.approx(np.exp(-1.0), abs=0.15)
    # the emulated satellite's gyro flies the same drift model
    truth = {"omega_b_rad_s": np.zeros((int(1800 / 0.25), 3))}
    carry = emulator.TelemetryCarry(np.random.default_rng(1))
    w_g = emulator._gyro(truth, drifting, np.arange(truth["omega_b_rad_s"].shape[0]) * 0.25, carry)
    assert np.std(w_g) == pytest.approx(np.hypot(sigma, noise), rel=0.25)


# --- Sun sensor -----------------------------------------------------------------------------------


def test_sun_sensor_bias_tilts_the_sun_safe_pointing_by_the_bias():
    """Sun/safe mode with the star tracker out (attitude invalid keeps the mode): the Sun axis follows the
    Sun sensor, so a bias b on its x component leaves the true Sun at atan(b) on the −x side."""
    bias = 0.05
    lost = faults.parse_fault("star_tracker:0:failure@0")
    s = _with(
        scenario_library.get("somov-ge4-scan"),
        duration_s=1500.0,
        initial_mode="sun_safe",
        estimator={"kind": "mekf"},
        output_dt_s=5.0,
        variants=_variants(
            ("nominal", [lost]), ("sun sensor bias", [lost, faults.parse_fault(f"sun_sensor:0:bias@0,value={bias}")])
        ),
    )
    traj = engine.simulate(s)
    t0 = traj.extra["epoch_unix_s"]
    sun = environment.sun_position_eci_m(t0 + traj.t_s)
    lit = ~sensors.in_earth_shadow(traj["r_eci_m"][0], sun) & (traj.t_s > 900.0)
    assert lit.sum() >= 20
    angles, x_side = [], []
    for v in range(2):
        s_b = quaternion.rotate(quaternion.conjugate(traj["q_ib"][v]), sun / np.linalg.norm(sun, axis=1, keepdims=True))
        assert np.all(traj["mode"][v, lit] == 1)  # still Sun/safe
        angles.append(np.median(np.arccos(np.clip(s_b[lit] @ SUN_AXIS_B, -1, 1))))
        x_side.append(np.median(s_b[lit, 0]))
    assert angles[0] < np.radians(1.0)
    assert angles[1] == pytest.approx(np.arctan(bias), rel=0.2)
    assert x_side[1] < 0.0


# --- tachometer (speed-sensor) faults ---------------------------------------------------------------

TACH_025_RPM = 0.25 * np.pi / 30.0  # our telemetry's tachometer resolution
TACH_ONSET_S = 401.0  # between control ticks (T_u = 2 s): the software reads the biased speed first at 402 s


def test_tachometer_fault_grammar_and_kernel_offset_the_reading_of_its_wheel_from_the_onset():
    f = faults.parse_fault("tachometer:1:bias@401.0,value=0.0785")
    assert faults.parse_fault(faults.format_fault(f)) == f
    table, _ = faults.fault_table([VariantSpec(name="bias", faults=[f])])
    reading = np.array([10.0, -20.0, 30.0, 0.0])
    before, after = reading.copy(), reading.copy()
    faults.tachometer_faults_1(table[0], 400.9, before)
    faults.tachometer_faults_1(table[0], 401.0, after)
    assert before.tolist() == reading.tolist()
    assert after.tolist() == [10.0, -20.0 + 0.0785, 30.0, 0.0]
    with pytest.raises(ValueError, match="tachometer fault"):
        faults.parse_fault("tachometer:0:stuck@1")
    s = scenario_library.get("somov-ge4-scan")
    with pytest.raises(ValueError, match="wheel 4 does not exist"):
        _with(s, variants=_variants(("x", [faults.parse_fault("tachometer:4:bias@1,value=1")])))


def _tachometer_flights(bias_rad_s: float, fdir_on: bool, **controller) -> tuple:
    """somov-ge4-scan with a 0.25 rpm tachometer, nominal and with wheel 2's reading biased from TACH_ONSET_S: two
    single-variant batches, so that both draw the same sensor noise."""
    s = scenario_library.get("somov-ge4-scan")
    d = s.model_dump()
    d["sensors"]["tachometer_quantum_rad_s"] = TACH_025_RPM
    d["controller"].update(controller)
    d.update(duration_s=420.0, output_dt_s=1.0)
    bias = FaultSpec(target="tachometer", index=1, type="bias", onset_s=TACH_ONSET_S, value=bias_rad_s)
    out = []
    for fs in ([], [bias]):
        d["variants"] = _variants(("v", fs))
        out.append(engine.simulate(Scenario.model_validate(d), fdir=fdir_on))
    return s, out[0], out[1]


@pytest.mark.parametrize("counts", [3.0, -3.0])
def test_tachometer_bias_moves_the_reading_not_the_rotor(counts):
    """A speed-sensor bias b on wheel 2 changes no physics: truth (rotor speeds, attitude) stays bit-identical to
    nominal until the software first reads the biased speed (the control tick at 402 s); the law's gyroscopic
    compensation ω̂ × (Jω̂ + Σ a_p J_r Ω̃_p) (seed 000 eq 1) then commands exactly ω̂ × a_2 J_r b more torque."""
    b = counts * TACH_025_RPM
    s, nominal, biased = _tachometer_flights(b, False, gyroscopic_compensation=True)
    t = nominal.t_s
    before = t <= 402.0
    for name in ("wheel_speed_rad_s", "q_ib", "omega_b_rad_s", "omega_est_b_rad_s"):
        assert np.array_equal(biased[name][0, before], nominal[name][0, before]), name
    k = int(np.searchsorted(t, 402.0))
    assert np.array_equal(nominal["control_torque_b_nm"][0, :k], biased["control_torque_b_nm"][0, :k])
    axis = engine.plant_params(s).wheel_axes_b[:, 1]
    j_r = s.spacecraft.cluster.wheels[1].inertia_kg_m2
    expected = np.cross(nominal["omega_est_b_rad_s"][0, k], axis * j_r * b)
    got = biased["control_torque_b_nm"][0, k] - nominal["control_torque_b_nm"][0, k]
    assert np.linalg.norm(expected) > 1e-7  # the scan's orbital rate makes the term visible
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("counts", [3.0, -3.0])
def test_tachometer_bias_is_isolated_by_the_wheel_check_within_two_periods(counts):
    """FDIR's momentum residual of wheel 2 (fdir.wheel_residual_1) steps by J_r b = ±3 J_r q when the software first
    reads the bias: every window sum straddling the onset holds the step, at least 2 J_r q after the two readings'
    rounding, beyond its bound J_r q + model terms (the readings telescope), so the wheel is detected at the first
    tick and isolated at the next (CONFIRM_PERIODS = 2); the other three wheels stay."""
    _, nominal, biased = _tachometer_flights(counts * TACH_025_RPM, True)
    assert nominal.events[0] == []
    wheel = [(t, name, arg) for t, name, arg in biased.events[0] if name != "fault_onset"]
    assert wheel == [(402.0, "fault_detected", 1), (404.0, "fault_isolated", 1), (404.0, "reconfigured", 0b1101)]
