"""A flight flown in segments (sim_core.engine.Flight) is one flight: the joined segments equal one flight of the
summed duration bit for bit, whatever the seams cut (a scheduled turn, a fault and its isolation, the mode
machine's B-dot, wheel noise and imbalance, the gyro's Markov drift, several variants in threads).

Truths: the one-segment flight itself (the same kernels, no hand-over), and :func:`engine.simulate`, which
differs from it only in the date of the field model's last IGRF hour.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim_core import engine, quaternion, scenario_library
from sim_core.faults import parse_fault
from sim_core.scenario import VariantSpec
from sim_core.trajectory import Trajectory

ARCSEC = np.pi / 180.0 / 3600.0
# simulate dates its last IGRF hour at that hour's data, the flight at the whole hour's middle: < 1e-11 T apart
# (secular variation ≤ 200 nT/yr over ≤ 1 h). The loop reacts to it through the MD torque and the MEKF's field
# updates far below the star tracker's 3″ noise; 1e-3″ bounds it with room and is 3,000× below that noise.
FIELD_DATE_ATTITUDE_TOL_RAD = 1e-3 * ARCSEC


def _segments(s, lengths: list[float], **kwargs) -> list[Trajectory]:
    flight = engine.Flight(s, **kwargs)
    return [flight.fly(d) for d in lengths]


def _assert_one_flight(whole: Trajectory, parts: list[Trajectory]) -> None:
    np.testing.assert_array_equal(np.concatenate([p.t_s for p in parts]), whole.t_s)
    for name, series in whole.series.items():
        np.testing.assert_array_equal(np.concatenate([p.series[name] for p in parts], axis=1), series, err_msg=name)
    for v in range(whole.n_variants):
        assert [e for p in parts for e in p.events[v]] == whole.events[v]


def test_a_scheduled_turn_fault_and_isolation_cut_by_seams_fly_as_one_flight() -> None:
    base = scenario_library.get("somov-ge4-scan")  # MEKF, 20° turn 420–520 s
    data = base.model_dump()
    data["variants"] = [
        VariantSpec(name="nominal").model_dump(),
        VariantSpec(name="wheel", faults=[parse_fault("wheel:2:failure@500")]).model_dump(),
    ]
    s = type(base).model_validate(data)
    lengths = [451.35, 48.7, 99.95]  # seams inside the turn and 0.05 s after the failure, off every T_q/T_u/output
    whole = engine.Flight(s, fdir=True).fly(sum(lengths))
    parts = _segments(s, lengths, fdir=True)
    _assert_one_flight(whole, parts)
    assert any(name == "fault_isolated" for _, name, _ in whole.events[1])  # the FDIR state crossed a seam
    assert parts[0].t_s[-1] < 451.35 <= parts[1].t_s[0] == parts[0].t_s[-1] + s.output_dt_s


@pytest.mark.parametrize(
    ("name", "lengths"),
    [
        ("song-table1", [73.3, 126.7]),  # wheel noise and imbalance, gyro Markov drift, motor electrics
        ("somov-detumble-to-scan", [61.05, 138.95]),  # mode machine: B-dot rate damping from a tumble
        ("somov-ge4-scan", [3000.0, 1000.0]),  # the second segment adds a whole IGRF hour of field rows
    ],
)
def test_seed_models_and_the_mode_machine_fly_across_seams(name: str, lengths: list[float]) -> None:
    s = scenario_library.get(name)
    _assert_one_flight(engine.Flight(s).fly(sum(lengths)), _segments(s, lengths))


def test_a_flight_is_simulate_but_for_the_date_of_its_last_igrf_hour() -> None:
    s = scenario_library.get("somov-ge4-scan").model_copy(update={"duration_s": 600.0})
    flown, simulated = engine.Flight(s).fly(600.0), engine.simulate(s)
    np.testing.assert_array_equal(flown.t_s, simulated.t_s)
    angle = quaternion.angle(quaternion.multiply(quaternion.conjugate(flown["q_ib"]), simulated["q_ib"]))
    assert np.max(angle) < FIELD_DATE_ATTITUDE_TOL_RAD


def test_a_segment_must_be_whole_dynamics_steps() -> None:
    flight = engine.Flight(scenario_library.get("somov-ge4-scan"))
    for bad in (0.0, -1.0, 0.07, float("nan")):
        with pytest.raises(ValueError, match="duration_s: expected a whole number"):
            flight.fly(bad)
    assert flight.flown_s == 0.0
