"""Live twin benchmark (issue 11): a fleet of emulated satellites at 1 Hz, each with its live twin, in real time.

    .venv/bin/python benchmarks/live_twin.py [--satellites 100] [--seconds 150] [--no-archive-telemetry] [--exact-model]
    .venv/bin/python benchmarks/live_twin.py --startup [--cold]  # acs-twin serve --no-auth: API, demo twin, monitors

Fleet: one nominal flight of the reference satellite (somov-ge4-scan, emulated, ACS_HK thinned to 1 Hz + GPS at
1 Hz) is streamed as N satellites joining one after the other over the first minute (so their 60 s re-syncs do
not all fall in the same second), one batch per satellite per wall second, through the server's live-twin
service (backend.twin.live.LiveTwins over a real SQLite archive, synchronous=FULL; with telemetry archiving on,
every satellite's second is also archived as its own upload by a writer thread committing whatever is queued in one
transaction, Archive.ingest_many, as the twins' residual writer does). Prints:
  * twin lag: wall time from a batch reaching the service to its residuals computed (p50/p99/max), and the
    newest telemetry instant minus the newest twin instant over all satellites (p99) — target p99 < 2 s;
  * server CPU: process CPU time / wall time over the run (1.0 = one core of this 2-core machine);
  * telemetry archiving: handed -> committed p50/p99 (durable once committed) and whether the writer kept up;
  * nominal attitude residual RMS over all satellites after 30 s (the star tracker's σ is 3″), wheels in rpm;
Start-up (--startup): after ``acs-twin warm`` (what scripts/run.sh runs once per install), wall time from launching
``acs-twin serve --no-auth`` (fresh data directory, free ports) to the API answering, to the demo satellite's first
telemetry at its live twin, to the twin propagating with residuals, to the three monitors answering HTTP; ``--cold``
does the same in an empty numba cache (every kernel compiled on the critical path: the state before warm).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import multiprocessing as mp
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
TELEMETRY_COMMIT_S = 10  # each satellite's telemetry handed to the archive writer every 10 s (an upload costs
# ~10-30 ms of CPU whatever its length: 100 satellites x 1/s would need 1-3 cores); committed in groups
GROUP_MAX_UPLOADS = 100  # as backend.twin.live: one transaction stays far below SQLite's 30 s busy timeout
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
        ctx = mp.get_context("spawn")  # the telemetry is archived in its own process, as by the live-ingest process
        writes, results = ctx.Queue(), ctx.Queue()
        writer = ctx.Process(target=_archive_telemetry, args=(f"sqlite:///{tmp}/bench.sqlite", writes, results))
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
                    if (s - join) % TELEMETRY_COMMIT_S == TELEMETRY_COMMIT_S - 1:
                        writes.put((name, held[name], time.time()))
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
        writes.put(None)
        archived_after, writer_cpu_s, backlog = results.get(timeout=600)
        writer.join(60)
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
        f"  server CPU: {cpu / wall:.2f} cores ({cpu:.1f} s CPU in {wall:.1f} s wall; machine has 2), i.e. "
        f"{cpu / seconds:.2f} cores to hold real time (CPU per streamed second, twins + feeder); feeder "
        f"{'kept' if worst_late < 1.0 else 'did not keep'} real time (worst {max(worst_late, 0.0):.2f} s late)"
    )
    if archive_telemetry:
        held_s = np.array(archived_after)
        print(
            f"  telemetry archived in its own process (group commit, synchronous=FULL): {held_s.size} uploads of "
            f"{TELEMETRY_COMMIT_S} s, handed -> committed p50 {np.percentile(held_s, 50):.2f} s, p99 "
            f"{np.percentile(held_s, 99):.2f} s, max {held_s.max():.2f} s; most waiting {backlog}; "
            f"{'kept up' if np.percentile(held_s, 99) < TELEMETRY_COMMIT_S else 'fell behind'}; "
            f"its CPU {writer_cpu_s / seconds:.2f} cores per streamed second"
        )
    print(
        f"  nominal attitude residual RMS after {SETTLE_S:.0f} s: {rms:.2f} arcsec (star tracker sigma 3 arcsec); "
        f"wheel speed residual RMS {wheel_rpm:.3f} rpm (tachometer count 0.25 rpm)"
    )


def _archive_telemetry(url: str, writes: mp.Queue[object], results: mp.Queue[object]) -> None:
    """Process: the fleet's telemetry archived with group commit, what is queued (each satellite's last
    TELEMETRY_COMMIT_S) in one Archive.ingest_many transaction, one upload per satellite; at the end it answers
    (handed -> committed seconds, its CPU seconds, most uploads it ever had waiting)."""
    from telemetry.archive import Archive

    archive, archived_after, backlog, stop = Archive(url, migrate=False), [], 0, False
    cpu0 = time.process_time()
    while not stop:
        group, item = [], writes.get()
        while item is not None:
            group.append(item)
            if len(group) >= GROUP_MAX_UPLOADS:
                break
            try:
                item = writes.get_nowait()
            except queue.Empty:
                break
        stop = item is None
        backlog = max(backlog, writes.qsize() + len(group))
        _commit_group(archive, group, archived_after)
    archive.close()
    results.put((archived_after, time.process_time() - cpu0, backlog))


def _commit_group(archive: object, group: list, archived_after: list[float]) -> None:
    from telemetry.archive import PacketBatch, PendingUpload

    uploads = []
    for name, parts, _ in group:
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
        uploads.append(PendingUpload(name, batches, "bench", "bench"))
    if uploads:
        archive.ingest_many(uploads)
        now = time.time()
        archived_after.extend(now - handed for _, _, handed in group)


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


def startup(cold: bool) -> None:
    """Launch acs-twin serve --no-auth and time API, demo live twin and monitors (after ``acs-twin warm``, as
    scripts/run.sh does; ``cold``: in an empty numba cache, i.e. compiling on the critical path as before)."""
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        if cold:
            env["NUMBA_CACHE_DIR"] = f"{tmp}/numba-cache"
        else:
            t = time.perf_counter()
            subprocess.run(
                [sys.executable, "-m", "backend", "warm"], cwd=REPO, env=env, check=True, capture_output=True
            )
            print(
                f"acs-twin warm (run.sh, once per install; a no-op load when cached): {time.perf_counter() - t:.1f} s"
            )
        load0 = os.getloadavg()
        marks, lines = _time_serve(env, f"{tmp}/data")
        load1 = os.getloadavg()
    print(
        f"start-up of acs-twin serve --no-auth (fresh data directory, {'cold' if cold else 'warm'} numba cache; "
        f"load average {load0[0]:.1f} at start, {load1[0]:.1f} at end on 2 cores: upper bounds):"
    )
    for key, label in (
        ("api", "API answers /health"),
        ("emulator", "emulator's flight computed, sending (emulator.log written)"),
        ("telemetry", "demo satellite's first telemetry at its live twin"),
        ("twin", "live twin propagating, residuals flowing"),
        ("monitors", "3 monitors answer HTTP"),
    ):
        figure = (
            f"{marks[key]:.1f} s (ratio to the 15 s target {marks[key] / 15.0:.2f})"
            if key in marks
            else "not within 300 s"
        )
        print(f"  {label}: {figure}")
    if len(marks) < 5:
        print("".join(lines[-30:]))


def _time_serve(env: dict[str, str], data_dir: str) -> tuple[dict[str, float], list[str]]:
    """Seconds from launching the server to each readiness mark; its output lines."""
    import httpx

    api, viewer, telemetry = _free_port(), _free_port(), _free_port()
    env = {**env, "ACS_TWIN_VIEWER_PORT": str(viewer), "ACS_TWIN_TELEMETRY_PORT": str(telemetry)}
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "backend", "serve", "--no-auth", "--port", str(api), "--data-dir", data_dir],
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
        with httpx.Client(timeout=2.0) as http:
            while len(marks) < 4 and time.perf_counter() - start < 300:  # api, telemetry, twin, monitors
                with contextlib.suppress(httpx.HTTPError):
                    _mark(http, base, viewer, marks, start)
                time.sleep(0.1)
    finally:
        proc.terminate()
        proc.wait(120)
    log = Path(data_dir) / "emulator.log"  # written once the emulator's flight is computed ("sending to ...")
    if log.exists() and "sending" in log.read_text():
        marks["emulator"] = log.stat().st_mtime - (time.time() - (time.perf_counter() - start))
    return marks, lines


def _mark(http: object, base: str, viewer: int, marks: dict[str, float], start: float) -> None:
    """Record the readiness marks reached now."""
    now = time.perf_counter() - start
    if "api" not in marks and http.get(f"{base}/health").status_code == 200:
        marks["api"] = now
    if "api" in marks and "twin" not in marks:
        twin = http.get(f"{base}/satellites/REFSAT/twin")
        state = twin.json() if twin.status_code == 200 else {}
        if state.get("telemetry_utc") and "telemetry" not in marks:
            marks["telemetry"] = now
        if state.get("state") == "propagating" and state.get("samples_compared", 0) > 0:
            marks["twin"] = now
    if "monitors" not in marks and all(
        http.get(f"http://127.0.0.1:{viewer + i}/").status_code == 200 for i in range(3)
    ):
        marks["monitors"] = now


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--satellites", type=int, default=100)
    parser.add_argument("--seconds", type=int, default=150)
    parser.add_argument("--no-archive-telemetry", action="store_true")
    parser.add_argument("--startup", action="store_true")
    parser.add_argument("--cold", action="store_true", help="--startup with an empty numba cache (compiling)")
    parser.add_argument("--exact-model", action="store_true", help="the satellite flies the twin's model exactly")
    args = parser.parse_args()
    if args.startup:
        startup(args.cold)
    else:
        fleet(args.satellites, args.seconds, not args.no_archive_telemetry, args.exact_model)


if __name__ == "__main__":
    main()
