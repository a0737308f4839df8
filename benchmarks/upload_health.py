"""Upload responsiveness (issue 12): GET /health latency while a large packet file is uploaded to the server.

    .venv/bin/python benchmarks/upload_health.py [--mb 200]

Starts ``acs-twin serve`` (its own process, SQLite, auth on; benchmarks/api_load.py helpers), uploads the
CYGNSS FM07 L0 stream (tests/data) replicated to --mb MB with every copy shifted in time (all packets
new) from a process of its own against a ccsdspy CSV dictionary uploaded with its time fields, and
meanwhile asks GET /api/v1/health every 20 ms from another thread. Prints the health p50/p99/max during
the upload (split at the uploader's last byte: body streaming vs the decoder's work) and, as the peer, over
IDLE_S on the idle server just before (the machine's own load shows there), the upload time, the archive's
tally, the server's peak RSS rise and the upload decoder's peak RSS, and the load average. Target: p99 <
100 ms during the upload. benchmarks/hardening.py reports the same measurement (``measure``).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from api_load import free_port, make_tokens  # noqa: E402
from foreign import CYGNSS_STREAM, CYGNSS_TIME, DATA, _calendar_shift, replicate  # noqa: E402

from backend.core.processes import cpu_seconds  # noqa: E402
from tests.process_tree import descendants  # noqa: E402 - the supervision tests' view of the process tree

START_STALL_S = 120.0  # a server start fails after this long without progress (no CPU time used by its process tree):
# at load 30 on 2 cores its imports alone take minutes, so a fixed limit killed servers that were still starting
IDLE_S = 10.0  # health polled this long on the idle server first: the same run's baseline
BLOCK_OCTETS = 2**20  # the uploader hands the body to httpx in blocks of this size


def start_server(data_dir: Path, port: int) -> subprocess.Popen:
    """``acs-twin serve`` in its own process (no live stream), waited for while it starts (``wait_answering``)."""
    env = {**os.environ, "ACS_TWIN_DATA_DIR": str(data_dir), "ACS_TWIN_LIVE_ENABLED": "false"}
    server = subprocess.Popen(
        [sys.executable, "-m", "backend", "serve", "--port", str(port)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
    )
    with httpx.Client(base_url=f"http://127.0.0.1:{port}/api/v1") as http:
        if wait_answering(server, http):
            return server
    server.kill()
    raise SystemExit("server did not start")


def wait_answering(server: subprocess.Popen, http: httpx.Client) -> bool:
    """True once ``server`` answers GET /health 200; False if it exited or its process tree used no CPU time for
    START_STALL_S (on a loaded machine a start takes minutes, but never without progress)."""
    cpu, progressed = -1.0, time.monotonic()
    while time.monotonic() - progressed < START_STALL_S and server.poll() is None:
        try:
            if http.get("/health", timeout=2.0).status_code == 200:
                return True
        except httpx.TransportError:
            time.sleep(0.2)
        if (now_cpu := _tree_cpu_s(server.pid)) > cpu:
            cpu, progressed = now_cpu, time.monotonic()
    return False


def _tree_cpu_s(pid: int) -> float:
    """CPU time (s) used so far by process ``pid`` and its living descendants."""
    return sum(cpu_seconds(p) or 0.0 for p in {pid} | descendants(pid))


def poll_health(base: str, stop: threading.Event, out: list[float], at: list[float] | None = None) -> None:
    """Latency (s) of GET /health every 20 ms until stop is set (and when each was sent, into ``at``)."""
    with httpx.Client(timeout=30) as client:
        while not stop.is_set():
            t0 = time.perf_counter()
            client.get(f"{base}/health")
            out.append(time.perf_counter() - t0)
            if at is not None:
                at.append(t0)
            time.sleep(0.02)


def _summary(ms: np.ndarray) -> str:
    if ms.size == 0:
        return "no request"
    return f"{ms.size} requests, p50 {np.percentile(ms, 50):.1f} ms, p99 {np.percentile(ms, 99):.1f} ms"


def upload(base: str, path: Path, headers: dict[str, str]) -> tuple[float, float, dict]:
    """POST the packet file (run in a process of its own: the client's GIL stays out of the health timings):
    (seconds, when its last byte went to the socket on the system-wide perf_counter clock, answer)."""
    sent: list[float] = []

    def blocks() -> Iterator[bytes]:
        with path.open("rb") as f:
            while block := f.read(BLOCK_OCTETS):
                yield block
        sent.append(time.perf_counter())

    t0 = time.perf_counter()
    answer = httpx.post(
        f"{base}/telemetry/uploads",
        params={"satellite": "CYGNSS-FM07", "dictionary": "cygnss_adcsio.csv"},
        content=blocks(),
        headers={**headers, "content-length": str(path.stat().st_size)},
        timeout=3600,
    )
    answer.raise_for_status()
    return time.perf_counter() - t0, sent[0], answer.json()


@dataclass
class UploadHealth:
    """Health latencies (ms) idle and during one upload, with the upload's tallies and the memory it took."""

    size_mb: float
    seconds: float
    archive: dict
    idle_ms: np.ndarray
    busy_ms: np.ndarray
    body_phase: np.ndarray  # per busy request: sent before the upload's last byte went out
    server_rss_rise_kb: int  # the server's peak RSS (VmHWM after its reset) over its RSS before the upload
    decoder_peak_kb: int  # peak RSS of the server's children started by the upload (the upload decoder)
    load: tuple[float, float]  # load average (1 min) at start and end

    def report(self) -> str:
        """The figures, the during/idle ratio and the load, for printing."""
        ms, idle = self.busy_ms, self.idle_ms
        return (
            f"upload of {self.size_mb:.0f} MB: {self.seconds:.1f} s, {self.archive['packets_accepted']:,} packets "
            f"archived ({self.archive['samples_accepted']:,} samples); server peak RSS rise "
            f"{self.server_rss_rise_kb / 1000:.0f} MB, upload decoder peak RSS {self.decoder_peak_kb / 1000:.0f} MB\n"
            f"health during it: {len(ms)} requests, p50 {np.percentile(ms, 50):.1f} ms, "
            f"p99 {np.percentile(ms, 99):.1f} ms, max {ms.max():.1f} ms (target p99 < 100 ms)\n"
            f"  while the body was sent (streamed to disk): {_summary(ms[self.body_phase])}\n"
            f"  after (the decoder process decoded and committed it): {_summary(ms[~self.body_phase])}\n"
            f"health idle ({IDLE_S:.0f} s before, same server): {len(idle)} requests, "
            f"p50 {np.percentile(idle, 50):.1f} ms, p99 {np.percentile(idle, 99):.1f} ms; p99 during / idle = "
            f"{np.percentile(ms, 99) / np.percentile(idle, 99):.2f}\n"
            f"load average (1 min) at start {self.load[0]:.1f}, at end {self.load[1]:.1f} (2 cores shared)"
        )


def status_kb(pid: int, key: str) -> int:
    """A /proc/<pid>/status figure in kB (0 once the process is gone)."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError:
        return 0
    return next((int(line.split()[1]) for line in lines if line.startswith(key + ":")), 0)


def measure(mb: float) -> UploadHealth:
    """Health idle for IDLE_S, then during an upload of ``mb`` MB of new CYGNSS packets, on a server of its own."""
    from telemetry.dictionary import load_dictionary

    load_start = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cygnss = load_dictionary(DATA / "cygnss_f7" / "ccsdspy", time_fields=CYGNSS_TIME)
        path = work / "upload.tlm"
        data = CYGNSS_STREAM.read_bytes()
        replicate(data, int(mb * 1e6 / len(data)), path, _calendar_shift(cygnss), block=2000)
        data_dir = work / "data"
        tokens = make_tokens(data_dir)
        port = free_port()
        server = start_server(data_dir, port)
        base = f"http://127.0.0.1:{port}/api/v1"
        operator = {"Authorization": f"Bearer {tokens['operator']}"}
        try:
            _upload_dictionary(base, operator)
            idle: list[float] = []
            stop = threading.Event()
            poller = threading.Thread(target=poll_health, args=(base, stop, idle))
            poller.start()
            time.sleep(IDLE_S)
            stop.set()
            poller.join()
            stop.clear()
            busy: list[float] = []
            sent_at: list[float] = []
            before_upload = descendants(server.pid)
            Path(f"/proc/{server.pid}/clear_refs").write_text("5")  # VmHWM from here on
            rss_before = status_kb(server.pid, "VmRSS")
            poller = threading.Thread(target=poll_health, args=(base, stop, busy, sent_at))
            poller.start()
            with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as uploader:
                elapsed, body_sent_at, body = uploader.submit(upload, base, path, operator).result()
            stop.set()
            poller.join()
            started = descendants(server.pid) - before_upload
            return UploadHealth(
                size_mb=path.stat().st_size / 1e6,
                seconds=elapsed,
                archive=body["archive"],
                idle_ms=np.array(idle) * 1e3,
                busy_ms=np.array(busy) * 1e3,
                body_phase=np.array(sent_at) < body_sent_at,
                server_rss_rise_kb=status_kb(server.pid, "VmHWM") - rss_before,
                decoder_peak_kb=max((status_kb(pid, "VmHWM") for pid in started), default=0),
                load=(load_start, os.getloadavg()[0]),
            )
        finally:
            server.terminate()
            server.wait(60)


def _upload_dictionary(base: str, operator: dict[str, str]) -> None:
    """The CYGNSS ADCS packet layout as the operator's dictionary cygnss_adcsio.csv, with its time fields."""
    layout = (DATA / "cygnss_f7" / "ccsdspy" / "apid00393.csv").read_bytes()
    made = httpx.post(
        f"{base}/dictionaries/cygnss_adcsio.csv",
        params={"apid": 393, "time_fields": CYGNSS_TIME},
        content=layout,
        headers=operator,
        timeout=60,
    )
    made.raise_for_status()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mb", type=float, default=200.0)
    args = parser.parse_args()
    print(measure(args.mb).report())


if __name__ == "__main__":
    main()
