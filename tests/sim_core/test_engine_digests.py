"""Bit-identity of the flight engine: every series and event of a handful of representative flights hashes
(SHA-256) to the digests stored in ``data/engine_digests.json``.

A change meant to be a pure refactor or speed-up must leave these flights bit-identical. A change meant to alter
results (new physics, a fixed bug) regenerates the file in the same commit and says why:

    PYTHONPATH=. python -m tests.sim_core.test_engine_digests --write

The digests hold for the platform recorded in the file (numba compiles for the host CPU; LAPACK picks its kernels
by CPU): on another machine regenerate them from the commit before your change, then apply the change.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba
import numpy as np
import pytest

from sim_core import engine, faults, scenario_library
from sim_core.scenario import Scenario
from sim_core.trajectory import Trajectory

DIGESTS = Path(__file__).parent / "data" / "engine_digests.json"

Flight = tuple[Scenario, dict[str, Any]]


def _library(name: str, duration_s: float | None = None, **update: Any) -> dict[str, Any]:
    data = scenario_library.get(name).model_dump()
    if duration_s is not None:
        data["duration_s"] = duration_s
    data.update(update)
    return data


def _wheel_faults() -> Flight:
    """peer-basilisk-rw4 with one variant per wheel fault type, onsets inside the orbit's first slews."""
    fault_rows = {
        "nominal": [],
        "failure 1": [{"target": "wheel", "index": 0, "type": "failure", "onset_s": 200.0}],
        "stuck 2": [{"target": "wheel", "index": 1, "type": "stuck", "onset_s": 950.0}],
        "gain 3": [{"target": "wheel", "index": 2, "type": "gain", "onset_s": 100.0, "gain": 0.5}],
        "friction 4": [{"target": "wheel", "index": 3, "type": "friction", "onset_s": 50.0, "value": 2e-3}],
        "intermittent 1": [{"target": "wheel", "index": 0, "type": "intermittent", "period_s": 40.0, "duty": 0.3}],
        "frozen controller": [{"target": "controller", "type": "frozen", "onset_s": 990.0, "duration_s": 30.0}],
    }
    data = _library("peer-basilisk-rw4", 1500.0)
    data["variants"] = [{"name": n, "faults": f} for n, f in fault_rows.items()]
    return Scenario.model_validate(data), {"fdir": [False, True, True, True, False, False, False]}


def _seed_models() -> Flight:
    """somov-ge4-scan (MEKF, seed 000 law) with every seed model of issue 13 switched on, plus gyro and star-tracker
    faults under FDIR."""
    data = _library("somov-ge4-scan", 900.0)
    sc = data["spacecraft"]
    for w in sc["cluster"]["wheels"]:
        w.update(aero_drag_nm_s15=1e-8, noise_nm=1e-5, imbalance_nm_s2=1e-10, torque_quantum_nm=1e-4)
    sc["cluster"]["motor"] = {}
    sc["flex_modes"] = scenario_library.get("somov-ge4-scan-flex").model_dump()["spacecraft"]["flex_modes"]
    sc["residual_dipole_am2"] = [0.1, -0.05, 0.2]
    sc["surfaces"] = [
        {"normal_b": [0.0, 1.0, 0.0], "area_m2": 2.0, "centroid_b_m": [0.3, 0.4, 0.2]},
        {"normal_b": [0.0, 0.0, 1.0], "area_m2": 1.5, "centroid_b_m": [0.1, 0.2, 0.6]},
    ]
    data["aerodynamic_torque"] = data["solar_pressure_torque"] = True
    data["sensors"].update(
        gyro_markov_sigma_rad_s=1e-6,
        star_tracker_sun_exclusion_deg=30.0,
        star_tracker_max_rate_rad_s=0.01,
        tachometer_quantum_rad_s=0.25 * np.pi / 30.0,
    )
    data["variants"] = [
        {"name": "nominal"},
        {
            "name": "gyro bias",
            "faults": [{"target": "gyro", "index": 1, "type": "bias", "onset_s": 300.0, "value": 1e-4}],
        },
        {"name": "star tracker out", "faults": [{"target": "star_tracker", "type": "failure", "onset_s": 200.0}]},
    ]
    return Scenario.model_validate(data), {"fdir": True}


def _two_wheels_md() -> Flight:
    """somov-ge4-scan's route on wheel pairs 1+3 (roll axis in its plane) and 1+2 with the least-dipole MD law."""
    variants, masks = faults.configuration_variants(4)
    keep = [v for v, m in enumerate(masks) if m.sum() == 2 and (m[[0, 2]].all() or m[[0, 1]].all())]
    data = _library("somov-ge4-scan", 900.0)
    data["allocation"]["md_law"] = "least_dipole"
    data["variants"] = [variants[v].model_dump() for v in keep]
    return Scenario.model_validate(data), {"wheel_available": masks[keep], "fdir": True}


def _estimator(kind: str) -> Callable[[], Flight]:
    def build() -> Flight:
        data = _library("somov-ge4-scan", 600.0)
        data["estimator"]["kind"] = kind
        return Scenario.model_validate(data), {}

    return build


def _plain(name: str, duration_s: float | None = None) -> Callable[[], Flight]:
    return lambda: (Scenario.model_validate(_library(name, duration_s)), {})


FLIGHTS: dict[str, Callable[[], Flight]] = {
    "peer-basilisk-rw4 one orbit": _plain("peer-basilisk-rw4"),
    "peer-basilisk-rw4 wheel faults": _wheel_faults,
    "somov-ge4-scan every seed model": _seed_models,
    "somov-ge4-scan two wheels + MD": _two_wheels_md,
    "somov-ge4-scan triad": _estimator("triad"),
    "somov-ge4-scan seed000 filter": _estimator("seed000_filter"),
    "somov-ge4-scan seed003 rate": _estimator("seed003_rate"),
    "somov-detumble-to-scan modes": _plain("somov-detumble-to-scan", 4000.0),  # three mode changes,
    "song-table1": _plain("song-table1", 300.0),  # seed 002: Earth pointing on the eq-15 observer, wheel models
}


def _platform() -> str:
    return f"{platform.machine()} {platform.processor() or platform.platform()}; numpy {np.__version__}, numba {numba.__version__}"


def _digest(*parts: bytes) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(part)
    return h.hexdigest()


def flight_digests(traj: Trajectory) -> dict[str, str]:
    """SHA-256 of each series (dtype, shape and bytes), of the time axis and of the events of every variant."""
    out = {"t_s": _digest(np.ascontiguousarray(traj.t_s).tobytes())}
    for name in sorted(traj.series):
        a = np.ascontiguousarray(traj.series[name])
        out[name] = _digest(str(a.dtype).encode(), str(a.shape).encode(), a.tobytes())
    out["events"] = _digest(repr(traj.events).encode())
    return out


def fly(name: str) -> dict[str, str]:
    scenario, options = FLIGHTS[name]()
    return flight_digests(engine.simulate(scenario, **options))


@pytest.fixture(scope="module")
def stored() -> dict[str, Any]:
    return json.loads(DIGESTS.read_text())


@pytest.mark.parametrize("name", list(FLIGHTS))
def test_flight_is_bit_identical_to_the_stored_digests(stored, name):
    expected = stored["flights"][name]
    got = fly(name)
    changed = sorted(k for k in expected.keys() | got.keys() if expected.get(k) != got.get(k))
    assert not changed, (
        f"{name}: {changed} differ from {DIGESTS.name} (recorded on {stored['platform']}; here {_platform()}). "
        "If the change is meant to alter results, regenerate with "
        "`PYTHONPATH=. python -m tests.sim_core.test_engine_digests --write` and say why in the commit."
    )


def main() -> None:
    parser = argparse.ArgumentParser(description="Regenerate (--write) or check the engine's stored digests.")
    parser.add_argument("--write", action="store_true", help=f"overwrite {DIGESTS}")
    args = parser.parse_args()
    flights = {name: fly(name) for name in FLIGHTS}
    if args.write:
        DIGESTS.write_text(json.dumps({"platform": _platform(), "flights": flights}, indent=1) + "\n")
        print(f"wrote {len(flights)} flights to {DIGESTS}")
        return
    stored = json.loads(DIGESTS.read_text())["flights"]
    for name, got in flights.items():
        print(f"{name}: {'same' if stored.get(name) == got else 'DIFFERENT'}")


if __name__ == "__main__":
    main()
