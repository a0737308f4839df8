"""The seeds' fault experiments, each asserted against the outcome the seed states (or, where our
physics disagrees, against what it gives, said so in the test name).

Seed 002 §3.2 on the ``song-table1`` bus (three orthogonal wheels with the seed's torque balance, motor
electrics and gyro drift; quaternion PD), 1,000 s of Earth pointing as the scenario's description says: without
reconfiguration (the paper's runs, star tracker as attitude sensor) and with our FDIR (MEKF + screening + wheel
isolation). The seed's Table 1 is garbled, so magnitudes are :data:`sim_core.faults.SEED002_MAGNITUDES`.

The nominal error is friction-limited (seed 002 eq 4). The law u = −K_p q_e − K_d ω_e has no integral: at rest
each axis i holds the torque its wheel's friction m_f(Ω_i) = K_nl sign Ω_i + K_l Ω_i takes from the motor, plus the
external torque the wheel stores (J_r Ω̇_i), by a standing error q_e,i = θ_i/2, so
|θ_i| = 2 |m_f(Ω_i) + J_r Ω̇_i| / K_p; the gyro's Markov drift b (eq 13, σ_b) adds 2 K_d b / K_p through the rate
term. A wheel beyond the Coulomb saturation speed has |m_f| = K_nl = 1e-4 N·m, hence θ = 1e-4 rad = 0.0057° at
K_p = 2 N·m; with every axis at its worst (external torque ≤ the gravity-gradient bound 3μ/r³ (J_max − J_min), drift
3σ_b) the whole error stays within √3 · 2 (K_nl + K_l Ω_max + M_gg + 3 K_d σ_b)/K_p = 0.014° (:func:`_friction_band`).
With ideal wheels the nominal held 4.5e-4°; the seed's faults are now measured against this band. Seed 000 §5:
wheels 2 and 4 with the magnetic driver fly the trace-scanning route near the 4-wheel accuracy;
and the 11-configuration table of issue 4 through ``acs-twin faults-table``.
"""

import json

import numpy as np
import pytest

from sim_core import engine, faults, fdir, orbit, quaternion, scenario_library
from sim_core.engine import simulate
from sim_core.scenario import Scenario, VariantSpec

DURATION_S = 1000.0
SETTLED_S = 200.0  # nominal settles from the 5° start in ~30 s; after 200 s only faults move the error
NOT_STABILISED = 10.0  # "cannot be stabilised": the error ends an order of magnitude beyond the nominal band
LOST_DEG = 10.0  # attitude lost: beyond 10° (the nominal holds a few arcsec)
RAMP_TRACKING = 0.1  # the loop follows a drifting attitude sensor to 10 % (PD lag at 5e-5 rad/s)
SETTLING_SAME_S = 2.0  # "no longer response" within 2 s of the nominal 29 s
MOMENTUM_TOLERANCE = 0.02  # trapezoid of the 0.1 s gravity-gradient samples against the flight, and ω × H terms
OBSERVABLE_WINDOW_S = 60.0  # issue 13: isolated within 60 s of the fault becoming observable
ARCSEC = np.pi / 180.0 / 3600.0


def _friction_band(s: Scenario, speed_max_rad_s: float) -> float:
    """Bound on the nominal's pointing error, rad (module docstring): √3 · 2 (K_nl + K_l Ω_max + M_gg + 3 K_d σ_b)/K_p."""
    w, j = s.spacecraft.cluster.wheels[0], np.linalg.eigvalsh(np.asarray(s.spacecraft.inertia_kg_m2))
    r = orbit.R_EARTH_M + s.orbit.altitude_m
    m_gg = 3.0 * orbit.MU_EARTH_M3_S2 / r**3 * (j[-1] - j[0])
    drift = 3.0 * s.controller.pd_kd_nms * s.sensors.gyro_markov_sigma_rad_s
    return float(
        np.sqrt(3.0) * 2.0 * (w.coulomb_nm + w.viscous_nm_s * speed_max_rad_s + m_gg + drift) / s.controller.pd_kp_nm
    )


def _song(estimator: str) -> Scenario:
    s = scenario_library.get("song-table1")
    data = s.model_dump()
    data["duration_s"] = DURATION_S
    data["estimator"]["kind"] = estimator
    data["variants"] = [VariantSpec(name=n, faults=f).model_dump() for n, f in faults.seed002_fault_sets().items()]
    return Scenario.model_validate(data)


class Outcome:
    """Error histories (deg) of one batch, by variant name."""

    def __init__(self, traj):
        self.traj = traj
        self.err = np.degrees(traj.pointing_error_rad())
        self.late = traj.t_s >= SETTLED_S
        self.names = traj.variant_names

    def rms_late(self, name: str) -> float:
        return float(np.sqrt(np.mean(self.err[self.names.index(name), self.late] ** 2)))

    def at(self, name: str, t_s: float) -> float:
        return float(self.err[self.names.index(name), np.searchsorted(self.traj.t_s, t_s)])

    def events(self, name: str) -> list:
        return self.traj.events[self.names.index(name)]

    def settling(self, name: str) -> float:
        return float(self.traj.settling_time_s()[self.names.index(name)])

    def band_deg(self) -> float:
        """The nominal's friction band (:func:`_friction_band`) at the fastest wheel speed after SETTLED_S, deg."""
        speed = np.max(np.abs(self.traj["wheel_speed_rad_s"][self.names.index("nominal"), self.late]))
        return float(np.degrees(_friction_band(scenario_library.get("song-table1"), speed)))


@pytest.fixture(scope="module")
def without_fdir() -> Outcome:
    return Outcome(simulate(_song("star_tracker"), fdir=False))


@pytest.fixture(scope="module")
def with_fdir() -> Outcome:
    return Outcome(simulate(_song("mekf"), fdir=True))


def test_abrupt_controller_fault_leaves_the_deviation_the_pd_balance_predicts(without_fdir):
    """Seed 002: 'a large deviation from the expected value'. PD balance k_p·2 sin(θ/2) = bias."""
    s = scenario_library.get("song-table1")
    bias = faults.SEED002_MAGNITUDES["controller_bias_nm"]
    expected_deg = np.degrees(2.0 * np.arcsin(bias / s.controller.pd_kp_nm))
    assert without_fdir.at("controller abrupt 7 s", DURATION_S - 1.0) == pytest.approx(expected_deg, rel=0.02)


def test_intermittent_controller_fault_recovers_but_does_not_lengthen_settling_on_this_bus(without_fdir):
    """Seed 002 says the response takes longer; a 1 s outage at 7 s of a 29 s settling does not here."""
    name = "controller intermittent 7-8 s"
    assert without_fdir.rms_late(name) < 2.0 * without_fdir.rms_late("nominal")
    assert abs(without_fdir.settling(name) - without_fdir.settling("nominal")) < SETTLING_SAME_S


def test_nominal_error_is_the_wheels_friction_balance(without_fdir):
    """Module docstring: a wheel beyond the Coulomb saturation speed Ω° all through the late window holds its axis at
    θ = 2 (K_nl sign Ω + K_l Ω + J_r Ω̇)/K_p (Ω̇ the external torque it stores, fitted from its speeds), within the gyro
    drift's 2 K_d/K_p · 3σ_b; the whole error stays inside the friction band."""
    s = scenario_library.get("song-table1")
    w, v = s.spacecraft.cluster.wheels[0], without_fdir.names.index("nominal")
    t = without_fdir.traj.t_s
    late = t >= 2.0 * SETTLED_S  # the gravity gradient has spun one wheel past Ω° by then
    speeds = without_fdir.traj["wheel_speed_rad_s"][v, late]
    beyond = np.all(np.abs(speeds) > w.coulomb_sat_speed_rad_s, axis=0)
    assert beyond.sum() >= 1
    q = without_fdir.traj["q_ib"][v, late]
    theta = 2.0 * q[:, 1:] * np.sign(q[:, :1])  # small-angle error per body axis (reference: identity)
    kp, kd = s.controller.pd_kp_nm, s.controller.pd_kd_nms
    for axis in np.nonzero(beyond)[0]:  # orthogonal3: wheel i on body axis i
        sp = speeds[:, axis]
        stored = w.inertia_kg_m2 * np.polyfit(t[late], sp, 1)[0]
        expected = 2.0 * (w.coulomb_nm * np.sign(sp.mean()) + w.viscous_nm_s * sp.mean() + stored) / kp
        drift = 2.0 * kd * 3.0 * s.sensors.gyro_markov_sigma_rad_s / kp
        assert abs(theta[:, axis].mean() - expected) <= drift
    assert without_fdir.rms_late("nominal") < without_fdir.band_deg()


def test_stuck_wheel_3_frees_its_axis_and_the_attitude_is_not_stabilised(without_fdir):
    """Seed 002 Fig. 30: 'the system cannot be stabilized' (it claims no ratio). Wheel 3 seized, the z axis has no
    actuator: its momentum changes by the gravity-gradient torque alone, J_z Δω_z = ∫ (3μ/|r|⁵ r_b × J r_b)_z dt
    (written out here, from the recorded orbit and attitude), so the error grows without bound while the other two
    axes stay controlled. It keeps growing and ends beyond ``NOT_STABILISED`` × the nominal's friction band (with
    ideal wheels it was > 100× the 4.5e-4° nominal; the friction floor is 13× higher, the drift the same)."""
    s = scenario_library.get("song-table1")
    v = without_fdir.names.index("wheel 3 stuck")
    t, j = without_fdir.traj.t_s, np.asarray(s.spacecraft.inertia_kg_m2)
    q, r = without_fdir.traj["q_ib"][v], without_fdir.traj["r_eci_m"][v]
    r_b = quaternion.rotate(quaternion.conjugate(q), r)
    m_gg = 3.0 * orbit.MU_EARTH_M3_S2 / np.linalg.norm(r_b, axis=1)[:, None] ** 5 * np.cross(r_b, r_b @ j.T)
    impulse = np.concatenate([[0.0], np.cumsum(0.5 * (m_gg[1:, 2] + m_gg[:-1, 2]) * np.diff(t))])
    h_z = j[2, 2] * without_fdir.traj["omega_b_rad_s"][v, :, 2]
    k0 = np.searchsorted(t, 10.0)  # after the seizure's momentum dump
    for k in np.searchsorted(t, [SETTLED_S, 500.0, DURATION_S - 1.0]):
        assert h_z[k] - h_z[k0] == pytest.approx(impulse[k] - impulse[k0], rel=MOMENTUM_TOLERANCE)
    err = [without_fdir.at("wheel 3 stuck", tt) for tt in (SETTLED_S, 500.0, 750.0, DURATION_S - 1.0)]
    assert all(a < b for a, b in zip(err, err[1:]))
    assert err[-1] > 2.0 * err[1]  # still diverging (a growing torque impulse: faster than linear)
    assert err[-1] > NOT_STABILISED * without_fdir.band_deg()


def test_wheel_3_gain_loss_does_not_destabilise_the_pd_loop_here(without_fdir):
    """Seed 002 reports instability for a multiplicative fault; 70 % gain loss only slows our z axis."""
    assert without_fdir.rms_late("wheel 3 multiplicative") < 2.0 * without_fdir.rms_late("nominal")


@pytest.mark.parametrize("name", ["wheels 1,2", "wheels 1,3", "wheels 2,3", "wheels 1,2,3"])
def test_two_or_three_failed_wheels_lose_the_attitude(without_fdir, with_fdir, name):
    assert without_fdir.at(name, SETTLED_S) > LOST_DEG
    assert with_fdir.at(name, SETTLED_S) > LOST_DEG  # FDIR cannot fly three axes on one wheel…
    assert any(n == "mode_change" for _, n, _ in with_fdir.events(name))  # …and says so: fault mode


def test_graded_attitude_sensor_fault_accumulates_its_drift_into_the_attitude(without_fdir):
    """Seed 002: 'a cumulative deviation in the attitude angle' — the loop follows the sensor ramp."""
    rate = faults.SEED002_MAGNITUDES["attitude_drift_rad_s"]
    for t in (500.0, DURATION_S - 1.0):
        expected = np.degrees(rate * (t - faults.SEED002_ONSET_S))
        assert without_fdir.at("attitude sensor graded", t) == pytest.approx(expected, rel=RAMP_TRACKING)


def test_graded_gyro_fault_grows_the_error_and_both_together_grow_it_more(without_fdir):
    """A gyro bias b = a (t − t_s) on one axis enters the rate term: J θ̈ = −(K_p/2) θ − K_d (θ̇ + b) is followed by
    θ = −(2 K_d a/K_p)(t − t_s − 2 K_d/K_p) (the ramp, one time constant 2 K_d/K_p late), to ``RAMP_TRACKING``."""
    s = scenario_library.get("song-table1")
    a, kp, kd = faults.SEED002_MAGNITUDES["gyro_drift_rad_s2"], s.controller.pd_kp_nm, s.controller.pd_kd_nms
    for t in (SETTLED_S, 500.0, DURATION_S - 1.0):
        expected = np.degrees(2.0 * kd * a / kp * (t - faults.SEED002_ONSET_S - 2.0 * kd / kp))
        assert without_fdir.at("gyro graded", t) == pytest.approx(expected, rel=RAMP_TRACKING)
    assert without_fdir.rms_late("gyro + attitude sensor graded") > without_fdir.rms_late("attitude sensor graded")


def test_more_measurement_noise_gives_more_deviation(without_fdir):
    """Seed 002 §3.2.4: the greater the noise, the greater the deviation (nominal < 10σ < 50σ)."""
    rms = [without_fdir.rms_late(n) for n in ("nominal", "noise 10 sigma", "noise 50 sigma")]
    assert rms[0] < rms[1] < rms[2]


def test_fdir_isolates_the_stuck_wheel_and_recovers_on_two_wheels_and_the_md(without_fdir, with_fdir):
    """The seized wheel withholds the ~2e-5 N·m the law asks of it: that is observable once the withheld momentum
    over some window outgrows the noise momentum seed 002's K_x puts there (fdir.observable_time, perfect
    tachometer; ≈ 18 s after the onset: (a/m T_u)² ≈ 180 periods); it is isolated within ``OBSERVABLE_WINDOW_S`` of
    that, on wheel 3 only, and the loop recovers into the nominal's friction band on two wheels + MD."""
    s = scenario_library.get("song-table1")
    isolated = [(t, arg) for t, n, arg in with_fdir.events("wheel 3 stuck") if n == "fault_isolated"]
    assert [arg for _, arg in isolated] == [2]
    v = with_fdir.names.index("wheel 3 stuck")
    t = with_fdir.traj.t_s
    cmd = with_fdir.traj["wheel_torque_cmd_nm"][v, :, 2]
    noise = fdir.wheel_noise_bound(
        np.array([s.spacecraft.cluster.wheels[2].noise_nm]),
        s.dynamics_dt_s,
        s.control_dt_s,
        fdir.FALSE_ALARM_PROBABILITY,
    )[0]
    j_r = engine.plant_params(s).wheels.inertia_kg_m2[2]
    onset = faults.SEED002_ONSET_S
    seen = fdir.observable_time(t, cmd, np.where(t >= onset, 0.0, cmd), onset, j_r, 0.0, float(noise), s.control_dt_s)
    assert seen is None or isolated[0][0] - seen <= OBSERVABLE_WINDOW_S  # None: isolated before it was
    end = DURATION_S - 1.0
    assert with_fdir.at("wheel 3 stuck", end) < without_fdir.band_deg()
    assert without_fdir.at("wheel 3 stuck", end) > NOT_STABILISED * without_fdir.band_deg()


def test_fdir_isolates_the_gyro_drift_and_recovers(without_fdir, with_fdir):
    isolated = [arg for _, n, arg in with_fdir.events("gyro graded") if n == "fault_isolated"]
    assert isolated and isolated[0] // 10 == (100 + 10) // 10  # the gyro
    end = DURATION_S - 1.0
    assert with_fdir.at("gyro graded", end) < 0.01 * without_fdir.at("gyro graded", end)


def test_fdir_cannot_tell_a_slow_attitude_sensor_drift_from_a_gyro_bias(without_fdir, with_fdir):
    """Two sensors, one ramp: indistinguishable from a constant gyro bias, so not caught (said in fdir)."""
    assert not any(n == "fault_isolated" for _, n, _ in with_fdir.events("attitude sensor graded"))
    end = DURATION_S - 1.0
    name = "attitude sensor graded"
    assert with_fdir.at(name, end) == pytest.approx(without_fdir.at(name, end), rel=0.05)


@pytest.fixture(scope="module")
def somov_pairs():
    s = scenario_library.get("somov-ge4-scan")
    fs, mask = faults.seed000_two_wheels()
    pair = {"name": "wheels 2+4 + MD", "faults": [f.model_dump() for f in fs]}
    s = Scenario.model_validate({**s.model_dump(), "variants": [{"name": "all wheels"}, pair]})
    traj = simulate(s, wheel_available=np.array([[True] * 4, mask]), fdir=True)
    obs = traj["observing"] > 0
    err = traj.pointing_error_rad() / ARCSEC
    return [float(np.sqrt(np.mean(err[v, obs[v]] ** 2))) for v in range(2)], traj


def test_wheels_2_and_4_with_the_md_fly_the_scan_near_the_four_wheel_accuracy(somov_pairs):
    """Seed 000 §5, Figs 5–7: 'a nearness of the accuracy characteristics' (here 3.2″ vs 4.1″ RMS)."""
    (rms_all, rms_pair), traj = somov_pairs
    assert rms_all < 10.0 and rms_pair < 10.0
    assert rms_pair < 2.0 * rms_all
    assert np.max(np.abs(traj["md_dipole_am2"][1])) <= 25.0 + 1e-9  # l^m = 25 A·m²
    assert np.max(np.abs(traj["md_dipole_am2"][1])) > 0.0


def test_faults_table_lists_the_eleven_configurations(tmp_path):
    from backend.cli import main

    out, table_md = tmp_path / "table.json", tmp_path / "table.md"
    assert main(["faults-table", "--out", str(out), "--out", str(table_md)]) == 0
    rows = {r["configuration"]: r for r in json.loads(out.read_text())["configurations"]}
    assert len(rows) == 11
    lines = table_md.read_text().splitlines()  # the format its name says: a Markdown table, 11 rows
    assert lines[0].startswith("| configuration |") and len(lines) == 2 + 11
    for name in ["all wheels"] + [f"without wheel {p}" for p in range(1, 5)]:
        assert rows[name]["route_flown"] and rows[name]["kappa_fraction"] is None
        assert rows[name]["max_roll_rate_deg_s"] <= rows["all wheels"]["max_roll_rate_deg_s"]
    assert rows["wheels 2+4 + MD"]["route_flown"]
    assert all(0.0 < rows[n]["kappa_fraction"] < 1.0 for n in rows if "+ MD" in n)
    for name, row in rows.items():  # a pair that misses the scanning accuracy says why, with figures
        assert (row["pointing_rms_seed_law_arcsec"] is not None) == ("+ MD" in name)
        if "+ MD" in name and not row["route_flown"]:
            why = row["why_not_flown"]
            assert ("geometry" in why or "dipole limit" in why) and "A·m²" in why and "from the pair normal" in why
        else:
            assert row["why_not_flown"] is None


@pytest.mark.parametrize("name", ["noise 10 sigma", "noise 50 sigma"])
def test_fdir_rescales_a_noisy_star_tracker_instead_of_locking_it_out(without_fdir, with_fdir, name):
    """Seed 002 §3.2.4 noise is no fault to isolate for good: σ is rescaled and the accuracy stays within
    3× of the loop without FDIR (which uses the noisy tracker directly)."""
    from sim_core.fdir import SENSOR_ARG

    assert any(n == "reconfigured" and arg == SENSOR_ARG + 21 for _, n, arg in with_fdir.events(name))
    assert with_fdir.rms_late(name) < 3.0 * without_fdir.rms_late(name)
