"""Fan-out of live items (parameter samples, alarms, twin state) to WebSocket subscribers.

Publishing never waits: each subscriber owns a bounded deque; when a slow client's deque is full
the oldest items are dropped (thinning) and counted; the WebSocket sender drains it in batches at
most ``rate_hz`` times per second and drops a client whose send stalls. Publish is safe from any
thread (deque.append is atomic; the subscriber list is replaced, never mutated in place). This is the
hub's part of the one fan-out policy for live samples, stated in :mod:`backend.ingest.telemetry_gateway`.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Protocol, TypedDict

__all__ = ["Delivery", "LiveHub", "LiveItem", "Publisher", "Subscription", "TOPIC_PREFIXES"]

TOPIC_PREFIXES = ("parameters/", "alarms", "twin", "archive")
LiveItem = dict[str, Any]  # what a topic carries: a JSON object (parameter samples, alarms, a twin's state)


class Delivery(TypedDict):
    """One pending item of a subscription, as the WebSocket sends it."""

    topic: str
    data: LiveItem


def _check_topic(topic: str) -> str:
    if not (topic in ("alarms", "twin", "archive") or (topic.startswith("parameters/") and len(topic) > 11)):
        raise ValueError(f"topics: {topic!r} is not 'parameters/<name>', 'parameters/*', 'alarms', 'twin' or 'archive'")
    return topic


@dataclass(eq=False)
class Subscription:
    """One client's topics and pending items."""

    capacity: int
    topics: set[str] = field(default_factory=set)
    pending: deque[Delivery] = field(init=False)
    dropped: int = 0

    def __post_init__(self) -> None:
        self.pending = deque(maxlen=self.capacity)

    def wants(self, topic: str) -> bool:
        """True if ``topic`` matches one of the subscribed topics (``parameters/*`` = all)."""
        return topic in self.topics or (topic.startswith("parameters/") and "parameters/*" in self.topics)

    def offer(self, topic: str, data: LiveItem) -> None:
        """Queue one item without waiting; the oldest is dropped when full."""
        if len(self.pending) == self.capacity:
            self.dropped += 1
        self.pending.append({"topic": topic, "data": data})

    def drain(self) -> list[Delivery]:
        """Take every pending item (for one batch)."""
        items = []
        for _ in range(len(self.pending)):
            items.append(self.pending.popleft())
        return items


class Publisher(Protocol):
    """What a producer of live items needs of the hub (:class:`LiveHub` is one)."""

    def publish(self, topic: str, data: LiveItem) -> None: ...

    def wants_any(self, topic: str) -> bool: ...


class LiveHub:
    """Topic-based, non-blocking fan-out to subscriptions."""

    def __init__(self, capacity: int) -> None:
        self._capacity = capacity
        self._subscriptions: tuple[Subscription, ...] = ()
        self._lock = threading.Lock()
        self.published = 0

    def subscribe(self, topics: list[str] | None = None) -> Subscription:
        """Register a subscription (topics validated; ValueError names the field ``topics``)."""
        sub = Subscription(self._capacity, {_check_topic(t) for t in topics or []})
        with self._lock:
            self._subscriptions = self._subscriptions + (sub,)
        return sub

    def update(self, sub: Subscription, add: list[str], remove: list[str]) -> None:
        """Change a subscription's topics."""
        sub.topics = (sub.topics | {_check_topic(t) for t in add}) - set(remove)

    def unsubscribe(self, sub: Subscription) -> None:
        """Forget a subscription."""
        with self._lock:
            self._subscriptions = tuple(s for s in self._subscriptions if s is not sub)

    def publish(self, topic: str, data: LiveItem) -> None:
        """Offer an item to every matching subscription; never blocks."""
        self.published += 1
        for sub in self._subscriptions:
            if sub.wants(topic):
                sub.offer(topic, data)

    def wants_any(self, topic: str) -> bool:
        """True if some subscription matches ``topic`` (lets publishers skip building items)."""
        return any(sub.wants(topic) for sub in self._subscriptions)

    @property
    def subscriber_count(self) -> int:
        """Number of connected subscriptions."""
        return len(self._subscriptions)
