"""A viewer's playback clock (shared by the viewers linked together: frontend.viewer.ViewerLink).

Modes: *live follow* (the displayed time is the newest data), *replay* (play/pause at ×1 … ×1000 of
real time through a stored pass), and seeking with the timeline. Thread-safe: the GUI callbacks of
three viser servers and the render loop all touch it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["PlaybackClock", "SPEEDS"]

SPEEDS = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0)


class PlaybackClock:
    """Displayed time (UTC s since the Unix epoch) advanced by wall time × speed inside the data span."""

    def __init__(self, span: Callable[[], tuple[float, float]], speed: float = 10.0) -> None:
        self._span = span
        self._lock = threading.Lock()
        t0, _ = span()
        self._t = float(t0)
        self._speed = self._checked_speed(speed)
        self._playing = False
        self._live = False

    @staticmethod
    def _checked_speed(speed: float) -> float:
        if not SPEEDS[0] <= float(speed) <= SPEEDS[-1]:
            raise ValueError(f"speed: must lie in [{SPEEDS[0]:g}, {SPEEDS[-1]:g}], got {speed}")
        return float(speed)

    @property
    def t_unix_s(self) -> float:
        """The displayed instant."""
        with self._lock:
            return self._t

    @property
    def speed(self) -> float:
        """Replay speed, multiples of real time."""
        return self._speed

    @property
    def playing(self) -> bool:
        """True while replay advances."""
        return self._playing

    @property
    def live(self) -> bool:
        """True while following the newest data."""
        return self._live

    def span_unix_s(self) -> tuple[float, float]:
        """The data span the clock moves in."""
        return self._span()

    def set_span(self, span: Callable[[], tuple[float, float]]) -> None:
        """Move in another data span (a new feed): paused at its start."""
        t0, _ = span()
        with self._lock:
            self._span, self._t, self._playing, self._live = span, float(t0), False, False

    def advance(self, wall_dt_s: float) -> float:
        """Move by wall_dt × speed (replay) or to the newest data (live); stop at the end; returns t."""
        t0, t1 = self._span()
        with self._lock:
            if self._live:
                self._t = t1
            elif self._playing:
                self._t = min(self._t + wall_dt_s * self._speed, t1)
                self._playing = self._t < t1
            self._t = min(max(self._t, t0), t1)
            return self._t

    def seek(self, t_unix_s: float) -> None:
        """Jump to an instant (clamped into the span); leaves live follow."""
        t0, t1 = self._span()
        with self._lock:
            self._live = False
            self._t = min(max(float(t_unix_s), t0), t1)

    def set_speed(self, speed: float) -> None:
        """Replay speed ×1 … ×1000."""
        self._speed = self._checked_speed(speed)

    def play(self) -> None:
        """Start replay (from the start if at the end)."""
        t0, t1 = self._span()
        with self._lock:
            if self._t >= t1:
                self._t = t0
            self._live, self._playing = False, True

    def pause(self) -> None:
        """Stop replay."""
        self._playing = False

    def copy(self) -> PlaybackClock:
        """A clock of its own in the same span, at the same instant, speed and mode."""
        twin = PlaybackClock(self._span, self._speed)
        with self._lock:
            twin._t, twin._playing, twin._live = self._t, self._playing, self._live
        return twin

    def follow_live(self, on: bool = True) -> None:
        """Follow the newest data (on) or stay where we are (off)."""
        with self._lock:
            self._live = bool(on)
            self._playing = False
