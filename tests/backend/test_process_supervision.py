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
from tests.backend.conftest import free_port
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


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_normal_stop_leaves_no_child_and_prints_no_traceback(tmp_path: Path, sig: signal.Signals) -> None:
    api, telemetry = free_port(), free_port()
    process, lines = start_server(tmp_path, api, telemetry)
    try:
        assert any("emulator" in line for line in lines), lines
        children = wait_children(process, 2)
        assert health(api) == 200
        process.send_signal(sig)
        out, _ = process.communicate(timeout=STOP_TIMEOUT_S)
    finally:
        process.kill()
    assert process.returncode == 0, out
    assert wait_gone(children) == set()
    assert "Traceback" not in out
    assert "Traceback" not in (tmp_path / "emulator.log").read_text()


def test_kill_9_of_the_server_takes_its_children_and_a_restart_gets_the_ports_back(tmp_path: Path) -> None:
    api, telemetry = free_port(), free_port()
    process, lines = start_server(tmp_path, api, telemetry)
    try:
        children = wait_children(process, 2)
        process.kill()
        process.wait(10)
        assert wait_gone(children) == set()
    finally:
        process.kill()
    again, lines = start_server(tmp_path, api, telemetry)
    try:
        assert any("emulator" in line for line in lines), lines
        assert health(api) == 200
        children = wait_children(again, 2)
        again.send_signal(signal.SIGTERM)
        again.communicate(timeout=STOP_TIMEOUT_S)
    finally:
        again.kill()
    assert wait_gone(children) == set()


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


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_the_dask_workers_of_a_job_go_with_the_server(tmp_path: Path, sig: signal.Signals) -> None:
    api = free_port()
    process, lines = start_server(tmp_path, api, free_port(), "--no-emulator", "--job-workers", "2")
    try:
        before = wait_children(process, 1)  # the ingest process
        workers = _job_on_the_cluster(process, lines, api, before)
        assert len(workers) >= 2, workers  # the LocalCluster's two worker processes (and their helpers)
        process.send_signal(sig)
        out, _ = process.communicate(timeout=STOP_TIMEOUT_S)
    finally:
        process.kill()
    assert wait_gone(workers | before) == set()
    if sig == signal.SIGTERM:
        assert process.returncode == 0 and "Traceback" not in out, out
