"""Child processes the server owns: each in its own process group, stopped on every exit path, and
gone with the server even after ``kill -9`` (Linux parent-death signal, a parent watch as backstop).

A child started by :func:`spawn_owned` (subprocess) or a ``multiprocessing`` child that calls
:func:`become_owned_child` first thing leaves the terminal's process group (a Ctrl-C reaches only
the server, which stops its children in order) and receives SIGTERM as soon as the server dies.
:func:`port_holder` says which process holds a TCP port when a bind fails.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import IO

__all__ = [
    "BULK_NICENESS",
    "PARENT_ENV",
    "become_owned_child",
    "cpu_seconds",
    "die_with_parent",
    "port_holder",
    "spawn_owned",
    "stop_owned",
]

PARENT_ENV = "ACS_TWIN_PARENT_PID"  # set by spawn_owned; the child's CLI calls die_with_parent()
PR_SET_PDEATHSIG = 1  # linux/prctl.h
PARENT_POLL_S = 0.5  # backstop where the parent-death signal is missing (macOS) or was armed too late
STOP_GRACE_S = 10.0  # a child gets this long after SIGTERM before SIGKILL
BULK_NICENESS = 10  # a child doing bulk work (the upload decoders and their fork server): on a busy CPU the server's
# requests go first (/health during a 200 MB upload: benchmarks/upload_health.py)


def die_with_parent(parent_pid: int | None = None, sig: int = signal.SIGTERM) -> None:
    """In a child: receive ``sig`` when ``parent_pid`` (default: $ACS_TWIN_PARENT_PID) dies; no-op without one."""
    if parent_pid is None:
        parent_pid = int(os.environ.pop(PARENT_ENV, "0")) or None  # popped: grandchildren have other parents
    if parent_pid is None:
        return
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
    threading.Thread(target=_watch_parent, args=(parent_pid, sig), name="parent-watch", daemon=True).start()


def _watch_parent(parent_pid: int, sig: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os.kill(os.getpid(), sig)  # re-parented: the server is gone (also covers a death before prctl)


def become_owned_child() -> None:
    """First call of a multiprocessing child: own process group (no terminal Ctrl-C), dies with the parent.

    A child of a ``forkserver`` context is the fork server's child: it dies with the fork server, which
    exits as soon as the process that started it does (multiprocessing closes its end of the server's alive pipe).
    """
    import multiprocessing

    parent = multiprocessing.parent_process()
    with contextlib.suppress(OSError):
        os.setpgid(0, 0)
    if parent is None or not parent.pid:
        return
    forked_by = os.getppid()
    if forked_by != parent.pid and parent.is_alive():  # forked by a fork server, which exits with the server
        die_with_parent(forked_by)
    else:
        die_with_parent(parent.pid)


def spawn_owned(command: list[str], log: IO[bytes]) -> subprocess.Popen[bytes]:
    """Start ``command`` in its own session, output to ``log``, told to die with this process."""
    env = {**os.environ, PARENT_ENV: str(os.getpid())}
    return subprocess.Popen(
        command, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env, start_new_session=True
    )


def stop_owned(process: subprocess.Popen[bytes] | BaseProcess, grace_s: float = STOP_GRACE_S) -> None:
    """SIGTERM the child's process group, wait ``grace_s``, then SIGKILL what is left of the group."""
    pid = process.pid
    if pid is None:
        return
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGTERM)
    if not _wait(process, grace_s):  # only a living leader: a reaped pid may belong to someone else by now
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(pid, signal.SIGKILL)
        _wait(process, grace_s)


def _wait(process: subprocess.Popen[bytes] | BaseProcess, timeout_s: float) -> bool:
    """True once the child has exited (and is reaped), False after ``timeout_s``."""
    if isinstance(process, subprocess.Popen):
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout_s)
        return process.poll() is not None
    process.join(timeout_s)  # multiprocessing.Process
    return not process.is_alive()


def cpu_seconds(pid: int) -> float | None:
    """CPU time (user + system, s) process ``pid`` has used so far (Linux /proc), None where unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime: fields 14, 15 of stat


def port_holder(port: int) -> str | None:
    """'pid N (command line)' of the process listening on TCP ``port`` (Linux /proc), else None."""
    inodes = _listening_inodes(port)
    if not inodes:
        return None
    for fd_dir in Path("/proc").glob("[0-9]*/fd"):
        with contextlib.suppress(OSError):
            for fd in fd_dir.iterdir():
                with contextlib.suppress(OSError):
                    if os.readlink(fd) in inodes:
                        pid = fd_dir.parent.name
                        cmd = (fd_dir.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode().strip()
                        return f"pid {pid} ({cmd[:200]})"
    return "a process this user cannot see"


def _listening_inodes(port: int) -> set[str]:
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with contextlib.suppress(OSError):
            for line in Path(table).read_text().splitlines()[1:]:
                fields = line.split()
                if int(fields[1].rsplit(":", 1)[1], 16) == port and fields[3] == "0A":  # 0A = LISTEN
                    found.add(f"socket:[{fields[9]}]")
    return found
