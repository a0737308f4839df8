"""The process tree as the kernel has it (/proc, Linux): what a server left running, for the supervision
tests (tests/backend/test_process_supervision.py) and the hardening figures (benchmarks/hardening.py)."""

from __future__ import annotations

import time
from pathlib import Path

__all__ = ["descendants", "alive", "wait_gone"]


def _ppid_and_state(pid: int) -> tuple[int, str] | None:
    """Parent pid and state letter of ``pid`` (None once it is gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[1].split()  # the command name in parentheses may hold spaces
    return int(fields[1]), fields[0]


def descendants(pid: int) -> set[int]:
    """Every living process below ``pid`` in the process tree (zombies excluded)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (info := _ppid_and_state(int(entry.name))) and info[1] != "Z":
            children.setdefault(info[0], []).append(int(entry.name))
    found, frontier = set(), [pid]
    while frontier:
        for child in children.get(frontier.pop(), []):
            found.add(child)
            frontier.append(child)
    return found


def alive(pids: set[int]) -> set[int]:
    """The ``pids`` still running (not exited, not zombies)."""
    return {pid for pid in pids if (info := _ppid_and_state(pid)) is not None and info[1] != "Z"}


def wait_gone(pids: set[int], timeout_s: float) -> set[int]:
    """Poll until none of ``pids`` runs; the ones left after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while (left := alive(pids)) and time.monotonic() < deadline:
        time.sleep(0.1)
    return left
