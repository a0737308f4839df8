"""The live stream in its own process: TCP listener → decode → archive (telemetry.live).

Ingest and the API never share a GIL, so neither slows the other; the ingest process forwards
each decoded batch (raw packets stripped) with its satellite (one listener serves the fleet: a connection
names its satellite, and for a mixed fleet the dictionary its packets decode with, by telemetry.live.hello; else
it is the server's live satellite and dictionary) and its tallies to the
API process through a bounded queue, never waiting: when the API side falls behind, the oldest waiting messages
are dropped and counted (their batches are archived regardless), so the server resumes at the present: the
outbox's part of the one fan-out policy for live samples, stated in :mod:`backend.ingest.telemetry_gateway`.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import os
import queue
import signal
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Literal, TypeAlias

if TYPE_CHECKING:
    from multiprocessing.queues import Queue
    from multiprocessing.synchronize import Event

    from telemetry.archive import Archive
    from telemetry.ingest_report import SampleBatch

    Tallies: TypeAlias = dict[str, int | float | str]  # telemetry.live.LiveStats' fields and forward_dropped
    OutboxMessage: TypeAlias = (  # to the server: its start-up steps, ("port", n) or ("error", why), then the rest
        tuple[Literal["starting"], str]  # names each start-up step as it begins
        | tuple[Literal["port"], int]
        | tuple[Literal["error"], str]
        | tuple[Literal["batch"], tuple[str, SampleBatch]]  # (satellite, its decoded batch: raw packets stripped)
        | tuple[Literal["stats"], Tallies]
        | tuple[Literal["stopped"], None]  # the last message: the server's relay ends on it
    )
    Outbox: TypeAlias = Queue[OutboxMessage]

__all__ = ["OUTBOX_MESSAGES", "STATS_PERIOD_S", "run_ingest_process"]

STATS_PERIOD_S = 0.5
PASS_PERIOD_S = 60.0  # a satellite's pass from data is widened over what was committed at most this often (in
# telemetry time; a few queries each, serialised with the commits in this process, never on the API's relay)
OUTBOX_MESSAGES = 1_000  # ≈ 20 s of batches at the 50 decodes/s of telemetry.live
STOP_POLL_S = 0.1
EVICT_WAIT_S = 0.5  # a full outbox's oldest message may still be in this process's feeder thread, not yet in the
# pipe: an eviction waits this long at most for it (it is there within milliseconds; the full wait happens only if
# the server emptied the outbox in between, and then the put that follows succeeds)
ORPHAN_EXIT_S = 20.0  # after SIGTERM the pending batches are archived within this, else the process exits anyway


def run_ingest_process(
    database_url: str,
    dictionaries_dir: str,
    dictionary: str,
    satellite: str,
    host: str,
    port: int,
    outbox: Outbox,
    stop: Event,
    sources: tuple[str, ...],
    go: Event,
) -> None:
    """Process entry: serve the live stream (packets only from ``sources``, CIDR) until ``stop`` is set or the
    server dies; ("starting", step) as each start-up step begins, then ("port", n) or ("error", why).

    What needs neither the archive nor the port (imports, the dictionary, the decoder's kernels) is done at once;
    the archive is opened and the port bound only once ``go`` is set (the server has migrated the archive), so
    ``acs-twin serve`` spawns this process first and its start-up runs beside the server's own."""
    from backend.core.processes import become_owned_child

    outbox.put(("starting", "process entry"))
    become_owned_child()  # SIGTERM when the server dies, even by kill -9: stop as if told to
    signal.signal(signal.SIGTERM, _OrphanStop(outbox, stop))
    asyncio.run(
        _serve(database_url, Path(dictionaries_dir), dictionary, satellite, host, port, outbox, stop, sources, go)
    )
    _exit_at_once(outbox)


def _exit_at_once(outbox: Outbox) -> None:
    """Exit once the outbox is in the pipe, without the interpreter's teardown: with numba, SQLAlchemy and numpy
    loaded it took 1-3 s of CPU after the last message (load 6-8), and the server's stop waited for it. Nothing of
    ours is left to it: the archive is closed and the stream stopped (``_serve``); an orphan's outbox is not waited
    for (``_OrphanStop``)."""
    outbox.close()
    outbox.join_thread()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


class _OrphanStop:
    """SIGTERM handler: archive what is pending, never wait for the server to read the outbox, exit within a bound.

    A dead server sends SIGTERM twice (PR_SET_PDEATHSIG and the parent watch): the second may interrupt the first
    handler while it holds the stop event's lock, so only the first one acts (a re-entered ``stop.set()`` waited
    on that lock for ever, the exit timer not yet started: the port stayed held after a kill -9 of the server).
    """

    def __init__(self, outbox: Outbox, stop: Event) -> None:
        self._outbox, self._stop, self._called = outbox, stop, False

    def __call__(self, *_: object) -> None:
        if self._called:
            return
        self._called = True
        exit_timer = threading.Timer(ORPHAN_EXIT_S, os._exit, args=(1,))
        exit_timer.daemon = True  # a bound, not a wait: an orderly stop that ends sooner exits at once
        exit_timer.start()
        self._outbox.cancel_join_thread()
        self._stop.set()


class LivePasses:
    """After each group commit of the live stream: every satellite's pass from data over what it committed since its
    last update (telemetry.passes.passes_from_data; predicted passes covering the data are recounted instead), at
    most every PASS_PERIOD_S of telemetry per satellite, and at stop for all: the pass list is never empty after data
    arrived."""

    def __init__(self) -> None:
        self._from: dict[str, int] = {}  # satellite -> first sample not yet counted in a pass
        self._newest: dict[str, int] = {}  # satellite -> newest committed sample

    def __call__(self, archive: Archive, spans: list[tuple[str, int, int]], final: bool) -> None:
        due = set()
        for satellite, t0_ns, t1_ns in spans:
            if satellite not in self._from:
                due.add(satellite)  # its first commit: the pass shows at once
            start = self._from.setdefault(satellite, t0_ns)
            self._newest[satellite] = max(self._newest.get(satellite, t1_ns), t1_ns)
            if t1_ns - start >= PASS_PERIOD_S * 1e9:
                due.add(satellite)
        if final:  # stopping: every satellite's pass reaches its newest committed sample
            due |= {s for s, t in self._newest.items() if t > self._from[s]}
        for satellite in sorted(due):
            self._update(archive, satellite)

    def _update(self, archive: Archive, satellite: str) -> None:
        from telemetry import passes

        passes.passes_from_data(archive, satellite, self._from[satellite], self._newest[satellite])
        self._from[satellite] = self._newest[satellite]


def _offer(outbox: Outbox, message: OutboxMessage, tally: dict[str, int]) -> None:
    """Put ``message`` without waiting on the server; newest wins: a full outbox loses its oldest message (counted
    in ``forward_dropped``). Only this process puts, so once one message is taken out there is room."""
    try:
        outbox.put_nowait(message)
        return
    except queue.Full:
        pass
    with contextlib.suppress(queue.Empty):  # empty: the server took everything meanwhile, room all the same
        outbox.get(timeout=EVICT_WAIT_S)
        tally["forward_dropped"] += 1
    try:
        outbox.put_nowait(message)
    except queue.Full:  # the server holds the read lock on a queue it has not emptied yet: the newcomer goes
        tally["forward_dropped"] += 1


async def _serve(
    database_url: str,
    dictionaries_dir: Path,
    dictionary_name: str,
    satellite: str,
    host: str,
    port: int,
    outbox: Outbox,
    stop: Event,
    sources: tuple[str, ...],
    go: Event,
) -> None:
    outbox.put(("starting", "imports of the live stream"))
    from backend.ingest.dictionary_catalogue import DictionaryCatalogue
    from telemetry.archive import Archive
    from telemetry.limits import dictionary_limits
    from telemetry.live import LiveStream, warm_decoder

    outbox.put(("starting", f"loading the dictionary {dictionary_name}"))
    catalogue = DictionaryCatalogue(dictionaries_dir)
    dictionary = catalogue.load(dictionary_name)
    outbox.put(("starting", "warming the decoder"))
    warm_decoder(dictionary)  # LiveStream.start warms it again: by then a few packets' decode, milliseconds
    outbox.put(("starting", "waiting for the server's archive"))
    while not go.wait(STOP_POLL_S):
        if stop.is_set():  # the server stopped before its start-up reached the live link
            return
    outbox.put(("starting", "opening the archive"))
    archive = Archive(database_url, migrate=False)
    outbox.put(("starting", f"listening on {host}:{port}"))
    stream = LiveStream(
        dictionary,
        archive=archive,
        satellite=satellite,
        limits=dictionary_limits(dictionary),
        allowed_sources=sources,
        on_committed=LivePasses(),
        dictionaries=catalogue.load_known,
    )
    try:
        outbox.put(("port", await stream.start(host, port)))
    except OSError as exc:  # the port is taken: say by whom instead of leaving the server waiting
        from backend.core.processes import port_holder

        holder = port_holder(port) or "another process"
        outbox.put(("error", f"telemetry port {host}:{port}: {exc.strerror or exc}; held by {holder}"))
        archive.close()
        return
    subscriber = stream.subscribe(max_messages=OUTBOX_MESSAGES)
    tally = {"forward_dropped": 0}

    async def forward() -> None:
        while True:
            message = await subscriber.get()
            batch = dataclasses.replace(message.batch, packets=None)
            _offer(outbox, ("batch", (message.satellite, batch)), tally)

    async def report() -> None:
        while True:
            await asyncio.sleep(STATS_PERIOD_S)
            _offer(outbox, ("stats", {**dataclasses.asdict(stream.stats), **tally}), tally)

    tasks = [asyncio.create_task(forward()), asyncio.create_task(report())]
    try:
        while not stop.is_set():
            await asyncio.sleep(STOP_POLL_S)
    finally:
        await stream.stop()
        for task in tasks:
            task.cancel()
        outbox.put(("stats", {**dataclasses.asdict(stream.stats), **tally}))
        archive.close()
        outbox.put(("stopped", None))
