"""Live twin benchmark (issue 11): a fleet of emulated satellites at 1 Hz, each with its live twin, in real time.

    .venv/bin/python benchmarks/live_twin.py [--satellites 100] [--seconds 150] [--no-archive-telemetry] [--exact-model]
    .venv/bin/python benchmarks/live_twin.py --startup       # acs-twin serve --no-auth: API, demo twin, monitors

Fleet: one nominal flight of the reference satellite (somov-ge4-scan, emulated, ACS_HK thinned to 1 Hz + GPS at
1 Hz) is streamed as N satellites joining one after the other over the first minute (so their 60 s re-syncs do
not all fall in the same second), one batch per satellite per wall second, through the server's live-twin
service (backend.twin.live.LiveTwins over a real SQLite archive; with telemetry archiving on, every batch is
also committed, one upload per satellite every 5 s, in a writer thread). Prints:
  * twin lag: wall time from a batch reaching the service to its residuals computed (p50/p99/max), and the
    newest telemetry instant minus the newest twin instant over all satellites (p99) — target p99 < 2 s;
  * server CPU: process CPU time / wall time over the run (1.0 = one core of this 2-core machine);
  * nominal attitude residual RMS over all satellites after 30 s (the star tracker's σ is 3″), wheels in rpm;
Start-up (--startup): wall time from launching ``acs-twin serve --no-auth`` (fresh data directory, free ports) to
the API answering, to the demo satellite's live twin propagating, to the three monitors answering HTTP.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import queue
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
EPOCH = "2026-03-20T00:00:00Z"
SETTLE_S = 30.0  # the emulated satellite's own MEKF converges first
STAGGER_S = 60  # satellites start spread over one re-sync period
TELEMETRY_COMMIT_S = 5  # each satellite's telemetry committed every 5 s (the live ingest commits every 0.5 s)
TARGET_LAG_P99_S = 2.0


def _flight(seconds: float, exact_model: bool = False) -> list:
    """Decoded nominal flight: ACS_HK thinned to 1 Hz, GPS_NAV at 1 Hz; the satellite flies its own truth
    (telemetry.emulator.TruthTolerances) unless ``exact_model``."""
    from telemetry.decoding import decode_stream
    from telemetry.dictionary import load_dictionary
    from telemetry.emulator import emulate

    data = emulate("somov-ge4-scan", [], seconds, EPOCH, truth_seed=None if exact_model else 0)[2].data
    batches = decode_stream(data, load_dictionary("reference_satellite.yaml"), source="bench").batches
    out = []
    for b in batches:
        keep = (b.t_utc_ns % 1_000_000_000) == 0  # whole seconds: 1 Hz
        out.append(
            dataclasses.replace(
                b,
                t_utc_ns=b.t_utc_ns[keep],
                sequence_count=b.sequence_count[keep],
                values={n: np.asarray(v)[keep] for n, v in b.values.items()},
                packets=None,
            )
        )
    return out


def _second(batches: list, t0_ns: int, k: int) -> list:
    lo, hi = t0_ns + k * 10**9, t0_ns + (k + 1) * 10**9
    out = []
    for b in batches:
        s = (b.t_utc_ns >= lo) & (b.t_utc_ns < hi)
        out.append(
            dataclasses.replace(
                b,
                t_utc_ns=b.t_utc_ns[s],
                sequence_count=b.sequence_count[s],
                values={n: v[s] for n, v in b.values.items()},
            )
        )
    return out


class _Hub:
    """Counts what the service publishes (the WebSocket fan-out is measured in benchmarks/api_load.py)."""

    def __init__(self) -> None:
        self.published = 0

    def publish(self, topic: str, data: object) -> None:
        self.published += 1

    def wants_any(self, topic: str) -> bool:
        return topic == "twin"


def fleet(n_satellites: int, seconds: int, archive_telemetry: bool, exact_model: bool = False) -> None:
    """Stream the fleet in real time through LiveTwins and print lag, CPU and residual figures."""
    from backend.twin.live import LiveTwins
    from telemetry.archive import Archive
    from telemetry.dictionary import load_dictionary

    flight_s = SETTLE_S + seconds + 5
    t_build = time.perf_counter()
    batches = _flight(flight_s, exact_model)
    print(f"emulated flight of {flight_s:.0f} s in {time.perf_counter() - t_build:.1f} s")
    t0_ns = int(min(b.t_utc_ns[0] for b in batches))
    with tempfile.TemporaryDirectory() as tmp:
        archive = Archive(f"sqlite:///{tmp}/bench.sqlite")
        dictionary = load_dictionary("reference_satellite.yaml")
        twins = LiveTwins(lambda: archive, _Hub(), lambda name: dictionary)
        names = [f"SAT-{k:03d}" for k in range(n_satellites)]
        joins = [(k * STAGGER_S) // n_satellites for k in range(n_satellites)]  # wall second each satellite joins
        for name in names:
            twins.register_model(name, "somov-ge4-scan", t0_ns)
        twins.start(recover=False)
        writes: queue.Queue = queue.Queue()
        writer = threading.Thread(target=_archive_telemetry, args=(archive, writes), daemon=True)
        writer.start()
        held: dict[str, list] = {name: [] for name in names}
        cpu0, wall0 = time.process_time(), time.perf_counter()
        behind: list[float] = []
        worst_late = 0.0
        for s in range(seconds):
            tick = wall0 + s
            for name, join in zip(names, joins):
                if s < join:
                    continue
                part = _second(batches, t0_ns, int(SETTLE_S) + s - join)
                if archive_telemetry:
                    held[name].extend(part)
                    if s % TELEMETRY_COMMIT_S == TELEMETRY_COMMIT_S - 1:
                        writes.put((name, held[name]))
                        held[name] = []
                twins.submit(name, "reference_satellite.yaml", part)
            if s >= 10:
                for name in names:
                    state = twins.state(name)
                    if state and state["twin_behind_telemetry_s"] is not None:
                        behind.append(state["twin_behind_telemetry_s"])
            late = time.perf_counter() - (tick + 1.0)
            worst_late = max(worst_late, late)
            if late < 0:
                time.sleep(-late)
        backlog = writes.qsize()
        writes.put(None)
        writer.join(300)
        twins.drain(120.0)
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        lag = np.array(twins.latencies_s)
        twins.stop()
        rms, wheel_rpm = _residuals(archive, names, t0_ns)
        archive.close()
    print(
        f"fleet: {n_satellites} satellites x 1 Hz ACS_HK + GPS for {seconds} s, telemetry archived: {archive_telemetry}"
    )
    print(
        f"  twin lag (batch arrival -> residuals computed): p50 {np.percentile(lag, 50) * 1e3:.1f} ms, "
        f"p99 {np.percentile(lag, 99) * 1e3:.1f} ms, max {lag.max() * 1e3:.1f} ms "
        f"(target p99 < {TARGET_LAG_P99_S:.0f} s: ratio {np.percentile(lag, 99) / TARGET_LAG_P99_S:.3f})"
    )
    print(
        f"  telemetry_utc - twin_utc over all satellites: p99 {np.percentile(behind, 99):.3f} s, "
        f"max {max(behind):.3f} s"
    )
    print(
        f"  server CPU: {cpu / wall:.2f} cores ({cpu:.1f} s CPU in {wall:.1f} s wall; machine has 2); feeder "
        f"{'kept' if worst_late < 1.0 else 'did not keep'} real time (worst {max(worst_late, 0.0):.2f} s late); "
        f"telemetry commits waiting at the end: {backlog}"
    )
    print(
        f"  nominal attitude residual RMS after {SETTLE_S:.0f} s: {rms:.2f} arcsec (star tracker sigma 3 arcsec); "
        f"wheel speed residual RMS {wheel_rpm:.3f} rpm (tachometer count 0.25 rpm)"
    )


def _archive_telemetry(archive: object, writes: queue.Queue) -> None:
    """What the live ingest does per stream: commit each satellite's telemetry as one upload (every 5 s here)."""
    from telemetry.archive import PacketBatch

    while (item := writes.get()) is not None:
        name, parts = item
        merged: dict[int, list] = {}
        for b in parts:
            merged.setdefault(b.apid, []).append(b)
        batches = [
            PacketBatch(
                apid,
                np.concatenate([b.t_utc_ns for b in bs]),
                np.concatenate([b.sequence_count for b in bs]),
                b"",
                np.zeros(sum(len(b.t_utc_ns) for b in bs), np.int64),
                {n: np.concatenate([b.values[n] for b in bs]) for n in bs[0].values},
            )
            for apid, bs in merged.items()
        ]
        archive.ingest(name, batches, source="bench", uploaded_by="bench")


def _residuals(archive: object, names: list[str], t0_ns: int) -> tuple[float, float]:
    att, wheels = [], []
    for name in names:
        if "twin_attitude_residual_arcsec" not in archive.parameters(name):
            continue  # its twin was still collecting GPS fixes for the orbit fit
        t, v = archive.read_parameter(name, "twin_attitude_residual_arcsec", t0_ns + int(SETTLE_S * 1e9), 2**62)
        att.append(v)
        for k in range(1, 5):
            wheels.append(archive.read_parameter(name, f"twin_wheel_speed_residual_rad_s_{k}", t0_ns, 2**62)[1])
    a, w = np.concatenate(att), np.concatenate(wheels) * 30 / np.pi
    return float(np.sqrt(np.mean(a**2))), float(np.sqrt(np.mean(w**2)))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def startup() -> None:
    """Launch acs-twin serve --no-auth and time API, demo live twin and monitors."""
    import httpx

    with tempfile.TemporaryDirectory() as tmp:
        api, viewer, telemetry = _free_port(), _free_port(), _free_port()
        env = {**os.environ, "ACS_TWIN_VIEWER_PORT": str(viewer), "ACS_TWIN_TELEMETRY_PORT": str(telemetry)}
        start = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "backend", "serve", "--no-auth", "--port", str(api), "--data-dir", tmp],
            cwd=REPO,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        lines: list[str] = []
        threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
        marks: dict[str, float] = {}
        base = f"http://127.0.0.1:{api}/api/v1"
        try:
            while len(marks) < 3 and time.perf_counter() - start < 300:
                with httpx.Client(timeout=2.0) as http:
                    try:
                        if "api" not in marks and http.get(f"{base}/health").status_code == 200:
                            marks["api"] = time.perf_counter() - start
                        twin = http.get(f"{base}/satellites/REFSAT/twin")
                        if "twin" not in marks and twin.status_code == 200 and twin.json()["state"] == "propagating":
                            marks["twin"] = time.perf_counter() - start
                        ports = [viewer + i for i in range(3)]
                        if "monitors" not in marks and all(
                            http.get(f"http://127.0.0.1:{p}/").status_code == 200 for p in ports
                        ):
                            marks["monitors"] = time.perf_counter() - start
                    except httpx.HTTPError:
                        pass
                time.sleep(0.2)
        finally:
            proc.terminate()
            proc.wait(30)
        print("start-up of acs-twin serve --no-auth (fresh data directory):")
        for key, label in (
            ("api", "API answers /health"),
            ("twin", "demo satellite's live twin propagating"),
            ("monitors", "3 monitors answer HTTP"),
        ):
            print(f"  {label}: " + (f"{marks[key]:.1f} s" if key in marks else "not within 300 s") + " (target 15 s)")
        if len(marks) < 3:
            print("".join(lines[-30:]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--satellites", type=int, default=100)
    parser.add_argument("--seconds", type=int, default=150)
    parser.add_argument("--no-archive-telemetry", action="store_true")
    parser.add_argument("--startup", action="store_true")
    parser.add_argument("--exact-model", action="store_true", help="the satellite flies the twin's model exactly")
    args = parser.parse_args()
    if args.startup:
        startup()
    else:
        fleet(args.satellites, args.seconds, not args.no_archive_telemetry, args.exact_model)


if __name__ == "__main__":
    main()
