"""API load benchmark (issue 6): the downsampled-samples endpoint under wrk while a live stream is ingested.

    .venv/bin/python benchmarks/api_load.py [--seconds 20] [--connections 8] [--live-rate 2000]

Starts ``acs-twin serve`` (SQLite under a fresh data directory, auth on) as its own process,
uploads the real NOAA-20 diary (7,200 packets), then runs a sender process streaming reference-
satellite ACS_HK packets over TCP to the live listener at --live-rate packets/s (wall-clock time
stamps, 47 parameters each) and, meanwhile, wrk (Debian ``wrk``) on loopback against
``GET /api/v1/parameters/q_ib_0/samples`` (2-hour window, max_points=1000), twice:
  * dashboard: every request asks the same window (answers come from the per-window cache,
    refreshed whenever ingested data overlaps the window);
  * distinct: a wrk Lua script gives every request a different window end, so no answer is ever
    reused: each is sliced from the parameter's decoded series (read from the archive once, kept
    in memory until an ingest touches the satellite), downsampled and serialised.
Target: ≥ 1,000 requests/s with p99 < 50 ms. Prints the figures and the ingest tallies.
"""

from __future__ import annotations

import argparse
import multiprocessing
import re
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from benchmarks.serve_process import start_serve

REPO = Path(__file__).resolve().parents[1]
DIARY = REPO.parent / "shared/data/real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
WINDOW = "start=2021-04-09T00:00:00Z&end=2021-04-09T02:00:00Z&max_points=1000"
LIVE_BURST = 20  # packets per send
TARGET_RPS, TARGET_P99_MS = 1_000.0, 50.0
DISTINCT_LUA = """
counter = 0
request = function()
  counter = counter + 1
  local minute = counter % 7200
  local query = "start=2021-04-09T00:00:00Z&end=2021-04-09T%02d:%02d:%02dZ&max_points=1000"
  local path = "/api/v1/parameters/q_ib_0/samples?" .. string.format(query,
               1 + math.floor(minute / 3600), math.floor(minute / 60) % 60, minute % 60)
  return wrk.format("GET", path)
end
"""


def free_port() -> int:
    """A TCP port free on loopback right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def make_tokens(data_dir: Path) -> dict[str, str]:
    """Viewer and operator tokens issued in the server's database before it starts."""
    from backend.core.auth import Role
    from backend.core.settings import Settings
    from backend.services import build_services

    services = build_services(Settings(data_dir=data_dir))
    tokens = {role.name: services.auth.issue(f"bench-{role.name}", role)[1] for role in (Role.viewer, Role.operator)}
    services.engine.dispose()
    return tokens


def start_server(data_dir: Path, port: int, live_port: int) -> subprocess.Popen:
    """``acs-twin serve`` in its own process, live stream of the reference satellite on live_port."""
    live = {
        "ACS_TWIN_TELEMETRY_PORT": str(live_port),
        "ACS_TWIN_LIVE_DICTIONARY": "reference_satellite.yaml",
        "ACS_TWIN_LIVE_SATELLITE": "REFSAT",
    }
    return start_serve(data_dir, port, env=live)


def live_sender(port: int, seconds: float, rate_hz: float) -> None:
    """Stream ACS_HK packets of the reference satellite at rate_hz, stamped with the wall clock."""
    from telemetry.dictionary import load_dictionary
    from telemetry.encoding import encode_packets

    packet = load_dictionary("reference_satellite.yaml").packets[256]
    rng = np.random.default_rng(6)
    values = {
        p.name: (rng.normal(0.0, 0.01, LIVE_BURST) if p.data_type == "float" else np.zeros(LIVE_BURST))
        for p in packet.parameters
    }
    period = LIVE_BURST / rate_hz
    with socket.create_connection(("127.0.0.1", port)) as link:
        link.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        start = time.perf_counter()
        for k in range(int(seconds / period)):
            delay = start + k * period - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            t = time.time_ns() + np.arange(LIVE_BURST, dtype=np.int64) * int(1e9 / rate_hz)
            seq = (k * LIVE_BURST + np.arange(LIVE_BURST)) % 16_384
            link.sendall(encode_packets(packet, t, seq, values).tobytes())


def run_wrk(url: str, token: str, seconds: int, connections: int, script: Path | None) -> dict[str, float]:
    """wrk -t2 on loopback; requests/s, p50/p99 latency (ms), non-2xx answers and socket errors."""
    command = ["wrk", "-t2", f"-c{connections}", f"-d{seconds}s", "--latency", "-H", f"Authorization: Bearer {token}"]
    if script is not None:
        command += ["-s", str(script)]
    out = subprocess.run(command + [url], capture_output=True, text=True, check=True).stdout
    unit = {"us": 1e-3, "ms": 1.0, "s": 1e3}
    latency = {q: float(v) * unit[u] for q, v, u in re.findall(r"^\s+(50|99)%\s+([\d.]+)(us|ms|s)", out, re.M)}
    non_2xx = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    errors = re.search(r"Socket errors: connect (\d+), read (\d+), write (\d+), timeout (\d+)", out)
    return {
        "rps": float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1)),
        "p50_ms": latency["50"],
        "p99_ms": latency["99"],
        "non_2xx": float(non_2xx.group(1)) if non_2xx else 0.0,
        "socket_errors": float(sum(int(g) for g in errors.groups())) if errors else 0.0,
    }


def report(name: str, figures: dict[str, float]) -> bool:
    """Print one run's figures against the target; True when it meets it."""
    ok = figures["rps"] >= TARGET_RPS and figures["p99_ms"] < TARGET_P99_MS and figures["non_2xx"] == 0
    print(
        f"  {name:10s} {figures['rps']:8.0f} req/s   p50 {figures['p50_ms']:6.2f} ms   "
        f"p99 {figures['p99_ms']:6.2f} ms   non-2xx {figures['non_2xx']:.0f}   "
        f"socket errors {figures['socket_errors']:.0f}   {'meets' if ok else 'MISSES'} target"
    )
    return ok


def main() -> None:
    """Run both wrk passes under the live stream and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=int, default=20)
    parser.add_argument("--connections", type=int, default=8)
    parser.add_argument("--live-rate", type=float, default=2_000.0)
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        raise SystemExit("wrk not found: apt-get install -y wrk")
    data_dir = Path(tempfile.mkdtemp(prefix="acs-twin-api-load-"))
    tokens = make_tokens(data_dir)
    port, live_port = free_port(), free_port()
    server = start_server(data_dir, port, live_port)
    base = f"http://127.0.0.1:{port}/api/v1"
    try:
        upload = httpx.post(
            f"{base}/telemetry/uploads",
            content=DIARY.read_bytes(),
            timeout=120,
            headers={"Authorization": f"Bearer {tokens['operator']}"},
        ).json()
        print(f"uploaded NOAA-20 diary: {upload['archive']['packets_accepted']} packets")
        script = data_dir / "distinct.lua"
        script.write_text(DISTINCT_LUA)
        stream_s = 2 * args.seconds + 10
        sender = multiprocessing.get_context("spawn").Process(
            target=live_sender, args=(live_port, stream_s, args.live_rate)
        )
        sender.start()
        time.sleep(2.0)
        before = httpx.get(f"{base}/health").json()["live"]
        dashboard = run_wrk(
            f"{base}/parameters/q_ib_0/samples?{WINDOW}", tokens["viewer"], args.seconds, args.connections, None
        )
        distinct = run_wrk(
            f"{base}/parameters/q_ib_0/samples", tokens["viewer"], args.seconds, args.connections, script
        )
        after = httpx.get(f"{base}/health").json()["live"]
        sender.join(stream_s + 30)
        rate = (after["packets_received"] - before["packets_received"]) / (2 * args.seconds)
        print(
            f"live stream during the runs: {rate:.0f} packets/s received "
            f"({after['packets_archived']} archived in total, {after['archive_errors']} archive errors)"
        )
        print(
            f"GET /api/v1/parameters/q_ib_0/samples (max_points=1000), wrk -t2 -c{args.connections}, "
            f"{args.seconds} s each, target >= {TARGET_RPS:.0f} req/s with p99 < {TARGET_P99_MS:.0f} ms:"
        )
        report("dashboard", dashboard)
        report("distinct", distinct)
    finally:
        server.terminate()
        server.wait(30)
        shutil.rmtree(data_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
