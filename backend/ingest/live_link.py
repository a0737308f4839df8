"""The live link as the server sees it: the live-ingest child process (backend.ingest.live_ingest), its outbox
and the thread relaying what it forwards.

The child listens for packets, decodes and archives them (telemetry.live) and forwards each decoded batch (raw
packets stripped) with its satellite, and its tallies; :class:`LiveLink` starts it, waits for its port, hands
every (satellite, batch) to ``on_batch`` in arrival order from its relay thread, keeps the newest tallies, and
stops it (the child archives what is pending first). The outbox's drop rule is the one fan-out policy stated in
:mod:`backend.ingest.telemetry_gateway`.
"""

from __future__ import annotations

import asyncio
import multiprocessing as mp
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.process import BaseProcess
from multiprocessing.queues import Queue
from multiprocessing.synchronize import Event
from typing import TYPE_CHECKING

from backend.core.settings import Settings
from telemetry.ingest_report import SampleBatch

if TYPE_CHECKING:
    from backend.ingest.live_ingest import OutboxMessage, Tallies

__all__ = ["LIVE_START_STALL_S", "LIVE_STOP_TIMEOUT_S", "LiveChild", "LiveLink", "abandon_ingest", "spawn_ingest"]

LIVE_START_STALL_S = 60.0  # the ingest process's start-up fails only after this long without progress (neither a
# step reported nor CPU time used): on a loaded machine its spawn and imports may take minutes, never silently
LIVE_STOP_TIMEOUT_S = 30.0  # the ingest process archives its pending batches before it exits
RELAY_POLL_S = 0.2


@dataclass(frozen=True)
class LiveChild:
    """The live-ingest process, its outbox to this server, its stop event and its go event (set: open the archive
    and listen)."""

    process: BaseProcess
    outbox: Queue[OutboxMessage]
    stop: Event
    go: Event | None = None


def spawn_ingest(settings: Settings) -> LiveChild:
    """Start the live-ingest process of ``settings``: its spawn, imports, dictionary and decoder warm-up run now,
    beside the server's start-up; it opens the archive and listens once :meth:`LiveLink.start` sets its go event.
    ``acs-twin serve`` calls this before its own imports (end it with :func:`abandon_ingest` if no link takes it)."""
    from backend.ingest.live_ingest import OUTBOX_MESSAGES, run_ingest_process

    ctx = mp.get_context("spawn")
    outbox: Queue[OutboxMessage] = ctx.Queue(OUTBOX_MESSAGES)
    stop, go = ctx.Event(), ctx.Event()
    args = (
        settings.resolved_database_url(),
        str(settings.data_dir / "dictionaries"),
        settings.live_dictionary,
        settings.live_satellite,
        settings.host,
        settings.telemetry_port,
        outbox,
        stop,
        tuple(settings.telemetry_sources),
        go,
    )
    process = ctx.Process(target=run_ingest_process, args=args, name="acs-twin-live-ingest", daemon=True)
    process.start()
    return LiveChild(process, outbox, stop, go)


def abandon_ingest(child: LiveChild) -> None:
    """Stop a spawned ingest process (one no link started exits before opening the archive; a stopped one is
    already gone)."""
    child.stop.set()
    child.process.join(LIVE_STOP_TIMEOUT_S)
    if child.process.is_alive():
        child.process.terminate()
        child.process.join()


def _first_live_message(live: LiveChild) -> OutboxMessage:
    """("port", n) from the ingest process, or ("error", why) if it failed, died or made no progress (neither a
    start-up step reported nor CPU time used) for LIVE_START_STALL_S; the error names the step it was in."""
    from backend.core.processes import cpu_seconds

    started = progressed = time.monotonic()
    step, cpu = "spawn and imports", cpu_seconds(live.process.pid or 0)
    while time.monotonic() - progressed < LIVE_START_STALL_S:
        try:
            message = live.outbox.get(timeout=RELAY_POLL_S)
        except queue.Empty:
            if not live.process.is_alive():
                return "error", f"the ingest process exited with code {live.process.exitcode} (see its output above)"
            now_cpu = cpu_seconds(live.process.pid or 0)
            if now_cpu is not None and now_cpu != cpu:
                cpu, progressed = now_cpu, time.monotonic()
            continue
        if message[0] != "starting":
            return message
        step, progressed = message[1], time.monotonic()
    return "error", (
        f"the ingest process made no progress for {LIVE_START_STALL_S:.0f} s at its step '{step}' "
        f"({time.monotonic() - started:.0f} s after it was started)"
    )


class LiveLink:
    """The live-ingest process of ``settings`` (its satellite, dictionary, host, port, allowed sources) and the relay
    of its batches to ``on_batch``."""

    def __init__(
        self, settings: Settings, on_batch: Callable[[str, SampleBatch], None], spawned: LiveChild | None = None
    ) -> None:
        self._settings, self._on_batch, self._spawned = settings, on_batch, spawned
        self._child: LiveChild | None = None
        self._relay: threading.Thread | None = None
        self._stats: Tallies = {}
        self.port: int | None = None

    async def start(self) -> int:
        """Spawn the ingest process (or take the one spawned ahead), let it open the archive and listen, wait for its
        port and start the relay; RuntimeError naming why it did not."""
        child = self._child = self._spawned or spawn_ingest(self._settings)
        self._spawned = None
        process, stop = child.process, child.stop
        assert child.go is not None
        child.go.set()
        match await asyncio.to_thread(_first_live_message, child):
            case ("port", port):
                self.port = port
            case (_, detail):
                stop.set()
                await asyncio.to_thread(process.join, LIVE_STOP_TIMEOUT_S)
                self._child = None
                raise RuntimeError(f"live ingest did not start: {detail}")
        self._relay = threading.Thread(target=self._relay_loop, args=(child,), name="live-relay", daemon=True)
        self._relay.start()
        return port

    def _relay_loop(self, child: LiveChild) -> None:
        """Hand on the child's batches and tallies until its last message (or, if it died without one, until it is
        gone and the outbox empty)."""
        while True:
            try:
                message = child.outbox.get(timeout=RELAY_POLL_S)
            except queue.Empty:
                if child.stop.is_set() and not child.process.is_alive():
                    return
                continue
            match message:
                case ("stats", tallies):
                    self._stats = tallies
                case ("batch", (satellite, batch)):
                    self._on_batch(satellite, batch)
                case ("stopped", _):
                    return

    async def stop(self) -> None:
        """Stop the ingest process (it archives what is pending first) and the relay thread."""
        if self._child is None:
            return
        process = self._child.process
        self._child.stop.set()
        await asyncio.to_thread(process.join, LIVE_STOP_TIMEOUT_S)
        if process.is_alive():
            process.terminate()
        if self._relay is not None:
            await asyncio.to_thread(self._relay.join, LIVE_STOP_TIMEOUT_S)
        self._child = None

    def stats(self) -> dict[str, int | float | str | None]:
        """Tallies of the live stream (packets received/archived, errors, forward_dropped), empty once stopped."""
        return {} if self._child is None else {"port": self.port, **self._stats}
