"""The 3D monitors of ``acs-twin serve`` as the API reaches them: what their simulated side flies.

The monitors (frontend.monitors.MonitorHandles) start on a satellite's live twin (backend.twin.demo_twin) and
register here with that nominal feed. A diagnosed hypothesis flown by backend.twin.diagnosis_flight is put on
them with its name on every viewer's panel (actual side: the telemetry of the flown window; simulated side: the
twin with the hypothesis); :meth:`MonitorDesk.show_nominal` puts the live twin back, in live follow.
Without running monitors a flight is still flown and kept (its residuals are the API's answer).
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from frontend.feed import NOMINAL_LABEL

if TYPE_CHECKING:
    from frontend.feed import TwinFeed
    from frontend.monitors import MonitorHandles

__all__ = ["MonitorDesk"]


class MonitorDesk:
    """The running monitors (if any), their nominal feed and the flight on their simulated side (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._handles: MonitorHandles | None = None
        self._nominal: TwinFeed | None = None
        self._satellite: str | None = None
        self._flight: dict[str, Any] | None = None

    def attach(self, handles: MonitorHandles, nominal: TwinFeed, satellite: str) -> None:
        """The monitors are up on ``satellite``'s live twin (``nominal``)."""
        with self._lock:
            self._handles, self._nominal, self._satellite = handles, nominal, satellite

    @property
    def running(self) -> bool:
        """True once monitors registered."""
        return self._handles is not None

    def show_flight(self, feed: TwinFeed, flight: dict[str, Any]) -> bool:
        """Keep ``flight`` (its ``label`` names it) and put its feed on the monitors; False when none run."""
        with self._lock:
            self._flight, handles = flight, self._handles
            if handles is None:
                return False
            handles.show_feed(feed, flight["label"], live=False)
            return True

    def show_nominal(self) -> bool:
        """The live twin back on the monitors, in live follow; whether a flight was shown."""
        with self._lock:
            flown, self._flight = self._flight is not None, None
            if self._handles is not None and self._nominal is not None:
                self._handles.show_feed(self._nominal, NOMINAL_LABEL, live=self._handles.live)
            return flown

    def state(self) -> dict[str, Any]:
        """What the simulated monitor shows: nominal or a hypothesis, its label, the flight, and the label each
        connected viewer's panel shows (what a browser on the monitors reads)."""
        with self._lock:
            handles, flight = self._handles, self._flight
            viewers = handles.all_viewers() if handles is not None else []
            return {
                "running": handles is not None,
                "satellite": self._satellite,
                "showing": "nominal" if flight is None else "hypothesis",
                "label": NOMINAL_LABEL if flight is None else flight["label"],
                "monitor_label": handles.label if handles is not None else None,
                "viewers": [
                    {"role": v.role, "client_id": v.client_id, "label": v.panels.simulated_label} for v in viewers
                ],
                "flight": flight,
            }
