"""Bit-identity of the flight engine: every series and event of a handful of representative flights hashes
(SHA-256) to the digests stored in ``data/engine_digests.json`` for this platform.

The bits depend on the platform, not on the code alone: numba compiles for the host CPU (FMA, vector width), numpy
and OpenBLAS dispatch their kernels by CPU, numba's linear algebra calls scipy's LAPACK. So the file holds one set of
digests per platform, keyed by :func:`platform_key` (machine, llvmlite's host CPU name, a hash of its host CPU
features, numpy, numba and scipy versions, OPENBLAS_CORETYPE if set; the kernel version does not change the bits and is not in the key).

A change meant to be a pure refactor or speed-up must leave these flights bit-identical. A change meant to alter
results (new physics, a fixed bug) regenerates the file in the same commit and says why:

    PYTHONPATH=. python -m tests.sim_core.test_engine_digests --write

``--write`` replaces this platform's digests. A flight that changed here (its digest, or on a platform not recorded
before, its fingerprint beyond the tolerance) gets a new fingerprint and is dropped from the other platforms'
records: their bits for it are unknown now, and they check the fingerprint until someone records them. To record a
new platform without altering results, run ``--write`` there on the commit before your change.

On a platform with no digest recorded for a flight, bit-identity is not checked: the test warns
(:class:`UnrecordedPlatform`, naming the platform and how to record it) and compares the flight with its fingerprint,
the float64 values of ``FINGERPRINT_SERIES`` of every variant at ``FINGERPRINT_SAMPLES`` samples spread over the
flight, the last included. Tolerance of a series: another platform rounds differently by a few ulps in each step
(``ROUNDING_ULPS_PER_STEP`` = 4: an FMA, a reordered BLAS sum or another libm changes a rounding or two per chain),
each difference grown by the flight's error growth g, the largest deviation of any fingerprinted series, in ulps of
its largest magnitude, when the initial state is nudged by one ulp (measured at ``--write``); summed over the
flight's n dynamics steps: ``tol = 4 · n · g · ulp(max |series|)``. One g for the flight, not one per series: the
rounding also enters where the initial nudge barely reaches, and each series' own growth fell short (1.8 tol) for the
every-seed-model body rate under the Haswell kernels below. Measured when recorded (2026-12-03, rocketlake): g from 2.5 ulps (peer-basilisk-rw4 one orbit) to
1.26e4 (somov-ge4-scan every seed model); the other platforms emulated here (OpenBLAS kernels forced by
OPENBLAS_CORETYPE=Haswell, Sandybridge, Prescott, the last also with numpy's AVX2/AVX-512 loops off) moved the
fingerprints by at most 0.042 tol (every seed model's control torque), the other flights by at most 1.3e-5 tol;
numba compiling for a generic x86-64 CPU changed no bit, and OPENBLAS_CORETYPE=Haswell here reproduces bit for bit
the digests recorded before on another machine (its OpenBLAS kernels were the whole difference). A platform that flips a discrete decision (mode switch,
FDIR isolation, tachometer count) will leave the tolerance: the test then fails, and that platform is recorded
from the commit before the change.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import os
import platform
import re
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any
from unittest import mock

import llvmlite.binding
import numba
import numpy as np
import pytest
import scipy

from sim_core import engine, faults, scenario_library
from sim_core.scenario import Scenario
from sim_core.trajectory import Trajectory

DIGESTS = Path(__file__).parent / "data" / "engine_digests.json"
FINGERPRINT_SERIES = ("t_s", "q_ib", "omega_b_rad_s", "wheel_speed_rad_s", "control_torque_b_nm")
FINGERPRINT_SAMPLES = 6
ROUNDING_ULPS_PER_STEP = 4
RECORD = "PYTHONPATH=. python -m tests.sim_core.test_engine_digests --write"

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


class UnrecordedPlatform(UserWarning):
    """No digest of a flight is recorded for this platform: only its fingerprint was checked."""


def platform_key() -> str:
    """What determines the flights' bits: machine, host CPU name and features (numba compiles for them, OpenBLAS and
    numpy pick their kernels by them), OPENBLAS_CORETYPE if it overrides OpenBLAS's pick, numpy, numba and scipy
    versions."""
    features = llvmlite.binding.get_host_cpu_features().flatten()
    cpu = f"{llvmlite.binding.get_host_cpu_name()} features {hashlib.sha256(features.encode()).hexdigest()[:12]}"
    blas = f", OPENBLAS_CORETYPE {os.environ['OPENBLAS_CORETYPE']}" if "OPENBLAS_CORETYPE" in os.environ else ""
    versions = f"numpy {np.__version__}, numba {numba.__version__}, scipy {scipy.__version__}"
    return f"{platform.machine()} {cpu}; {versions}{blas}"


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


def _fingerprinted(traj: Trajectory) -> dict[str, np.ndarray]:
    """The fingerprint's series over the whole flight (variant, sample, …); the time axis as one row."""
    return {name: traj.t_s[None] if name == "t_s" else traj.series[name] for name in FINGERPRINT_SERIES}


def _samples(n_samples: int) -> np.ndarray:
    return (np.arange(1, FINGERPRINT_SAMPLES + 1) * (n_samples - 1)) // FINGERPRINT_SAMPLES


def _steps(name: str) -> int:
    scenario, _ = FLIGHTS[name]()
    return round(scenario.duration_s / scenario.dynamics_dt_s)


def fly(name: str, nudged: bool = False) -> Trajectory:
    """The flight ``name``; ``nudged``: its initial state (every variant's) moved up by one ulp."""
    scenario, options = FLIGHTS[name]()
    if not nudged:
        return engine.simulate(scenario, **options)
    pack_state = engine.pack_state
    with mock.patch.object(engine, "pack_state", lambda *a: np.nextafter(pack_state(*a), np.inf)):
        return engine.simulate(scenario, **options)


@functools.cache
def _flown(name: str) -> Trajectory:
    return fly(name)


def fingerprint(name: str, traj: Trajectory) -> dict[str, Any]:
    """Sampled values of the flight, one ulp of each series' largest magnitude and the flight's error growth: the
    largest deviation of any series, in those ulps, when the initial state is nudged by one ulp (at least 1)."""
    series, nudged = _fingerprinted(traj), _fingerprinted(fly(name, nudged=True))
    ulp = {k: float(np.spacing(np.abs(a).max())) for k, a in series.items()}
    growth = max(1.0, *(float(np.abs(nudged[k] - a).max()) / ulp[k] for k, a in series.items()))
    idx = _samples(traj.t_s.size)
    return {
        "steps": _steps(name),
        "growth_ulps": growth,
        "ulp": ulp,
        "samples": idx.tolist(),
        "values": {k: a[:, idx].tolist() for k, a in series.items()},
    }


def tolerance(record: dict[str, Any]) -> dict[str, float]:
    """Per series: ROUNDING_ULPS_PER_STEP ulps in each of the flight's steps, each grown by the flight's error growth
    (module doc)."""
    scale = ROUNDING_ULPS_PER_STEP * record["steps"] * record["growth_ulps"]
    return {k: scale * ulp for k, ulp in record["ulp"].items()}


def fingerprint_excess(record: dict[str, Any], traj: Trajectory) -> dict[str, float]:
    """Per series beyond its tolerance: the largest deviation from the fingerprint, in tolerances."""
    series, tol = _fingerprinted(traj), tolerance(record)
    out = {}
    for k, expected in record["values"].items():
        got = series[k][:, record["samples"]]
        excess = float(np.abs(got - np.array(expected)).max()) / tol[k] if got.shape == np.shape(expected) else np.inf
        if not excess <= 1.0:
            out[k] = excess
    return out


def check_flight(stored: dict[str, Any], name: str, traj: Trajectory) -> None:
    """Bit-identity with this platform's digests if recorded, else the fingerprint within tolerance and a warning."""
    key = platform_key()
    expected = stored["platforms"].get(key, {}).get(name)
    if expected is None:
        excess = fingerprint_excess(stored["fingerprints"][name], traj)
        assert not excess, (
            f"{name}: {excess} (deviation from the fingerprint in tolerances) on platform {key!r}, which has no "
            f"digest recorded for it. If the change is meant to alter results, regenerate with `{RECORD}` and say "
            "why in the commit."
        )
        warnings.warn(
            f"{name}: bit-identity not checked on platform {key!r} (no digest recorded for it), only the fingerprint "
            f"within its tolerance; record the platform with `{RECORD}` on the commit before your change.",
            UnrecordedPlatform,
            stacklevel=2,
        )
        return
    got = flight_digests(traj)
    changed = sorted(k for k in expected.keys() | got.keys() if expected.get(k) != got.get(k))
    assert not changed, (
        f"{name}: {changed} differ from {DIGESTS.name} on platform {key!r}. If the change is meant to alter "
        f"results, regenerate with `{RECORD}` and say why in the commit."
    )


@pytest.fixture(scope="module")
def stored() -> dict[str, Any]:
    return json.loads(DIGESTS.read_text())


@pytest.mark.parametrize("name", list(FLIGHTS))
def test_flight_matches_its_stored_record(stored, name):
    check_flight(stored, name, _flown(name))


CHEAPEST = "song-table1"


def test_a_changed_bit_fails():
    traj = _flown(CHEAPEST)
    digests = flight_digests(traj)
    recorded = {"platforms": {platform_key(): {CHEAPEST: digests}}, "fingerprints": {}}
    check_flight(recorded, CHEAPEST, traj)
    digests["q_ib"] = digests["q_ib"][::-1]
    with pytest.raises(AssertionError, match=r"\['q_ib'\] differ"):
        check_flight(recorded, CHEAPEST, traj)


def test_an_unrecorded_platform_checks_the_fingerprint_and_warns(stored, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "platform_key", lambda: "pdp11 kl10")
    with pytest.warns(UnrecordedPlatform, match="bit-identity not checked on platform 'pdp11 kl10'"):
        check_flight(stored, CHEAPEST, _flown(CHEAPEST))
    record = stored["fingerprints"][CHEAPEST]
    moved = json.loads(json.dumps(stored))
    moved["fingerprints"][CHEAPEST]["values"]["wheel_speed_rad_s"][0][-1][0] += (
        2.0 * tolerance(record)["wheel_speed_rad_s"]
    )
    with pytest.raises(AssertionError, match="wheel_speed_rad_s"):
        check_flight(moved, CHEAPEST, _flown(CHEAPEST))


def record(stored: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """The stored file with this platform's digests replaced; a changed flight re-fingerprinted and dropped from the
    other platforms. Returns the new file and the changed flights."""
    key = platform_key()
    platforms = {k: dict(v) for k, v in stored.get("platforms", {}).items() if k != key}
    here, fingerprints = stored.get("platforms", {}).get(key, {}), dict(stored.get("fingerprints", {}))
    digests, changed = {}, []
    for name in FLIGHTS:
        traj = fly(name)
        digests[name] = flight_digests(traj)
        if name in here:
            same = here[name] == digests[name]
        else:
            same = name in fingerprints and not fingerprint_excess(fingerprints[name], traj)
        if not same:
            changed.append(name)
            fingerprints[name] = fingerprint(name, traj)
            for other in platforms.values():
                other.pop(name, None)
    platforms[key] = digests
    return {"platforms": platforms, "fingerprints": {n: fingerprints[n] for n in FLIGHTS}}, changed


def _dumps(data: dict[str, Any]) -> str:
    """JSON with one line per innermost list of numbers."""
    text = json.dumps(data, indent=1)
    return re.sub(r"\[[-+0-9.eE,\s]*\]", lambda m: json.dumps(json.loads(m.group())), text) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description="Regenerate (--write) or check the engine's stored digests.")
    parser.add_argument("--write", action="store_true", help=f"record this platform in {DIGESTS}")
    args = parser.parse_args()
    stored = json.loads(DIGESTS.read_text()) if DIGESTS.exists() else {}
    if args.write:
        data, changed = record(stored)
        DIGESTS.write_text(_dumps(data))
        print(f"recorded {len(FLIGHTS)} flights for {platform_key()!r} in {DIGESTS}; changed: {changed or 'none'}")
        return
    here = stored["platforms"].get(platform_key(), {})
    for name in FLIGHTS:
        traj = fly(name)
        bits = "no digest" if name not in here else "same" if here[name] == flight_digests(traj) else "DIFFERENT"
        excess = fingerprint_excess(stored["fingerprints"][name], traj)
        print(f"{name}: bits {bits}; fingerprint {excess or 'within tolerance'}")


if __name__ == "__main__":
    main()
