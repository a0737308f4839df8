"""viser's message event set from another thread leaves the loop's waiters to the loop (frontend.viser_events)."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator

import pytest
from viser.infra._async_message_buffer import AsyncMessageBuffer

from frontend.viser_events import LoopSafeEvent, loop_safe_message_events

HANG_S = 30.0  # a waiter the loop never wakes fails the test after this (a hang bound, not a budget)


@pytest.fixture
def loop() -> Iterator[asyncio.AbstractEventLoop]:
    """An event loop running in a thread of its own, as viser's server runs its."""
    running = asyncio.new_event_loop()
    thread = threading.Thread(target=running.run_forever, daemon=True)
    thread.start()
    yield running
    running.call_soon_threadsafe(running.stop)
    thread.join(HANG_S)
    running.close()


def _waiting(loop: asyncio.AbstractEventLoop, event: asyncio.Event):
    """A task of ``loop`` waiting on ``event``, once its waiter is registered."""
    task = asyncio.run_coroutine_threadsafe(event.wait(), loop)
    _until_waited_on(loop, event)
    return task


def _until_waited_on(loop: asyncio.AbstractEventLoop, event: asyncio.Event) -> None:
    deadline = time.monotonic() + HANG_S
    while not asyncio.run_coroutine_threadsafe(_count(event), loop).result(HANG_S):
        assert time.monotonic() < deadline, "nothing ever waited on the event"
        time.sleep(0.01)


async def _count(event: asyncio.Event) -> int:
    return len(event._waiters)


def test_a_set_from_another_thread_only_raises_the_flag_and_the_loop_s_set_wakes_the_waiter(loop) -> None:
    event = asyncio.run_coroutine_threadsafe(_make(loop), loop).result(HANG_S)
    task = _waiting(loop, event)
    waiter = asyncio.run_coroutine_threadsafe(_first_waiter(event), loop).result(HANG_S)
    event.set()  # as AsyncMessageBuffer.push does from the queuing thread
    assert event.is_set() and not waiter.done()  # a plain asyncio.Event completes the loop's future from here
    loop.call_soon_threadsafe(event.set)  # the set push makes on the loop right after
    assert task.result(HANG_S) is True


async def _make(loop: asyncio.AbstractEventLoop) -> LoopSafeEvent:
    return LoopSafeEvent(loop)


async def _first_waiter(event: asyncio.Event) -> asyncio.Future:
    return event._waiters[0]


def test_the_buffers_viser_makes_afterwards_use_it_and_still_wake_their_consumer(loop) -> None:
    from viser._messages import ViewerCameraMessage

    loop_safe_message_events()
    loop_safe_message_events()  # idempotent: one wrapper
    buffer = AsyncMessageBuffer(loop, persistent_messages=False)
    assert type(buffer.message_event) is LoopSafeEvent

    async def first_window() -> int:
        async for window in buffer.window_generator(0):
            return len(window)
        return 0

    consumer = asyncio.run_coroutine_threadsafe(first_window(), loop)
    _until_waited_on(loop, buffer.message_event)  # the window loop waits for a message
    buffer.push(ViewerCameraMessage((1, 0, 0, 0), (0, 0, 1), 1.0, 0.01, 100.0, 10, 10, (0, 0, 0), (0, 0, 1)))
    assert consumer.result(HANG_S) == 1
    buffer.set_done()
