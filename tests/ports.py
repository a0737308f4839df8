"""Loopback ports for the servers the tests start."""

from __future__ import annotations

import random
import socket
from pathlib import Path

EPHEMERAL_RANGE = Path("/proc/sys/net/ipv4/ip_local_port_range")
LOWEST = 10_000  # below: well-known and registered services' ports


def _ephemeral_start() -> int:
    """First port of the kernel's range for outgoing connections (Linux default 32768)."""
    try:
        return int(EPHEMERAL_RANGE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32_768


def free_port() -> int:
    """A TCP port free on loopback now, below the kernel's ephemeral range.

    ``bind(0)`` hands out a port inside that range, where any outgoing connection of the processes a test starts
    (Dask's workers, database and HTTP clients) can take it before the server binds it (seen: the monitor gate's
    "address already in use" once in ~20 SIGTERM supervision runs). A random port below the range is only ever
    taken by a listener, and one that is bound now is skipped.
    """
    top = _ephemeral_start()
    for _ in range(200):
        port = random.randrange(LOWEST, top)
        with socket.socket() as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise RuntimeError(f"no free loopback port in {LOWEST}–{top - 1}")
