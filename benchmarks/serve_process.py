"""``acs-twin serve`` in a process of its own, for the benchmarks that measure the real server."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 300.0  # spawn, imports and the numba cache's load on a loaded 2-core machine
POLL_S = 0.3


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
