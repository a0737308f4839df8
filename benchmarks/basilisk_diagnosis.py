"""Acceptance rehearsal: ``acs-twin diagnose`` on randomised Basilisk-flown ``peer-basilisk-rw4`` hidden faults.

The acceptance of issue 14 diagnoses telemetry of an independent simulator whose fault type, wheel,
onset and magnitude we do not know. This draws ``--cases`` such flights at random
(:mod:`benchmarks.basilisk_faults`: Basilisk flies the peer case, a module the flight software never
sees injects the fault): every fault type it supports in turn (``failure``, ``gain_loss`` with a
remaining gain 0.1–0.8, ``friction`` of 0.5–5 mN·m, ``stuck``, and ``none``), a random wheel, a file
cut anywhere in the orbit (first sample 0–4,000 s into the flight, 600–1,800 s long, its own random
epoch), the onset 120 s after the first sample to 240 s before the last. Each file is diagnosed by
exactly the acceptance's command (``backend.cli.main(["diagnose", …])``) on one shared 2-worker Dask
LocalCluster; prints per case the truth, the top hypothesis, the onset error and the magnitude
error, and the top-1 (fault type and wheel) and onset-within-60-s rates.

The fault's *signature* is stated per case: the largest deviation, in tachometer counts (0.25 rpm),
that the fault puts between the wheel's speed and the integral of its telemetered command
(failure: ∫u, gain loss: (1 − g)∫u, friction: f·t, stuck: the speed at the onset). Below
SIGNATURE_COUNTS the data cannot show the fault (a wheel commanded µN·m in fine pointing fails
unseen), and such cases are counted apart. Files go to ``--out-dir`` (a temporary directory by
default, never the repository) and are reused when present.

    python -m benchmarks.basilisk_diagnosis [--cases 15] [--seed 14] [--out-dir DIR] [--workers 2]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import tempfile
import time
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from benchmarks import basilisk_faults as bf

DICTIONARY = Path(__file__).resolve().parents[1] / "telemetry" / "dictionaries" / "reference_satellite.yaml"
SCENARIO = "peer-basilisk-rw4"
KINDS = ("failure", "gain_loss", "friction", "stuck", "none")
ONSET_TOLERANCE_S = 60.0  # issue 14 acceptance: onset within 60 s
SIGNATURE_COUNTS = 3.0  # a deviation of fewer tachometer counts is lost in the rounding of a 1 Hz record
ROTOR_INERTIA_KG_M2 = 0.0191  # HR12 (benchmarks.peer_basilisk)


@dataclass(frozen=True)
class Case:
    """One hidden fault: kind, 1-based wheel, onset after the first sample (s), magnitude, file cut, epoch."""

    index: int
    fault: str
    wheel: int
    onset_s: float
    magnitude: float
    start_s: float
    length_s: float
    epoch: str

    @property
    def name(self) -> str:
        """File name unique to the draw."""
        return f"{self.index:02d}_{self.fault}_w{self.wheel}_{self.start_s:.0f}_{self.onset_s:.0f}_{self.length_s:.0f}"


def draw_cases(n: int, seed: int) -> list[Case]:
    """``n`` cases cycling through KINDS with random wheel, magnitude, cut, onset and epoch."""
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n):
        kind = KINDS[i % len(KINDS)]
        magnitude = {"gain_loss": rng.uniform(0.1, 0.8), "friction": rng.uniform(5e-4, 5e-3)}.get(kind, 0.0)
        length = float(np.round(rng.uniform(600.0, 1800.0)))
        epoch = datetime(2026, 1, 1, tzinfo=UTC) + timedelta(seconds=float(rng.uniform(0.0, 365 * 86_400.0)))
        cases.append(
            Case(
                index=i,
                fault=kind,
                wheel=int(rng.integers(1, 5)),
                onset_s=float(np.round(rng.uniform(120.0, length - 240.0), 1)),
                magnitude=float(magnitude),
                start_s=float(np.round(rng.uniform(0.0, 4000.0))),
                length_s=length,
                epoch=epoch.strftime("%Y-%m-%dT%H:%M:%SZ"),
            )
        )
    return cases


def generate(case: Case, out_dir: Path) -> Path:
    """Fly the case in Basilisk and write its ground CSV (kept if already there)."""
    path = out_dir / f"{case.name}.csv"
    if not path.exists():
        series = bf.fly(
            case.fault, case.wheel - 1, case.start_s + case.onset_s, case.magnitude, case.start_s + case.length_s
        )
        keep = series["t_s"] >= case.start_s
        bf.write_csv(path, {k: v[keep] for k, v in series.items()}, datetime.fromisoformat(case.epoch))
    return path


def signature_counts(case: Case, path: Path) -> float:
    """Largest speed deviation (tachometer counts) the fault causes against the wheel's integrated command."""
    if case.fault == "none":
        return 0.0
    names = ("t_utc", f"wheel_speed_rad_s_{case.wheel}", f"wheel_torque_cmd_nm_{case.wheel}")
    data = np.genfromtxt(str(path), delimiter=",", names=True, dtype=None, encoding=None)
    stamps = np.array([np.datetime64(s.rstrip("Z"), "ms") for s in data["t_utc"]])
    t = (stamps - stamps[0]).astype(float) * 1e-3
    after = t >= case.onset_s
    u = np.clip(data[names[2]][after], -bf.HR12_MAX_TORQUE_NM, bf.HR12_MAX_TORQUE_NM)
    speed = data[names[1]][after]
    if case.fault == "stuck":
        deviation = float(np.abs(speed[0])) if speed.size else 0.0
    elif case.fault == "friction":
        deviation = case.magnitude * float(t[after][-1] - case.onset_s) / ROTOR_INERTIA_KG_M2
    else:
        lost = 1.0 if case.fault == "failure" else 1.0 - case.magnitude
        deviation = float(np.max(np.abs(np.cumsum(lost * u)), initial=0.0)) / ROTOR_INERTIA_KG_M2
    return deviation / bf.TACHOMETER_QUANTUM_RAD_S


def diagnose(path: Path, out: Path) -> tuple[dict, float]:
    """The acceptance's command on one file (its printout swallowed); the JSON and the wall time."""
    from backend.cli import main

    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(
            ["diagnose", str(path), "--dictionary", str(DICTIONARY), "--scenario", SCENARIO, "--json", str(out)]
        )
    if code != 0:
        raise RuntimeError(f"acs-twin diagnose {path}: exit {code}")
    return json.loads(out.read_text()), time.perf_counter() - start


def judge(case: Case, result: dict) -> dict:
    """Top-1 right (fault type and wheel), onset error (s) and magnitude error of the top hypothesis."""
    top = result["hypotheses"][0]
    truth = (case.fault, None if case.fault == "none" else case.wheel)
    right = (top["fault"], top["wheel"]) == truth
    onset_error = None
    if case.fault != "none" and top["onset_utc"] is not None:
        start = datetime.fromisoformat(result["telemetry_start_utc"]).timestamp()
        onset_error = datetime.fromisoformat(top["onset_utc"]).timestamp() - start - case.onset_s
    magnitude_error = None
    if right and case.fault in ("gain_loss", "friction") and top["magnitude"] is not None:
        magnitude_error = top["magnitude"] - case.magnitude
    return {
        "right": right,
        "onset_ok": case.fault == "none" or (onset_error is not None and abs(onset_error) <= ONSET_TOLERANCE_S),
        "onset_error_s": onset_error,
        "magnitude_error": magnitude_error,
        "top": f"{top['fault']} w{top['wheel']} ({top['score']:.2f})",
    }


def main(argv: list[str] | None = None) -> int:
    """Draw, fly (on the cluster), diagnose each file with the command, print the table and the rates."""
    from backend.jobs import cluster

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=15)
    p.add_argument("--seed", type=int, default=14)
    p.add_argument("--out-dir", type=Path, help="where the flown CSVs go (default: a temporary directory)")
    p.add_argument("--workers", type=int, default=2)
    args = p.parse_args(argv)
    out_dir = args.out_dir or Path(tempfile.mkdtemp(prefix="basilisk-diagnosis-"))
    out_dir.mkdir(parents=True, exist_ok=True)
    cases = draw_cases(args.cases, args.seed)
    client = cluster.dask_client(n_workers=args.workers, warm=True)
    os.environ[cluster.SCHEDULER_ENV] = str(client.scheduler_info()["address"])
    try:
        start = time.perf_counter()
        paths = cluster.map_cases(client, lambda c: generate(c, out_dir), cases)
        print(f"{len(cases)} Basilisk flights in {out_dir} ({time.perf_counter() - start:.0f} s)", flush=True)
        rows = []
        for case, path in zip(cases, paths):
            result, wall = diagnose(path, out_dir / f"{case.name}.json")
            row = {**judge(case, result), "signature": signature_counts(case, path), "wall_s": wall}
            rows.append(row)
            err = "-" if row["onset_error_s"] is None else f"{row['onset_error_s']:+.1f} s"
            mag = "" if row["magnitude_error"] is None else f" magnitude error {row['magnitude_error']:+.4g}"
            print(
                f"  {case.name:<34} truth {case.fault} w{case.wheel} m={case.magnitude:.4g} "
                f"signature {row['signature']:.1f} counts -> {row['top']} onset {err}{mag} "
                f"[{'ok' if row['right'] and row['onset_ok'] else 'MISS'}] {wall:.1f} s",
                flush=True,
            )
    finally:
        os.environ.pop(cluster.SCHEDULER_ENV, None)
        cluster.close_client(client)
    _summary(cases, rows)
    return 0


def _summary(cases: list[Case], rows: list[dict]) -> None:
    visible = [r for c, r in zip(cases, rows) if c.fault == "none" or r["signature"] >= SIGNATURE_COUNTS]
    for label, group in (("all", rows), (f"signature >= {SIGNATURE_COUNTS:.0f} counts or none", visible)):
        n = max(len(group), 1)
        ok = sum(r["right"] and r["onset_ok"] for r in group)
        print(
            f"{label}: {len(group)} cases, top-1 {sum(r['right'] for r in group)}/{len(group)}, "
            f"top-1 with onset within {ONSET_TOLERANCE_S:.0f} s {ok}/{len(group)} ({100 * ok / n:.0f} %)"
        )
    errors = [abs(r["onset_error_s"]) for r in rows if r["right"] and r["onset_error_s"] is not None]
    if errors:
        print(f"onset error (top-1 right): median {np.median(errors):.1f} s, max {max(errors):.1f} s")
    walls = [r["wall_s"] for r in rows]
    print(f"command wall time per file: median {np.median(walls):.1f} s, max {max(walls):.1f} s")


if __name__ == "__main__":
    raise SystemExit(main())
