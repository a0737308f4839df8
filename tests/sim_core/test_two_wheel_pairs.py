"""Seed 000 §3/§8: after a fault of any two wheels, the remaining pair + the magnetic driver keep the spacecraft
stable and pointing, "with some decrease in the rotation manoeuvre rate". Every GE pair flies somov-ge4-scan's
route with the least-dipole MD law (sim_core.allocation.MD_LAW_PAIR_NORMAL) for 1,800 s, beside the four wheels.

Truths: while the rods are not saturated the allocation reproduces the law's torque exactly, so a pair scans like
the four wheels; a pair whose plane holds the roll axis (GE wheels 1+3 and 2+4: ⟨e_y, a_p × a_q⟩ = 0) needs the
MD only for the small gravity-gradient and gyroscopic torques and flies the whole route; the others cannot roll
20° in 100 s (the turn asks more torque across their plane than 25 A·m² rods give, whatif.pair_limit's figures)
but a stable loop never strays beyond the roll it could not follow and comes back to the scanning budget.
"""

import numpy as np
import pytest

from sim_core import allocation, faults, scenario_library, whatif
from sim_core.engine import plant_params, simulate
from sim_core.scenario import Scenario
from sim_core.trajectory import ARCSEC_PER_RAD

pytestmark = pytest.mark.slow  # six 1,800-s flights: scheduled first (tests/conftest.py)

DURATION_S = 1800.0
ROLL_DEG = 20.0  # the route's roll between its two courses
SCAN_RMS_ARCSEC = 10.0  # seed 000 §5 asks a few arcsec; the four wheels give ~3″
RECOVERED_S = 300.0  # the last stretch of the flight, long after the turn, must be back within the scan budget
PAIR_NAMES = ["1+2", "1+3", "1+4", "2+3", "2+4", "3+4"]


@pytest.fixture(scope="module")
def pairs_flight():
    s = scenario_library.get("somov-ge4-scan")
    variants, masks = faults.configuration_variants(4)
    keep = [0] + [v for v, m in enumerate(masks) if m.sum() == 2]
    data = s.model_dump()
    data["duration_s"] = DURATION_S
    data["allocation"]["md_law"] = "least_dipole"
    data["variants"] = [variants[v].model_dump() for v in keep]
    s = Scenario.model_validate(data)
    traj = simulate(s, wheel_available=masks[keep], fdir=True)
    return s, traj, masks[keep]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


@pytest.mark.parametrize("name", PAIR_NAMES)
def test_every_wheel_pair_with_the_md_stays_stable_and_points(pairs_flight, name):
    s, traj, masks = pairs_flight
    pair = [int(w) - 1 for w in name.split("+")]
    v = next(i for i, m in enumerate(masks) if m.sum() == 2 and m[pair].all())
    err = traj.pointing_error_rad() * ARCSEC_PER_RAD
    t, observing = traj.t_s, traj["observing"][v] > 0
    turn_start = s.guidance.route_start_s + s.guidance.route[0].duration_s
    first = observing & (t < turn_start)
    assert first.sum() > 100

    # first course: the allocation is exact (rods within their limit), so the pair scans like the four wheels
    assert np.all(traj["allocation_status"][v][first] == allocation.STATUS_OK)
    assert _rms(err[v, first]) < max(2.0 * _rms(err[0, first]), SCAN_RMS_ARCSEC)
    # stable: never beyond the roll it could not follow, and back within the scanning budget
    assert np.max(err[v]) < ROLL_DEG * 3600.0
    assert np.max(err[v, t > DURATION_S - RECOVERED_S]) < whatif.ROUTE_FLOWN_ARCSEC

    axes = plant_params(s).wheel_axes_b
    normal = np.cross(axes[:, pair[0]], axes[:, pair[1]])
    roll_across = abs(normal[1]) / np.linalg.norm(normal)
    if roll_across < 1e-9:  # the roll axis lies in the pair's plane: the whole route at scanning accuracy
        assert _rms(err[v, observing]) < SCAN_RMS_ARCSEC
        assert np.max(err[v, observing]) < whatif.ROUTE_FLOWN_ARCSEC
    else:  # the turn asks torque across the plane beyond the rods: the table says so, with figures
        assert roll_across > 0.5
        why = whatif.pair_limit(s, masks[v])
        assert why.startswith(("dipole limit", "geometry")) and "A·m²" in why
