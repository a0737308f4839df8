"""viser's message event, safe to set from any thread (viser 1.1.1: ``viser.infra._async_message_buffer``).

``AsyncMessageBuffer.push`` sets its ``asyncio.Event`` from the thread that queues the message (our render thread,
viser's callback pool, a connect callback) and then again on the server's event loop (``call_soon_threadsafe``).
``asyncio.Event`` is not thread-safe: ``set`` walks the loop's waiters and completes their futures, and when the loop
thread meanwhile resumes a waiter (``Event.wait`` removes it from that deque) the queuing thread fails with
"RuntimeError: deque mutated during iteration". Seen once in the suite at load 17: a connecting browser's scene was
never built (``set_up_direction`` in ``TwinScene._build``, on the connect thread) and
test_browser::test_each_monitor_paints_a_globe timed out waiting for the panel.

:class:`LoopSafeEvent` only raises the flag when set off its loop; the set that viser makes on the loop right after
(or in ``atomic_end``) wakes the waiters, as before. :func:`loop_safe_message_events` gives every buffer viser makes
from then on such an event (serve_monitors calls it before it starts its servers).
"""

from __future__ import annotations

import asyncio
import functools
from typing import Any

__all__ = ["LoopSafeEvent", "loop_safe_message_events"]


class LoopSafeEvent(asyncio.Event):
    """An ``asyncio.Event`` of ``loop`` whose ``set`` from another thread leaves the loop's waiters to the loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._owner = loop

    def set(self) -> None:
        """Raise the flag; on the owning loop also wake every waiter (whether or not the flag was up already)."""
        try:
            on_loop = asyncio.get_running_loop() is self._owner
        except RuntimeError:  # no loop runs in this thread
            on_loop = False
        self._value = True
        if on_loop:
            for waiter in self._waiters:
                if not waiter.done():
                    waiter.set_result(True)


def loop_safe_message_events() -> None:
    """Every ``AsyncMessageBuffer`` made from now on gets a :class:`LoopSafeEvent` (idempotent)."""
    from viser.infra._async_message_buffer import AsyncMessageBuffer

    made = AsyncMessageBuffer.__init__
    if getattr(made, "loop_safe", False):
        return

    @functools.wraps(made)
    def __init__(self: AsyncMessageBuffer, *args: Any, **kwargs: Any) -> None:
        made(self, *args, **kwargs)
        self.message_event = LoopSafeEvent(self.event_loop)

    __init__.loop_safe = True  # type: ignore[attr-defined]
    AsyncMessageBuffer.__init__ = __init__  # type: ignore[method-assign]
