"""The ingest process's outbox to the server (newest wins when the server falls behind, losses counted), its
SIGTERM handler and the server's wait for its start-up."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import threading
import time

from backend.ingest import live_ingest, live_link
from backend.ingest.live_ingest import _offer

OUTBOX_MESSAGES = 3
GET_TIMEOUT_S = 10.0  # the queue's feeder thread writes to its pipe within milliseconds; margin for a loaded machine
STALL_S = 2.0  # the start-up wait's limit without progress in these tests (a step or CPU time), instead of 60 s
STALLED_CHILD_S = 60.0  # a stalled child sleeps this long (it is terminated once the wait has given up)
REENTRY_WAIT_S = 2.0  # a re-entered stop.set() waits this long on its own lock before the test calls it a deadlock


def test_a_full_outbox_loses_its_oldest_messages_and_counts_them() -> None:
    outbox = mp.get_context("spawn").Queue(OUTBOX_MESSAGES)
    tally = {"forward_dropped": 0}
    for i in range(10):  # the server reads nothing meanwhile
        _offer(outbox, ("starting", str(i)), tally)
    received = [outbox.get(timeout=GET_TIMEOUT_S)[1] for _ in range(OUTBOX_MESSAGES)]
    assert received == ["7", "8", "9"]  # the server resumes at the present, in order
    assert tally["forward_dropped"] == 10 - OUTBOX_MESSAGES
    outbox.close()


class _SecondSigtermInsideSet:
    """A stop event like multiprocessing's (set() holds a non-reentrant lock) during whose first set() a second
    SIGTERM arrives, as when the server was killed -9 (parent-death signal and parent watch both fire). A set()
    re-entered from the handler finds the lock held: with the real event it waits for ever; here it fails."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.sets = 0

    def set(self) -> None:
        if not self._lock.acquire(timeout=REENTRY_WAIT_S):
            raise AssertionError("stop.set() re-entered from the second SIGTERM waited on its own lock (deadlock)")
        try:
            self.sets += 1
            if self.sets == 1:
                signal.raise_signal(signal.SIGTERM)  # its handler runs here, the lock held
        finally:
            self._lock.release()


def test_a_second_sigterm_during_the_first_neither_deadlocks_nor_acts_twice(monkeypatch) -> None:
    timers: list[tuple[float, object, bool]] = []

    class RecordedTimer:  # the real one would os._exit the test process ORPHAN_EXIT_S later
        def __init__(self, interval: float, function: object, args: tuple[int]) -> None:
            self.interval, self.function, self.daemon = interval, function, False

        def start(self) -> None:
            timers.append((self.interval, self.function, self.daemon))

    monkeypatch.setattr(live_ingest.threading, "Timer", RecordedTimer)
    outbox = mp.get_context("spawn").Queue(OUTBOX_MESSAGES)
    stop = _SecondSigtermInsideSet()
    previous = signal.signal(signal.SIGTERM, live_ingest._OrphanStop(outbox, stop))  # type: ignore[arg-type]
    try:
        signal.raise_signal(signal.SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert stop.sets == 1  # the second signal did nothing: the first one's set() completed
    # one bounded exit, armed; a daemon thread, so an orderly stop that ends sooner is not held for the bound
    assert timers == [(live_ingest.ORPHAN_EXIT_S, os._exit, True)]
    outbox.close()


def _starts_slowly(outbox: mp.queues.Queue, busy_s: float, stalls: bool) -> None:
    """An ingest process's start-up as the server sees it: a step reported, then ``busy_s`` of CPU work with no
    message (imports on a loaded machine), then its port, or silence without CPU use (a stalled step)."""
    outbox.put(("starting", "process entry"))
    end = time.monotonic() + busy_s
    while time.monotonic() < end:
        pass
    if stalls:
        outbox.put(("starting", "opening the archive"))
        time.sleep(STALLED_CHILD_S)
    outbox.put(("port", 4242))


def _first_message_of_child(busy_s: float, stalls: bool) -> tuple[str, object]:
    ctx = mp.get_context("spawn")
    outbox, stop = ctx.Queue(OUTBOX_MESSAGES), ctx.Event()
    process = ctx.Process(target=_starts_slowly, args=(outbox, busy_s, stalls), daemon=True)
    process.start()
    try:
        return live_link._first_live_message(live_link.LiveChild(process, outbox, stop))
    finally:
        process.terminate()
        process.join()


def test_a_slow_live_ingest_start_up_is_waited_for_while_it_progresses(monkeypatch) -> None:
    monkeypatch.setattr(live_link, "LIVE_START_STALL_S", STALL_S)
    assert _first_message_of_child(busy_s=3 * STALL_S, stalls=False) == ("port", 4242)


def test_a_stalled_live_ingest_start_up_fails_naming_its_step(monkeypatch) -> None:
    monkeypatch.setattr(live_link, "LIVE_START_STALL_S", STALL_S)
    kind, why = _first_message_of_child(busy_s=0.0, stalls=True)
    assert kind == "error"
    assert f"no progress for {STALL_S:.0f} s at its step 'opening the archive'" in str(why)
