"""Caches of what is read from the archive: JSON sample answers per window, decoded series per parameter, and
results computed from a window (a twin session's residuals).

All are dropped when ingested data overlaps them (an upload's or a live batch's time span), and a
computation that started before such an ingest is not stored (per-satellite generation counter).
Live data younger than HOT_S may not be archived yet (the live stream commits every 0.5 s), so
answers reaching into it are never stored and the satellite's series are read per window.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict, deque

import numpy as np

__all__ = ["SampleCache", "ANSWER_ENTRIES", "SERIES_BYTES", "COMPUTED_ENTRIES", "HOT_S"]

ANSWER_ENTRIES = 4096  # distinct (parameter, window, max_points) answers kept between ingests
SERIES_BYTES = 256_000_000  # decoded (t, value) arrays kept in memory, least recently used first out
COMPUTED_ENTRIES = 32  # results computed from archive windows (a session's residuals: a few MB at most)
INGEST_LOG = 4096  # recent ingest spans remembered: a result computed meanwhile is kept if none overlaps it
HOT_S = 5.0  # live data younger than this may still wait for the archive flush (every 0.5 s)

AnswerKey = tuple[str, str, int, int, int]
ComputedKey = tuple[str, str, int, int]  # satellite, what was computed, t0_ns, t1_ns of the archive window read


class SampleCache:
    """Thread-safe answer and series caches with overlap invalidation."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._answers: OrderedDict[AnswerKey, bytes] = OrderedDict()
        self._series: OrderedDict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = OrderedDict()
        self._series_bytes = 0
        self._computed: OrderedDict[ComputedKey, object] = OrderedDict()
        self._ingested: deque[tuple[str, int, int, int]] = deque(maxlen=INGEST_LOG)  # satellite, generation, t0, t1
        self._generation: dict[str, int] = {}
        self._hot: deque[tuple[float, str, int]] = deque()

    def generation(self, satellite: str) -> int:
        """Counter bumped by every ingest of the satellite (take it before reading the archive)."""
        with self._lock:
            return self._generation.get(satellite, 0)

    def invalidate(self, satellite: str, t0_ns: int, t1_ns: int) -> None:
        """New data of ``satellite`` in [t0_ns, t1_ns]: drop overlapping answers and its series."""
        with self._lock:
            self._generation[satellite] = self._generation.get(satellite, 0) + 1
            self._ingested.append((satellite, self._generation[satellite], t0_ns, t1_ns))
            for key in [k for k in self._answers if k[0] == satellite and k[2] <= t1_ns and k[3] >= t0_ns]:
                del self._answers[key]
            for done in [k for k in self._computed if k[0] == satellite and k[2] <= t1_ns and k[3] >= t0_ns]:
                del self._computed[done]
            for series_key in [k for k in self._series if k[0] == satellite]:
                self._series_bytes -= sum(a.nbytes for a in self._series.pop(series_key))

    def mark_live(self, satellite: str, t_min_ns: int) -> None:
        """Live data from t_min_ns on has just arrived (maybe not archived for a while)."""
        self._hot.append((time.monotonic(), satellite, t_min_ns))

    def hot_start_ns(self, satellite: str) -> int | None:
        """Earliest time of live data of ``satellite`` received within HOT_S, else None."""
        while self._hot and time.monotonic() - self._hot[0][0] > HOT_S:
            self._hot.popleft()
        starts = [t for _, sat, t in list(self._hot) if sat == satellite]
        return min(starts) if starts else None

    def answer(self, key: AnswerKey) -> bytes | None:
        """A stored answer (marks it recently used)."""
        with self._lock:
            hit = self._answers.get(key)
            if hit is not None:
                self._answers.move_to_end(key)
            return hit

    def store_answer(self, key: AnswerKey, generation: int, body: bytes) -> None:
        """Keep an answer unless an ingest happened meanwhile or its window reaches hot live data."""
        hot = self.hot_start_ns(key[0])
        with self._lock:
            if self._generation.get(key[0], 0) != generation or (hot is not None and key[3] >= hot):
                return
            self._answers[key] = body
            if len(self._answers) > ANSWER_ENTRIES:
                self._answers.popitem(last=False)

    def computed(self, key: ComputedKey) -> object | None:
        """A stored result computed from an archive window (marks it recently used)."""
        with self._lock:
            hit = self._computed.get(key)
            if hit is not None:
                self._computed.move_to_end(key)
            return hit

    def store_computed(self, key: ComputedKey, generation: int, value: object) -> None:
        """Keep a computed result unless an ingest since ``generation`` overlapped its window (a live stream
        elsewhere in time does not count) or the window reaches hot live data."""
        hot = self.hot_start_ns(key[0])
        with self._lock:
            if not self._untouched(key[0], generation, key[2], key[3]) or (hot is not None and key[3] >= hot):
                return
            self._computed[key] = value
            if len(self._computed) > COMPUTED_ENTRIES:
                self._computed.popitem(last=False)

    def _untouched(self, satellite: str, generation: int, t0_ns: int, t1_ns: int) -> bool:
        """No ingest of ``satellite`` since ``generation`` overlapped [t0_ns, t1_ns] (False if the log cannot tell)."""
        since = self._generation.get(satellite, 0) - generation
        spans = [(a, b) for s, g, a, b in self._ingested if s == satellite and g > generation]
        return len(spans) == since and not any(a <= t1_ns and b >= t0_ns for a, b in spans)

    def series(self, satellite: str, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The whole decoded series of a parameter if stored."""
        with self._lock:
            found = self._series.get((satellite, name))
            if found is not None:
                self._series.move_to_end((satellite, name))
            return found

    def store_series(self, satellite: str, name: str, generation: int, t: np.ndarray, v: np.ndarray) -> None:
        """Keep a whole series (if no ingest happened meanwhile), evicting least recently used ones."""
        size = t.nbytes + v.nbytes
        if size > SERIES_BYTES // 4:
            return
        with self._lock:
            if self._generation.get(satellite, 0) != generation or (satellite, name) in self._series:
                return
            self._series[(satellite, name)] = (t, v)
            self._series_bytes += size
            while self._series_bytes > SERIES_BYTES:
                self._series_bytes -= sum(a.nbytes for a in self._series.popitem(last=False)[1])
