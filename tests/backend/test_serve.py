"""``acs-twin serve`` as a real process: prints URLs, an admin token once, serves the API."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx

from tests.ports import free_port

START_TIMEOUT_S = 60.0  # cold imports of numpy/numba/sqlalchemy on a busy 2-core machine


def _serve(data_dir: Path, port: int) -> tuple[subprocess.Popen, list[str]]:
    env = {**os.environ, "ACS_TWIN_DATA_DIR": str(data_dir), "ACS_TWIN_TELEMETRY_PORT": "0"}
    env.pop("ACS_TWIN_DATABASE_URL", None)
    process = subprocess.Popen(
        [sys.executable, "-m", "backend", "serve", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    lines: list[str] = []
    assert process.stdout is not None
    while (line := process.stdout.readline()) and line.strip():
        lines.append(line.rstrip())
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        try:
            httpx.get(f"http://127.0.0.1:{port}/api/v1/health", timeout=1.0)
            return process, lines
        except httpx.TransportError:
            time.sleep(0.2)
    process.kill()
    raise AssertionError(f"server did not answer: {lines}")


def _stop(process: subprocess.Popen) -> None:
    process.send_signal(signal.SIGINT)
    process.wait(timeout=30)


def test_first_start_prints_an_admin_token_once_and_binds_loopback(tmp_path: Path) -> None:
    port = free_port()
    process, lines = _serve(tmp_path, port)
    try:
        found = [m.group(1) for line in lines if (m := re.search(r"admin token .*: (acs_\S+)", line))]
        assert len(found) == 1, lines
        assert any(f"http://127.0.0.1:{port}/api/v1" in line for line in lines)
        tokens = httpx.get(
            f"http://127.0.0.1:{port}/api/v1/tokens", headers={"Authorization": f"Bearer {found[0]}"}
        ).json()
        assert [t["role"] for t in tokens] == ["admin"]
        assert httpx.get(f"http://127.0.0.1:{port}/api/v1/tokens").status_code == 401
    finally:
        _stop(process)
    assert (tmp_path / "acs-twin.sqlite").exists()
    again, lines = _serve(tmp_path, port)
    try:
        assert not any("admin token" in line for line in lines)
    finally:
        _stop(again)
