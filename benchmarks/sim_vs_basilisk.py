"""acs-twin's engine against the peer simulator Basilisk on the same scenario, in one run.

    pip install -e '.[bench]' && python benchmarks/sim_vs_basilisk.py [--repeats 3] [--skip-24h]

Prints, for ``peer-basilisk-rw4`` (DESIGN.md's case, built in both): execution time of one orbit
(alternating acs-twin and Basilisk runs, median of the repeats), their ratio, both settling times
after the second slew and the largest attitude difference between the two histories; then the 11
wheel-fault variants (nominal, 4 single, 6 double failures) as one acs-twin batch against 11 Basilisk
runs on a process pool of the same width; then 24 h of ``somov-ge4-scan``. The first acs-twin call
(numba compile or cache load) is reported separately.
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peer_basilisk  # noqa: E402

from sim_core import engine, scenario_library  # noqa: E402
from sim_core.scenario import FaultSpec, VariantSpec, apply_overrides  # noqa: E402

SETTLE_DEG = 0.01
FAULT_SETS = [()] + [(i,) for i in range(4)] + list(itertools.combinations(range(4), 2))


def _angle_deg_from_mrp(sigma: np.ndarray) -> np.ndarray:
    return np.degrees(4.0 * np.arctan(np.linalg.norm(sigma, axis=-1)))


def _settling_after(t: np.ndarray, err_deg: np.ndarray, after_s: float) -> float:
    sel = t >= after_s
    bad = np.nonzero(err_deg[sel] > SETTLE_DEG)[0]
    return 0.0 if bad.size == 0 else float(t[sel][min(bad[-1] + 1, sel.sum() - 1)] - after_s)


def _ours(scenario, available=None):
    start = time.perf_counter()
    traj = engine.simulate(scenario, wheel_available=available)
    return time.perf_counter() - start, traj


def _basilisk_job(failed: tuple[int, ...]) -> float:
    return peer_basilisk.run(failed_wheels=failed, record=False).wall_time_s


def one_orbit(repeats: int) -> None:
    """Peer scenario, one orbit: alternate the two simulators and compare timing and histories."""
    scenario = scenario_library.get("peer-basilisk-rw4")
    first, _ = _ours(scenario)
    print(f"acs-twin first call (compile or cache load + run): {first:.2f} s")
    ours, theirs = [], []
    traj = peer = None
    for _ in range(repeats):
        dt, traj = _ours(scenario)
        ours.append(dt)
        peer = peer_basilisk.run()
        theirs.append(peer.wall_time_s)
    t_ours, t_bsk = statistics.median(ours), statistics.median(theirs)
    err_ours = np.degrees(traj.pointing_error_rad()[0])
    err_bsk = _angle_deg_from_mrp(peer.sigma_br)
    n = min(err_ours.size, err_bsk.size)
    # At the reference switch (t = 1000 s) Basilisk logs the old reference's error, we the new one's.
    steady = np.abs(traj.t_s[:n] - 1000.0) > 0.25
    print(
        f"one orbit (5,801 s): acs-twin {t_ours:.3f} s, Basilisk {t_bsk:.3f} s "
        f"(runs {[round(x, 3) for x in ours]} vs {[round(x, 3) for x in theirs]})"
    )
    print(
        f"  ratio Basilisk / acs-twin = {t_bsk / t_ours:.2f}x (target >= 4x); "
        f"acs-twin runs {5801.0 / t_ours:,.0f}x real time"
    )
    print(
        f"  settling to {SETTLE_DEG} deg after the second slew: acs-twin "
        f"{_settling_after(traj.t_s, err_ours, 1000.0):.1f} s, "
        f"Basilisk {_settling_after(peer.t_s, err_bsk, 1000.0):.1f} s"
    )
    print(
        f"  largest difference of the attitude-error angle between the two: "
        f"{np.max(np.abs(err_ours[:n] - err_bsk[:n])[steady]):.2e} deg; final wheel speeds (rpm) acs-twin "
        f"{np.round(traj['wheel_speed_rad_s'][0, -1] * 30 / np.pi, 2)}, Basilisk "
        f"{np.round(peer.omega_rw_rad_s[-1] * 30 / np.pi, 2)}"
    )


def fault_variants(repeats: int) -> None:
    """The 11 wheel-fault configurations: one acs-twin batch vs 11 Basilisk runs on a pool."""
    base = scenario_library.get("peer-basilisk-rw4")
    variants = [
        VariantSpec(
            name="nominal" if not fs else "fail " + "+".join(str(i + 1) for i in fs),
            faults=[FaultSpec(target="wheel", index=i, type="failure") for i in fs],
        )
        for fs in FAULT_SETS
    ]
    scenario = base.model_copy(update={"variants": variants})
    available = np.array([[i not in fs for i in range(4)] for fs in FAULT_SETS])
    workers = os.cpu_count() or 1
    _ours(scenario, available)
    ours, theirs = [], []
    with ProcessPoolExecutor(max_workers=workers) as pool:
        list(pool.map(_basilisk_job, [()] * workers))  # warm the workers' imports
        for _ in range(repeats):
            ours.append(_ours(scenario, available)[0])
            start = time.perf_counter()
            list(pool.map(_basilisk_job, FAULT_SETS))
            theirs.append(time.perf_counter() - start)
    t_ours, t_bsk = statistics.median(ours), statistics.median(theirs)
    print(
        f"11 wheel-fault variants, one orbit each ({workers} cores): acs-twin {t_ours:.3f} s, "
        f"Basilisk {t_bsk:.3f} s -> ratio {t_bsk / t_ours:.2f}x (target >= 10x)"
    )


def day_of_scanning() -> None:
    """24 h of somov-ge4-scan (T_q = 0.25 s, T_u = 2 s, MEKF, GE allocation, IGRF)."""
    scenario = apply_overrides(scenario_library.get("somov-ge4-scan"), ["duration_s=86400", "output_dt_s=1.0"])
    _ours(scenario)  # compile/cache for this configuration
    dt, traj = _ours(scenario)
    summary = traj.summary()
    print(
        f"24 h of somov-ge4-scan: {dt:.2f} s (target < 10 s), {86400 / dt:,.0f}x real time; "
        f"scanning RMS {summary['pointing_error_rms_arcsec']:.2f} arcsec, "
        f"max {summary['pointing_error_max_arcsec']:.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-24h", action="store_true")
    args = parser.parse_args()
    one_orbit(args.repeats)
    fault_variants(args.repeats)
    if not args.skip_24h:
        day_of_scanning()


if __name__ == "__main__":
    main()
