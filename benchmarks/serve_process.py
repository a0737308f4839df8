"""``acs-twin serve`` in a process of its own, for the benchmarks that measure the real server; run as a script, the
figures of the server's process lifecycle (issue 17):

    .venv/bin/python -m benchmarks.serve_process [--repeats 3]

``acs-twin serve`` (fresh SQLite data directory, live link on an ephemeral port, no emulator) from the command to
/health 200 and from SIGINT to its exit, with the CPU of the server and its children; the upload decoder's first
file (process start, imports, kernels), a file on the running decoder, and a file right after it was SIGKILLed.
Medians of the repeats, wall seconds, with the load average before and after."""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path

import httpx

from tests.ports import free_port

REPO = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 300.0  # spawn, imports and the numba cache's load on a loaded 2-core machine
POLL_S = 0.3
STOP_TIMEOUT_S = 60.0
DECODER_CHUNKS = 3  # decode chunks (telemetry.packet_files.CHUNK_OCTETS) per file of the decoder figures


def start_serve(
    data_dir: Path, port: int, *flags: str, env: Mapping[str, str] | None = None, timeout_s: float = START_TIMEOUT_S
) -> subprocess.Popen[bytes]:
    """``python -m backend serve --port PORT --data-dir DATA_DIR *flags`` with ``env`` added to this process's
    environment, returned once ``/api/v1/health`` answers 200; RuntimeError (the server killed) if it exits or
    does not answer within ``timeout_s``."""
    command = [sys.executable, "-m", "backend", "serve", "--port", str(port), "--data-dir", str(data_dir), *flags]
    server = subprocess.Popen(
        command, cwd=REPO, env={**os.environ, **(env or {})}, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT
    )
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and server.poll() is None:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/api/v1/health", timeout=2.0).status_code == 200:
                return server
        except httpx.TransportError:
            time.sleep(POLL_S)
    server.kill()
    raise RuntimeError(f"acs-twin serve did not answer on port {port} within {timeout_s:.0f} s (exit {server.poll()})")


def _serve_cycle(port: int) -> tuple[float, float, float]:
    """One ``acs-twin serve`` (fresh SQLite data directory, live link on an ephemeral port, no emulator): wall s from
    the command to /health 200, from SIGINT to its exit, and the CPU s of the server and the children it reaped."""
    before = os.times()
    with tempfile.TemporaryDirectory() as data_dir:
        started = time.monotonic()
        server = start_serve(Path(data_dir), port, env={"ACS_TWIN_TELEMETRY_PORT": "0"})
        try:
            healthy = time.monotonic() - started
            stopping = time.monotonic()
            server.send_signal(signal.SIGINT)
            server.wait(STOP_TIMEOUT_S)
            stopped = time.monotonic() - stopping
        finally:  # a server that did not stop in time is killed (its children die with it), not left running
            if server.poll() is None:
                server.kill()
                server.wait()
    after = os.times()
    cpu = after.children_user - before.children_user + after.children_system - before.children_system
    return healthy, stopped, cpu


def _decoder_runs(data_dir: Path) -> tuple[float, float, float]:
    """The upload decoder on files of DECODER_CHUNKS chunks (tests.telemetry.packet_streams.mixed_stream, each new):
    wall s of its first file (spawn, imports, kernels from numba's cache, decode, archive), of a file on the running
    decoder, and of a file right after the decoder was killed (SIGKILL: a fresh process takes it)."""
    from backend.ingest.upload_decoder import PacketFileJob, UploadDecoder
    from telemetry.archive import Archive
    from telemetry.packet_files import CHUNK_OCTETS
    from tests.telemetry.packet_streams import HK_PER_GPS, mixed_stream

    url = f"sqlite:///{data_dir / 'archive.sqlite'}"
    Archive(url).close()  # created and migrated, as the server does
    dictionaries = REPO / "telemetry" / "dictionaries"
    n_gps = DECODER_CHUNKS * CHUNK_OCTETS // ((HK_PER_GPS * 126 + 62) * 3)  # three files from one stream
    stream = mixed_stream(3 * n_gps)
    files = []
    for i in range(3):
        path = data_dir / f"upload{i}.bin"
        path.write_bytes(stream[i * len(stream) // 3 : (i + 1) * len(stream) // 3])
        files.append(PacketFileJob(path, "BENCH", "reference_satellite.yaml", f"file {i}", "benchmark"))
    decoder = UploadDecoder(url, dictionaries)
    walls = []
    try:
        for i, job in enumerate(files):
            if i == 2 and decoder.pid is not None:
                os.kill(decoder.pid, signal.SIGKILL)
            started = time.monotonic()
            decoder.run(job)
            walls.append(time.monotonic() - started)
    finally:
        decoder.stop()
    return walls[0], walls[1], walls[2]


def main() -> None:
    """Print the figures of the server's process lifecycle (median of --repeats) and the load average."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    cycles = [_serve_cycle(free_port()) for _ in range(args.repeats)]
    for name, values in zip(("start -> /health 200", "SIGINT -> exit", "server CPU"), zip(*cycles, strict=True)):
        runs = ", ".join(f"{v:.2f}" for v in values)
        print(f"acs-twin serve {name}: median {statistics.median(values):.2f} s (runs {runs})")
    decoder = []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as data_dir:
            decoder.append(_decoder_runs(Path(data_dir)))
    first, warm, restarted = (statistics.median(v) for v in zip(*decoder, strict=True))
    print(
        f"upload decoder, {DECODER_CHUNKS}-chunk file: first {first:.2f} s, running decoder {warm:.2f} s, "
        f"after a SIGKILL {restarted:.2f} s (restart cost {restarted - warm:.2f} s)"
    )
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
