"""Hardening figures (issue 16): kill -9 trials, leaked processes after stops, health p99 during a big upload.

    .venv/bin/python benchmarks/hardening.py [--kill-trials 20] [--stops 20] [--upload-mb 200] [--parallel 4]

Each run starts the real ``acs-twin serve`` (SQLite in a fresh data directory, auth off, demo
emulator on, free loopback ports) as its own process:
  * kill -9 trials: while a thread uploads slices of the real NOAA-20 diary (600 packets each, one
    satellite name per upload) the server is killed with SIGKILL at a random instant (0-3 s after the
    trial's first upload was answered: before it, a loaded machine may still be warming up); it is started
    again on the same ports and data, and every upload that was answered 200 (acknowledged) must be
    in the archive with all its accepted samples. Lost = acknowledged samples not found afterwards.
    The server's children (live-ingest process, emulator, job workers) must all be gone after each kill.
  * stops: SIGTERM and SIGINT alternately; the children still running afterwards are counted.
  * health during an upload: benchmarks/upload_health.py's measurement (--upload-mb of new CYGNSS packets
    from a process of their own, health polled from another thread; p50/p99 by phase beside the same server's
    idle p99, the server's peak RSS rise and the upload decoder's peak RSS).
The health measurement runs alone, first; the kill trials then run as --parallel independent chains (each its own
data directory and ports) and the stops --parallel at a time: the servers' start-ups (imports, minutes each on a
loaded machine) overlap, so that the whole run ends in minutes, not an hour.
Targets: 0 samples lost, 0 processes leaked, health p99 < 100 ms.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from tests import process_tree  # noqa: E402 - the supervision tests' view of the process tree
from tests.process_tree import alive, descendants  # noqa: E402

sys.path.insert(0, str(REPO / "benchmarks"))
import upload_health  # noqa: E402 - the health-during-upload measurement lives there

DIARY = REPO.parent / "shared/data/real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
PACKET_OCTETS = 71  # the diary's APID 11 packets
SLICE_PACKETS = 600
START_TIMEOUT_S = 300.0  # a loaded 2-core machine: the children of a server that answers
GONE_TIMEOUT_S = 25.0


def free_port() -> int:
    """A TCP port free on loopback now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_gone(pids: set[int]) -> set[int]:
    """Poll until none of ``pids`` runs; those left after GONE_TIMEOUT_S."""
    return process_tree.wait_gone(pids, GONE_TIMEOUT_S)


class Server:
    """``python -m backend serve`` with the demo emulator, on fixed ports and a data directory."""

    def __init__(self, data_dir: Path, api: int, telemetry: int, viewer: int, *extra: str) -> None:
        env = {
            **os.environ,
            "ACS_TWIN_DATA_DIR": str(data_dir),
            "ACS_TWIN_TELEMETRY_PORT": str(telemetry),
            "ACS_TWIN_VIEWER_PORT": str(viewer),
            "PYTHONPATH": str(REPO),
        }
        env.pop("ACS_TWIN_DATABASE_URL", None)
        command = [sys.executable, "-m", "backend", "serve", "--port", str(api), "--no-auth", *extra]
        self.log = data_dir / "serve.log"
        with self.log.open("ab") as log:
            self.process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=REPO)
        self.http = httpx.Client(base_url=f"http://127.0.0.1:{api}/api/v1", timeout=60.0)
        if upload_health.wait_answering(self.process, self.http):
            return
        self.process.kill()
        tail = self.log.read_text(errors="replace")[-2000:]
        raise RuntimeError(f"server did not answer (exit code {self.process.wait()}); its output ends:\n{tail}")

    def children(self, count: int = 2) -> set[int]:
        """Its descendants once there are ``count`` (ingest process + emulator)."""
        deadline = time.monotonic() + START_TIMEOUT_S
        while len(found := descendants(self.process.pid)) < count and time.monotonic() < deadline:
            time.sleep(0.2)
        return found


def kill_trials(trials: int, diary: bytes, chains: int) -> tuple[int, int, int, int]:
    """(acknowledged uploads, acknowledged samples, samples lost, processes leaked) over ``trials`` kill -9s, made
    by ``chains`` independent chains of trials at once."""
    shares = [trials // chains + (c < trials % chains) for c in range(chains)]
    with ThreadPoolExecutor(chains) as pool:
        results = list(pool.map(kill_chain, range(chains), shares, [diary] * chains))
    uploads, samples, lost, leaked = (sum(column) for column in zip(*results, strict=True))
    return uploads, samples, lost, leaked


def kill_chain(chain: int, trials: int, diary: bytes) -> tuple[int, int, int, int]:
    """``kill_trials`` of one chain: one data directory and set of ports, killed and restarted ``trials`` times."""
    data_dir = Path(tempfile.mkdtemp(prefix="acs-hardening-"))
    ports = (free_port(), free_port(), free_port())
    acknowledged: dict[str, int] = {}
    leaked = 0
    rng = random.Random(16 + chain)
    n_slices = len(diary) // (PACKET_OCTETS * SLICE_PACKETS)
    for trial in range(trials):
        started = time.monotonic()
        server = Server(data_dir, *ports)
        children = server.children()
        stop, first_answered = threading.Event(), threading.Event()

        def upload(
            trial: int = trial, server: Server = server, stop: threading.Event = stop, first=first_answered
        ) -> None:
            k = 0
            while not stop.is_set():
                at = (k % n_slices) * PACKET_OCTETS * SLICE_PACKETS
                satellite = f"KILL-{chain}-{trial}-{k}"
                try:
                    answer = server.http.post(
                        "/telemetry/uploads",
                        params={"satellite": satellite},
                        content=diary[at : at + PACKET_OCTETS * SLICE_PACKETS],
                        timeout=START_TIMEOUT_S,  # only the kill ends it: the first one warms the decode path
                    )
                except httpx.TransportError:
                    return  # killed mid-request: not acknowledged
                if answer.status_code == 200:
                    acknowledged[satellite] = answer.json()["archive"]["packets_accepted"]
                first.set()
                k += 1

        sender = threading.Thread(target=upload)
        sender.start()
        while sender.is_alive() and not first_answered.wait(1.0):  # the first upload: minutes under load
            pass
        time.sleep(rng.uniform(0.0, 3.0))
        server.process.kill()
        server.process.wait(30)
        stop.set()
        sender.join(60)
        leaked += len(wait_gone(children))
        print(
            f"  kill -9 chain {chain} trial {trial + 1}/{trials}: {len(acknowledged)} uploads acknowledged so far, "
            f"children left {len(alive(children))} ({time.monotonic() - started:.0f} s)",
            flush=True,
        )
    server = Server(data_dir, *ports)
    lost = 0
    for satellite, accepted in acknowledged.items():
        found = server.http.get(
            "/parameters/ADCFAQ4/samples",
            params={
                "satellite": satellite,
                "start": "2021-04-09T00:00:00Z",
                "end": "2021-04-10T00:00:00Z",
                "max_points": 100_000,
            },
        )
        count = len(found.json().get("values", [])) if found.status_code == 200 else 0
        lost += max(accepted - count, 0)
    children = server.children()
    server.process.send_signal(signal.SIGTERM)
    server.process.wait(300)
    leaked += len(wait_gone(children))
    return len(acknowledged), sum(acknowledged.values()), lost, leaked


def stop_trials(stops: int, parallel: int) -> int:
    """Processes left running after ``stops`` SIGTERM / SIGINT stops (alternating), ``parallel`` at a time."""
    with ThreadPoolExecutor(parallel) as pool:
        return sum(pool.map(lambda k: stop_once(k, stops), range(stops)))


def stop_once(k: int, stops: int) -> int:
    """Processes left running after stop ``k`` (SIGTERM if even, else SIGINT) of a fresh server."""
    server = Server(Path(tempfile.mkdtemp(prefix="acs-hardening-")), free_port(), free_port(), free_port())
    children = server.children()
    server.process.send_signal(signal.SIGTERM if k % 2 == 0 else signal.SIGINT)
    server.process.wait(300)
    left = wait_gone(children)
    print(
        f"  stop {k + 1}/{stops} ({'SIGTERM' if k % 2 == 0 else 'SIGINT'}): {len(children)} children, {len(left)} left",
        flush=True,
    )
    return len(left)


def main() -> None:
    """Run the three measurements and print the figures against their targets."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--kill-trials", type=int, default=20)
    parser.add_argument("--stops", type=int, default=20)
    parser.add_argument("--upload-mb", type=float, default=200.0)
    parser.add_argument("--parallel", type=int, default=4, help="kill-trial chains and stops at once")
    args = parser.parse_args()
    started = time.monotonic()
    diary = DIARY.read_bytes()
    if args.upload_mb > 0:
        print(upload_health.measure(args.upload_mb).report(), flush=True)
    if args.kill_trials > 0:
        uploads, samples, lost, leaked = kill_trials(args.kill_trials, diary, min(args.parallel, args.kill_trials))
        print(
            f"kill -9 trials: {args.kill_trials}, acknowledged uploads {uploads} ({samples} samples), "
            f"samples lost {lost} (target 0), processes leaked {leaked} (target 0)",
            flush=True,
        )
    if args.stops > 0:
        leaked = stop_trials(args.stops, args.parallel)
        print(f"stops (SIGTERM/SIGINT alternately): {args.stops}, processes leaked {leaked} (target 0)", flush=True)
    print(f"hardening figures in {time.monotonic() - started:.0f} s, load average {os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
