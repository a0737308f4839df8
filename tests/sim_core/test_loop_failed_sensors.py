"""A failed sensor is read by nothing in the loop (closed_loop: the validity faults.held_sensor_faults_1 returns):

- a failed magnetometer's output (what it would show: its field, under any other fault of it) changes no series and
  no event of a flight: a bias and a noise fault on top of the failure leave the flight bit-identical to the failure
  alone, while before the failure the magnetometer is read (the MEKF without a star sample, its FDIR monitor);
- two wheels + MD whose magnetometer has failed from t = 0 fly the flight of the same pair without a magnetic driver
  (l^m = 0), bit for bit: without a field no dipole gives a torque L × B, so the pair gives the in-plane part of
  M^r either way (seed 000 §3); only the status says why (allocation.STATUS_NO_FIELD against STATUS_NO_DRIVER);
  a failure at t_f leaves the flight before it as the nominal pair's and zeroes the dipole from t_f on;
- a failed gyro's rate reaches neither the MEKF's estimate nor seed 002's observer (a bias on top of the failure
  changes nothing);
- TRIAD pairs no vector with a magnetometer that gives no valid sample.
"""

import numpy as np
import pytest

from sim_core import allocation, engine, estimation, faults, scenario_library
from sim_core.scenario import FaultSpec, Scenario, VariantSpec
from sim_core.trajectory import Trajectory

T_F = 200.0  # the sensor's failure onset (s)
STAR_OUT_S = 100.0  # the star tracker fails first: the MEKF then reads the earth sensor and the magnetometer
MAG_BIAS_T = 2e-5  # 400 σ of the 50 nT magnetometer: read by anything, it would move the flight
MAG_NOISE_FACTOR = 10.0
GYRO_BIAS_RAD_S = 1e-3  # 0.06 °/s: read, it would turn the estimate by degrees within minutes


def _fault(target: str, kind: str, onset_s: float, index: int = 0, value: float = 0.0) -> FaultSpec:
    return FaultSpec(target=target, index=index, type=kind, onset_s=onset_s, value=value)


def _scenario(name: str, duration_s: float, fault_specs: list[FaultSpec]) -> dict:
    """One variant: each flight flown alone draws the same random stream (the engine seeds variant i apart)."""
    data = scenario_library.get(name).model_dump()
    data.update(duration_s=duration_s, output_dt_s=2.0)
    data["variants"] = [VariantSpec(name="v", faults=fault_specs).model_dump()]
    return data


def _fly(name: str, duration_s: float, fault_specs: list[FaultSpec], fdir: bool = False) -> Trajectory:
    return engine.simulate(Scenario.model_validate(_scenario(name, duration_s, fault_specs)), fdir=fdir)


def _assert_same_flight(a: Trajectory, b: Trajectory) -> None:
    """Every series and event of two flights equal, but the fault table's own (flags, onsets): b flies more fault
    rows."""
    for name, series in a.series.items():
        if name != "fault_flags":
            np.testing.assert_array_equal(series, b[name], err_msg=name)
    table = ("fault_onset", "fault_cleared")
    assert [e for e in a.events[0] if e[1] not in table] == [e for e in b.events[0] if e[1] not in table]


def _differs_from(a: Trajectory, b: Trajectory, name: str, t_s: float) -> None:
    """Series ``name`` of two flights equal before t_s and not after."""
    before = a.t_s < t_s
    np.testing.assert_array_equal(a[name][0][before], b[name][0][before])
    assert np.any(a[name][0][~before] != b[name][0][~before])


def test_a_failed_magnetometer_is_read_by_nothing():
    star_out = [_fault("star_tracker", "failure", STAR_OUT_S)]
    failed = [*star_out, _fault("magnetometer", "failure", T_F)]
    corrupted = [*failed, _fault("magnetometer", "bias", T_F, 0, MAG_BIAS_T)]
    corrupted += [_fault("magnetometer", "noise", T_F, i, MAG_NOISE_FACTOR) for i in range(3)]
    flights = [_fly("somov-ge4-scan", 400.0, f, fdir=True) for f in (star_out, failed, corrupted)]
    _assert_same_flight(flights[1], flights[2])
    # the magnetometer was read until it failed: its loss changes the estimate from t_f on, not before
    _differs_from(flights[0], flights[1], "q_est_ib", T_F)
    after = flights[1].t_s >= T_F
    assert np.all(flights[1]["b_mag_b_t"][0][after] == 0.0) and np.all(flights[1]["b_mag_b_t"][0][~after] != 0.0)


def _pair(duration_s: float, fault_specs: list[FaultSpec], md_max_am2: float) -> Trajectory:
    """somov-ge4-scan's route on wheels 1+3 (the roll axis in their plane) with the least-dipole MD law."""
    all_variants, masks = faults.configuration_variants(4)
    (keep,) = [v for v, m in enumerate(masks) if m.sum() == 2 and m[[0, 2]].all()]
    data = _scenario("somov-ge4-scan", duration_s, [*all_variants[keep].faults, *fault_specs])
    data["allocation"]["md_law"] = "least_dipole"
    data["spacecraft"]["md_max_dipole_am2"] = md_max_am2
    return engine.simulate(Scenario.model_validate(data), wheel_available=masks[keep][None], fdir=False)


def test_two_wheels_without_a_magnetometer_fly_as_without_a_driver():
    no_field = _pair(300.0, [_fault("magnetometer", "failure", 0.0)], 25.0)
    no_driver = _pair(300.0, [], 0.0)
    assert np.all(no_field["allocation_status"][0] == allocation.STATUS_NO_FIELD)
    assert np.all(no_driver["allocation_status"][0] == allocation.STATUS_NO_DRIVER)
    assert np.all(no_field["md_dipole_am2"][0] == 0.0)
    for name in ("q_ib", "omega_b_rad_s", "wheel_speed_rad_s", "wheel_torque_cmd_nm", "control_torque_b_nm"):
        np.testing.assert_array_equal(no_field[name][0], no_driver[name][0], err_msg=name)


def test_two_wheels_lose_the_driver_when_the_magnetometer_fails():
    nominal, failed = _pair(400.0, [], 25.0), _pair(400.0, [_fault("magnetometer", "failure", T_F)], 25.0)
    before = nominal.t_s < T_F
    assert np.any(nominal["md_dipole_am2"][0][before] != 0.0)  # the pair needs the driver on this route
    _differs_from(nominal, failed, "q_ib", T_F)
    assert np.all(failed["md_dipole_am2"][0][~before] == 0.0)
    assert np.all(failed["allocation_status"][0][~before] == allocation.STATUS_NO_FIELD)


@pytest.mark.parametrize(("name", "duration_s"), [("somov-ge4-scan", 400.0), ("song-table1", 300.0)])
def test_a_failed_gyro_is_read_by_nothing(name, duration_s):
    """MEKF (somov-ge4-scan) and seed 002's gyro + earth-sensor observer (song-table1)."""
    failed = [_fault("gyro", "failure", T_F)]
    biased = [*failed, *[_fault("gyro", "bias", T_F, i, GYRO_BIAS_RAD_S) for i in range(3)]]
    nominal, failed_alone, failed_biased = (_fly(name, duration_s, f) for f in ([], failed, biased))
    _assert_same_flight(failed_alone, failed_biased)
    _differs_from(nominal, failed_alone, "omega_est_b_rad_s", T_F)


def test_triad_pairs_no_vector_with_a_magnetometer_without_a_sample():
    nadir_b, mag_b = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.6, 0.8])
    sun = np.array([0.0, 0.0, 1.0])
    q, ok = estimation.triad_sensors_1(sun, False, nadir_b, True, mag_b, True, sun, nadir_b, mag_b)
    assert ok and np.allclose(np.abs(q), [1.0, 0.0, 0.0, 0.0])
    _, ok = estimation.triad_sensors_1(sun, False, nadir_b, True, mag_b, False, sun, nadir_b, mag_b)
    assert not ok
