"""The seeds' fault experiments, each asserted against the outcome the seed states (or, where our
physics disagrees, against what it gives, said so in the test name).

Seed 002 §3.2 on the ``song-table1`` bus (three orthogonal wheels, quaternion PD), 1,000 s of
Earth pointing as the scenario's description says: without reconfiguration (the paper's runs, star
tracker as attitude sensor) and with our FDIR (MEKF + screening + wheel isolation). The seed's
Table 1 is garbled, so magnitudes are :data:`sim_core.faults.SEED002_MAGNITUDES`. Seed 000 §5:
wheels 2 and 4 with the magnetic driver fly the trace-scanning route near the 4-wheel accuracy;
and the 11-configuration table of issue 4 through ``acs-twin faults-table``.
"""

import json

import numpy as np
import pytest

from sim_core import faults, scenario_library
from sim_core.engine import simulate
from sim_core.scenario import Scenario, VariantSpec

DURATION_S = 1000.0
SETTLED_S = 200.0  # nominal settles from the 5° start in ~30 s; after 200 s only faults move the error
GROWTH = 100.0  # "destroyed stability": RMS error after SETTLED_S above 100× the nominal one
LOST_DEG = 10.0  # attitude lost: beyond 10° (the nominal holds a few arcsec)
RAMP_TRACKING = 0.1  # the loop follows a drifting attitude sensor to 10 % (PD lag at 5e-5 rad/s)
SETTLING_SAME_S = 2.0  # "no longer response" within 2 s of the nominal 29 s
ARCSEC = np.pi / 180.0 / 3600.0


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


def test_stuck_wheel_3_destroys_stability_on_three_orthogonal_wheels(without_fdir):
    err_mid, err_end = without_fdir.at("wheel 3 stuck", 500.0), without_fdir.at("wheel 3 stuck", DURATION_S - 1.0)
    assert without_fdir.rms_late("wheel 3 stuck") > GROWTH * without_fdir.rms_late("nominal")
    assert err_end > 2.0 * err_mid  # still diverging


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
    gyro = [without_fdir.at("gyro graded", t) for t in (200.0, 500.0, DURATION_S - 1.0)]
    assert gyro[0] < gyro[1] < gyro[2] and gyro[0] > GROWTH * without_fdir.rms_late("nominal")
    assert without_fdir.rms_late("gyro + attitude sensor graded") > without_fdir.rms_late("attitude sensor graded")


def test_more_measurement_noise_gives_more_deviation(without_fdir):
    """Seed 002 §3.2.4: the greater the noise, the greater the deviation (nominal < 10σ < 50σ)."""
    rms = [without_fdir.rms_late(n) for n in ("nominal", "noise 10 sigma", "noise 50 sigma")]
    assert rms[0] < rms[1] < rms[2]


def test_fdir_isolates_the_stuck_wheel_and_recovers_on_two_wheels_and_the_md(without_fdir, with_fdir):
    t_iso = next(t for t, n, arg in with_fdir.events("wheel 3 stuck") if n == "fault_isolated" and arg == 2)
    assert t_iso - faults.SEED002_ONSET_S <= 2 * scenario_library.get("song-table1").control_dt_s + 1e-9
    end = DURATION_S - 1.0
    assert with_fdir.at("wheel 3 stuck", end) < 0.01 * without_fdir.at("wheel 3 stuck", end)


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
