"""acs-twin's engine against the peer simulator Basilisk on the same scenario, in one run.

    pip install -e '.[bench]' && python benchmarks/sim_vs_basilisk.py [--repeats 3] [--skip-24h]

Prints, for ``peer-basilisk-rw4`` (DESIGN.md's case, built in both): execution time of one orbit
(alternating acs-twin and Basilisk runs; wall time median and CPU time minimum of the repeats), their
ratios, both settling times after the second slew and the largest attitude difference between the two
histories; then the 11 wheel-fault variants (nominal, 4 single, 6 double failures) as one acs-twin batch
against 11 Basilisk runs on a process pool of the same width (CPU time: all threads or workers summed);
the cost of each seed model (one orbit of ``somov-ge4-scan`` with each switched on alone, then all: CPU
time, minimum of ``--model-repeats`` rounds that each fly every case once); then 24 h of
``somov-ge4-scan``. The first acs-twin call (numba compile or cache load) is reported separately. On a
shared machine the CPU-time minima are the figures to compare: wall times carry other processes' load.
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peer_basilisk  # noqa: E402

from sim_core import engine, scenario_library  # noqa: E402
from sim_core.scenario import (  # noqa: E402
    FaultSpec,
    MotorSpec,
    Scenario,
    SurfaceSpec,
    VariantSpec,
    apply_overrides,
)

SETTLE_DEG = 0.01
FAULT_SETS = [()] + [(i,) for i in range(4)] + list(itertools.combinations(range(4), 2))


def _angle_deg_from_mrp(sigma: np.ndarray) -> np.ndarray:
    return np.degrees(4.0 * np.arctan(np.linalg.norm(sigma, axis=-1)))


def _settling_after(t: np.ndarray, err_deg: np.ndarray, after_s: float) -> float:
    sel = t >= after_s
    bad = np.nonzero(err_deg[sel] > SETTLE_DEG)[0]
    return 0.0 if bad.size == 0 else float(t[sel][min(bad[-1] + 1, sel.sum() - 1)] - after_s)


def _ours(scenario, available=None):
    """Wall time, CPU time (every thread of this process) and trajectory of one acs-twin run."""
    start, start_cpu = time.perf_counter(), time.process_time()
    traj = engine.simulate(scenario, wheel_available=available)
    return time.perf_counter() - start, time.process_time() - start_cpu, traj


def _basilisk_job(failed: tuple[int, ...]) -> float:
    """CPU time of one Basilisk run in a pool worker."""
    return peer_basilisk.run(failed_wheels=failed, record=False).cpu_time_s


def _ms(values: list[float]) -> list[float]:
    return [round(1e3 * v, 1) for v in values]


def one_orbit(repeats: int) -> float:
    """Peer scenario, one orbit: alternate the two simulators and compare timing and histories; returns
    Basilisk's CPU-time minimum."""
    scenario = scenario_library.get("peer-basilisk-rw4")
    first, _, _ = _ours(scenario)
    print(f"acs-twin first call (compile or cache load + run): {first:.2f} s")
    ours, theirs, ours_cpu, theirs_cpu = [], [], [], []
    traj = peer = None
    for _ in range(repeats):
        dt, cpu, traj = _ours(scenario)
        ours.append(dt)
        ours_cpu.append(cpu)
        peer = peer_basilisk.run()
        theirs.append(peer.wall_time_s)
        theirs_cpu.append(peer.cpu_time_s)
    t_ours, t_bsk = statistics.median(ours), statistics.median(theirs)
    cpu_ours, cpu_bsk = min(ours_cpu), min(theirs_cpu)
    err_ours = np.degrees(traj.pointing_error_rad()[0])
    err_bsk = _angle_deg_from_mrp(peer.sigma_br)
    n = min(err_ours.size, err_bsk.size)
    # At the reference switch (t = 1000 s) Basilisk logs the old reference's error, we the new one's.
    steady = np.abs(traj.t_s[:n] - 1000.0) > 0.25
    print(
        f"one orbit (5,801 s): wall median acs-twin {t_ours:.3f} s, Basilisk {t_bsk:.3f} s "
        f"(ms {_ms(ours)} vs {_ms(theirs)}); CPU min acs-twin {cpu_ours:.3f} s, Basilisk {cpu_bsk:.3f} s "
        f"(ms {_ms(ours_cpu)} vs {_ms(theirs_cpu)})"
    )
    print(
        f"  ratio Basilisk / acs-twin = {t_bsk / t_ours:.2f}x wall, {cpu_bsk / cpu_ours:.2f}x CPU "
        f"(target >= 8x, issue 13); acs-twin runs {5801.0 / t_ours:,.0f}x real time"
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
    return cpu_bsk


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
    ours, theirs, ours_cpu, theirs_cpu = [], [], [], []
    with ProcessPoolExecutor(max_workers=workers) as pool:
        list(pool.map(_basilisk_job, [()] * workers))  # warm the workers' imports
        for _ in range(repeats):
            dt, cpu, _ = _ours(scenario, available)
            ours.append(dt)
            ours_cpu.append(cpu)
            start = time.perf_counter()
            theirs_cpu.append(sum(pool.map(_basilisk_job, FAULT_SETS)))
            theirs.append(time.perf_counter() - start)
    t_ours, t_bsk = statistics.median(ours), statistics.median(theirs)
    cpu_ours, cpu_bsk = min(ours_cpu), min(theirs_cpu)
    print(
        f"11 wheel-fault variants, one orbit each ({workers} cores): wall median acs-twin {t_ours:.3f} s, "
        f"Basilisk {t_bsk:.3f} s -> ratio {t_bsk / t_ours:.2f}x; CPU min (summed over threads/workers) "
        f"acs-twin {cpu_ours:.3f} s, Basilisk {cpu_bsk:.3f} s -> ratio {cpu_bsk / cpu_ours:.2f}x (target >= 10x)"
    )


def day_of_scanning() -> None:
    """24 h of somov-ge4-scan (T_q = 0.25 s, T_u = 2 s, MEKF, GE allocation, IGRF)."""
    scenario = apply_overrides(scenario_library.get("somov-ge4-scan"), ["duration_s=86400", "output_dt_s=1.0"])
    _ours(scenario)  # compile/cache for this configuration
    dt, cpu, traj = _ours(scenario)
    summary = traj.summary()
    print(
        f"24 h of somov-ge4-scan: {dt:.2f} s wall, {cpu:.2f} s CPU (target < 3 s, issue 13), "
        f"{86400 / dt:,.0f}x real time; "
        f"scanning RMS {summary['pointing_error_rms_arcsec']:.2f} arcsec, "
        f"max {summary['pointing_error_max_arcsec']:.2f}"
    )


def _wheels(s: Scenario, **update: float) -> Scenario:
    ws = [w.model_copy(update=update) for w in s.spacecraft.cluster.wheels]
    return _cluster(s, wheels=ws)


def _cluster(s: Scenario, **update: object) -> Scenario:
    cluster = s.spacecraft.cluster.model_copy(update=update)
    return s.model_copy(update={"spacecraft": s.spacecraft.model_copy(update={"cluster": cluster})})


def _spacecraft(s: Scenario, **update: object) -> Scenario:
    return s.model_copy(update={"spacecraft": s.spacecraft.model_copy(update=update)})


def _sensors(s: Scenario, **update: object) -> Scenario:
    return s.model_copy(update={"sensors": s.sensors.model_copy(update=update)})


PLATES = [
    SurfaceSpec(normal_b=n, area_m2=a, centroid_b_m=c)
    for n, a, c in (
        ([0.0, 1.0, 0.0], 2.0, [0.3, 0.4, 0.2]),
        ([0.0, -1.0, 0.0], 1.0, [-0.2, -0.4, 0.1]),
        ([0.0, 0.0, 1.0], 1.5, [0.1, 0.2, 0.6]),
        ([1.0, 0.0, 0.0], 1.0, [0.5, 0.1, -0.2]),
    )
]
SEED_MODELS: dict[str, Callable[[Scenario], Scenario]] = {
    "wheel aero drag (seed 002 eq 4)": lambda s: _wheels(s, aero_drag_nm_s15=1e-8),
    "wheel noise (seed 002 eq 4)": lambda s: _wheels(s, noise_nm=1e-4),
    "wheel imbalance (seed 002 eq 4)": lambda s: _wheels(s, imbalance_nm_s2=1e-10),
    "motor electrics (seed 002 eq 2-3)": lambda s: _cluster(s, motor=MotorSpec()),
    "torque quantisation (seed 000 eq 3)": lambda s: _wheels(s, torque_quantum_nm=1e-4),
    "flexible modes x2 (seed 000 eq 1)": lambda s: _spacecraft(
        s, flex_modes=scenario_library.get("somov-ge4-scan-flex").spacecraft.flex_modes
    ),
    "gyro Markov drift (seed 002 eq 13)": lambda s: _sensors(s, gyro_markov_sigma_rad_s=1e-6),
    "star-tracker Sun blinding (seed 003)": lambda s: _sensors(s, star_tracker_sun_exclusion_deg=30.0),
    "star-tracker rate limit": lambda s: _sensors(s, star_tracker_max_rate_rad_s=0.01),
    "residual dipole": lambda s: _spacecraft(s, residual_dipole_am2=[0.1, 0.1, 0.1]),
    "aerodynamic torque": lambda s: _spacecraft(s, surfaces=PLATES).model_copy(update={"aerodynamic_torque": True}),
    "solar-pressure torque": lambda s: _spacecraft(s, surfaces=PLATES).model_copy(
        update={"solar_pressure_torque": True}
    ),
}


def seed_model_costs(repeats: int, cpu_bsk: float) -> None:
    """One orbit of somov-ge4-scan (MEKF, GE cluster, IGRF, gravity gradient) with each seed model switched on
    alone and then all together: the extra CPU time each costs (minimum over ``repeats`` rounds; each round flies
    every case once, so a change of machine load falls on all cases alike), and the all-on run against Basilisk's
    orbit (``cpu_bsk``: its CPU-time minimum in this run)."""
    base = apply_overrides(scenario_library.get("somov-ge4-scan"), ["duration_s=5801", "output_dt_s=1.0"])
    every = base
    for switch in SEED_MODELS.values():
        every = switch(every)
    cases = {"all off": base, **{name: switch(base) for name, switch in SEED_MODELS.items()}, "all on": every}
    _ours(every)  # compile/cache (switches are values: one compiled loop serves every case)
    cpu: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(repeats):
        for name, s in cases.items():
            cpu[name].append(_ours(s)[1])
    best = {name: min(times) for name, times in cpu.items()}
    t_base, t_all = best["all off"], best["all on"]
    print(f"seed models, one orbit of somov-ge4-scan, CPU min of {repeats} alternated rounds: all off {t_base:.3f} s")
    for name in SEED_MODELS:
        t = best[name]
        spread = max(cpu[name]) - t
        print(
            f"  + {name:40s} {t:.3f} s  (cost {t - t_base:+.3f} s, {100 * (t / t_base - 1):+.1f} %; "
            f"its rounds spread {spread:.3f} s)"
        )
    print(
        f"  all on: {t_all:.3f} s ({100 * (t_all / t_base - 1):+.0f} %); Basilisk's rw4 orbit in this run "
        f"{cpu_bsk:.3f} s CPU -> ratio {cpu_bsk / t_all:.2f}x (Basilisk flies a rigid body, no sensors, no seed models)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--model-repeats", type=int, default=7, help="rounds of the seed-model costs (CPU minimum)")
    parser.add_argument("--skip-24h", action="store_true")
    args = parser.parse_args()
    cpu_bsk = one_orbit(args.repeats)
    fault_variants(args.repeats)
    seed_model_costs(args.model_repeats, cpu_bsk)
    if not args.skip_24h:
        day_of_scanning()


if __name__ == "__main__":
    main()
