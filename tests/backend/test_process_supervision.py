"""``acs-twin serve`` owns its children: no stop (SIGTERM, SIGINT, kill -9) leaves one running.

Truths: the kernel's process table (/proc: every descendant of the server, zombies counted as
gone), the ports (a restart on the same ports after kill -9 answers), and the server's own words
(no traceback on a normal stop; a busy port named with the process that holds it, and no admin
token spent on a start that failed).
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from tests import process_tree
from tests.ports import free_port
from tests.process_tree import descendants

pytestmark = pytest.mark.slow

START_TIMEOUT_S = 120.0  # cold imports of the server, the ingest process and the emulator on a busy machine
GONE_TIMEOUT_S = 25.0  # the ingest process archives what is pending before it exits (ORPHAN_EXIT_S = 20)
STOP_TIMEOUT_S = 180.0  # SIGTERM to exit: the ingest process archives what is pending (32 s seen at load 26)


def wait_gone(pids: set[int], timeout_s: float = GONE_TIMEOUT_S) -> set[int]:
    """Poll until none of ``pids`` runs; the ones left after ``timeout_s``."""
    return process_tree.wait_gone(pids, timeout_s)


def start_server(data_dir: Path, api_port: int, telemetry_port: int, *extra: str) -> tuple[subprocess.Popen, list[str]]:
    """``python -m backend serve`` on free loopback ports with the demo emulator; its start-up lines."""
    env = {
        **os.environ,
        "ACS_TWIN_DATA_DIR": str(data_dir),
        "ACS_TWIN_TELEMETRY_PORT": str(telemetry_port),
        "ACS_TWIN_VIEWER_PORT": str(free_port()),
    }
    env.pop("ACS_TWIN_DATABASE_URL", None)
    process = subprocess.Popen(
        [sys.executable, "-m", "backend", "serve", "--port", str(api_port), *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    lines: list[str] = []
    assert process.stdout is not None
    deadline = time.monotonic() + START_TIMEOUT_S
    while (line := process.stdout.readline()) and line.strip() and time.monotonic() < deadline:
        lines.append(line.rstrip())
    return process, lines


def wait_children(process: subprocess.Popen, count: int) -> set[int]:
    """The server's descendants once there are ``count`` of them (ingest process + emulator)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while len(found := descendants(process.pid)) < count and time.monotonic() < deadline:
        time.sleep(0.2)
    assert len(found) >= count, f"expected {count} children of the server, found {found}"
    return found


def health(port: int) -> int:
    return httpx.get(f"http://127.0.0.1:{port}/api/v1/health", timeout=5.0).status_code


DASK_JOB = {"kind": "rigid-spin", "duration_s": 2000.0, "dt_s": 0.001}  # runs long enough to be stopped mid-way
CLUSTER_START_TIMEOUT_S = 400.0  # the first job starts the LocalCluster: two workers import and warm the engine


def _job_on_the_cluster(process: subprocess.Popen, lines: list[str], api: int, before: set[int]) -> set[int]:
    """Start a job through the API; the server's new descendants once its Dask workers run it."""
    token = next(m.group(1) for line in lines if (m := re.search(r"admin token .*: (acs_\S+)", line)))
    headers = {"Authorization": f"Bearer {token}"}
    job_id = httpx.post(f"http://127.0.0.1:{api}/api/v1/simulations", json=DASK_JOB, headers=headers).json()["id"]
    deadline = time.monotonic() + CLUSTER_START_TIMEOUT_S
    while time.monotonic() < deadline:
        job = httpx.get(f"http://127.0.0.1:{api}/api/v1/simulations/{job_id}", headers=headers).json()
        if job["progress"] > 0.0:
            return descendants(process.pid) - before
        assert job["status"] in ("queued", "running"), job
        time.sleep(0.2)
    raise AssertionError(f"the job never ran: {job}")


def test_sigterm_stops_the_server_its_children_and_its_dask_workers_without_a_traceback(tmp_path: Path) -> None:
    api = free_port()
    process, lines = start_server(tmp_path, api, free_port(), "--job-workers", "2")
    try:
        assert any("emulator" in line for line in lines), lines
        children = wait_children(process, 2)  # the ingest process and the emulator
        assert health(api) == 200
        workers = _job_on_the_cluster(process, lines, api, children)
        assert len(workers) >= 2, workers  # the LocalCluster's two worker processes (and their helpers)
        process.send_signal(signal.SIGTERM)
        out, _ = process.communicate(timeout=STOP_TIMEOUT_S)
    finally:
        process.kill()
    assert process.returncode == 0, out
    assert wait_gone(children | workers) == set()
    assert "Traceback" not in out
    assert "Traceback" not in (tmp_path / "emulator.log").read_text()


def test_kill_9_takes_children_and_dask_workers_a_restart_gets_the_ports_back_and_sigint_stops_it(
    tmp_path: Path,
) -> None:
    """One server start-up per stop: kill -9 of a server with a job on its cluster, then SIGINT of its restart."""
    api, telemetry = free_port(), free_port()
    process, lines = start_server(tmp_path, api, telemetry, "--job-workers", "2")
    try:
        children = wait_children(process, 2)
        workers = _job_on_the_cluster(process, lines, api, children)
        assert len(workers) >= 2, workers
        process.kill()
        process.wait(10)
        assert wait_gone(children | workers) == set()
    finally:
        process.kill()
    log = tmp_path / "emulator.log"
    killed_part = log.stat().st_size  # what the killed server's emulator wrote (it is gone: nothing more comes)
    again, lines = start_server(tmp_path, api, telemetry)
    try:
        assert any("emulator" in line for line in lines), lines
        assert health(api) == 200
        children = wait_children(again, 2)
        again.send_signal(signal.SIGINT)
        out, _ = again.communicate(timeout=STOP_TIMEOUT_S)
    finally:
        again.kill()
    assert again.returncode == 0, out
    assert wait_gone(children) == set()
    assert "Traceback" not in out
    assert "Traceback" not in log.read_bytes()[killed_part:].decode()


def test_a_busy_port_is_named_with_its_holder_and_spends_no_admin_token(tmp_path: Path) -> None:
    api, telemetry = free_port(), free_port()
    with socket.socket() as squatter:
        squatter.bind(("127.0.0.1", telemetry))
        squatter.listen()
        process, lines = start_server(tmp_path, api, telemetry, "--no-emulator")
        out = "\n".join(lines) + process.communicate(timeout=STOP_TIMEOUT_S)[0]
    assert process.returncode != 0
    assert f"telemetry port 127.0.0.1:{telemetry}" in out and f"pid {os.getpid()}" in out, out
    assert "Traceback" not in out and "admin token" not in out
    process, lines = start_server(tmp_path, api, free_port(), "--no-emulator")
    try:
        assert any(re.search(r"admin token .*: acs_\S+", line) for line in lines), lines
    finally:
        process.send_signal(signal.SIGTERM)
        process.communicate(timeout=STOP_TIMEOUT_S)
