"""The 3D monitors' feed of one satellite's live twin: frontend.feed.TwinFeed over backend.twin.live.LiveTwins.

Actual side: the mapped attitude (telemetry.attitude_mapping) and the GPS orbit of the last RECENT_S; simulated
side: the twin's attitude at the telemetry instants it was compared at (the actual one for a satellite without
ACS model, which the alarm panel says). The span grows as telemetry arrives, so the monitors' live follow stays a
few seconds behind real time; the panel's alarm list starts with a STALE warning once no telemetry came for
STALE_S. A snapshot of the twin's buffers is taken at most every SNAPSHOT_S (the render loop asks 30 times a s).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from frontend.feed import DEFAULT_STATIONS, FeedWindow, GroundStation, attitude_error_rad
from sim_core import quaternion
from telemetry.actual_state import ActualTrack

__all__ = ["LiveFeed"]

NS_PER_S = 1e9
SNAPSHOT_S = 0.5
MIN_GPS_FIXES = 3  # ActualTrack.orbit_eci fits at least three


def _interp_q(t: np.ndarray, t_tab: np.ndarray, q_tab: np.ndarray) -> np.ndarray:
    """q_ib at t, linear between neighbouring (hemisphere-continuous) samples and renormalised; ends held."""
    return quaternion.normalize(np.stack([np.interp(t, t_tab, q_tab[:, j]) for j in range(4)], axis=-1))


class LiveFeed:
    """TwinFeed of a satellite's live twin (thread-safe: the render loop and the twin worker run apart)."""

    def __init__(
        self,
        twins: Any,
        satellite: str,
        alarms: Callable[[], Sequence[Any]] = tuple,
        stations: Sequence[GroundStation] = DEFAULT_STATIONS,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self._twins, self._satellite, self._alarms, self._clock = twins, satellite, alarms, clock
        self._stations = list(stations)
        self._lock = threading.Lock()
        self._taken = -np.inf
        self._snap: dict[str, Any] = {}
        self._track: ActualTrack | None = None
        if not self.ready():
            raise ValueError(f"satellite: the live twin of {satellite!r} has no attitude and GPS samples yet")

    def ready(self) -> bool:
        """True once the twin holds attitude samples and enough GPS fixes for the orbit."""
        recent = self._twins.recent(self._satellite)
        return bool(recent and recent["t_ns"].size >= 2 and recent["gps_t_ns"].size >= MIN_GPS_FIXES)

    def _snapshot(self) -> dict[str, Any]:
        with self._lock:
            if self._clock() - self._taken >= SNAPSHOT_S:
                recent = self._twins.recent(self._satellite)
                if recent and recent["t_ns"].size >= 2 and recent["gps_t_ns"].size >= MIN_GPS_FIXES:
                    m = recent["mapping"]
                    gps = recent["gps"]
                    self._track = ActualTrack(
                        np.empty(0, np.int64),
                        {},
                        recent["gps_t_ns"],
                        {
                            "r_ecef_m": np.stack([gps[n] for n in m.r_ecef_m], -1),
                            "v_ecef_m_s": np.stack([gps[n] for n in m.v_ecef_m_s], -1),
                        },
                    )
                    self._snap = {
                        **recent,
                        "t_s": recent["t_ns"] / NS_PER_S,
                        "twin_t_s": recent["twin_t_ns"] / NS_PER_S,
                        "state": self._twins.state(self._satellite) or {},
                    }
                self._taken = self._clock()
            return self._snap

    def span_unix_s(self) -> tuple[float, float]:
        """Oldest and newest telemetry sample held (the newest moves on as telemetry arrives)."""
        t = self._snapshot()["t_s"]
        return float(t[0]), float(t[-1])

    def attitude_actual(self, t_unix_s: np.ndarray) -> np.ndarray:
        """Telemetered q_ib (mapped to scalar-first body→inertial)."""
        s = self._snapshot()
        return _interp_q(np.asarray(t_unix_s, float), s["t_s"], s["q_ib"])

    def attitude_simulated(self, t_unix_s: np.ndarray) -> np.ndarray:
        """The twin's q_ib where it was compared; the actual attitude without ACS model or before the first sync."""
        s = self._snapshot()
        if s["twin_t_s"].size < 2:
            return self.attitude_actual(t_unix_s)
        return _interp_q(np.asarray(t_unix_s, float), s["twin_t_s"], s["twin_q_ib"])

    def orbit_eci(self, t_unix_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ECI position and velocity from the GPS fixes (telemetry.actual_state.ActualTrack.orbit_eci)."""
        self._snapshot()
        assert self._track is not None
        return self._track.orbit_eci(t_unix_s)

    def window(self, t0_unix_s: float, t1_unix_s: float) -> FeedWindow:
        """Telemetry samples in [t0, t1] with the attitude error against the twin (NaN where no twin flew)."""
        s = self._snapshot()
        m = s["mapping"]
        sel = (s["t_s"] >= t0_unix_s) & (s["t_s"] <= t1_unix_s)
        t, hk, n = s["t_s"][sel], s["hk"], int(sel.sum())
        error = np.full(n, np.nan)
        if s["twin_t_s"].size >= 2:
            inside = (t >= s["twin_t_s"][0]) & (t <= s["twin_t_s"][-1])
            error[inside] = attitude_error_rad(s["q_ib"][sel][inside], self.attitude_simulated(t[inside]))
        wheels = np.stack([hk[w][sel] for w in m.wheel_speeds_rad_s], -1) if m.wheel_speeds_rad_s else np.zeros((n, 0))
        isolated = np.stack([hk[w][sel] != 0 for w in m.wheel_isolated], -1) if m.wheel_isolated else np.zeros((n, 0))
        return FeedWindow(
            t_unix_s=t,
            error_angle_rad=error,
            wheel_speed_rad_s=wheels,
            md_dipole_am2=np.full((n, 3), np.nan),  # not in the attitude mapping
            mode=np.asarray(hk[m.mode][sel], np.int64) if m.mode else np.zeros(n, np.int64),
            fault_flags=(isolated * (1 << np.arange(isolated.shape[1]))).sum(axis=1).astype(np.int64),
            observing=np.zeros(n, dtype=bool),
        )

    def active_alarms(self, t_unix_s: float) -> list[str]:
        """A STALE warning and the model note first, then the archived alarms raised by t and not cleared."""
        state = self._snapshot()["state"]
        out = []
        if state.get("stale"):
            age = state.get("last_packet_age_s")
            out.append(f"STALE: no telemetry for {age:.0f} s" if age is not None else "STALE: no telemetry")
        if state.get("model_note"):
            out.append(state["model_note"])
        t_ns = t_unix_s * NS_PER_S
        out += [
            f"{a.parameter}: {a.severity} ({a.state})"
            for a in self._alarms()
            if a.first_t_ns <= t_ns and a.state != "cleared"
        ]
        return out

    def ground_stations(self) -> list[GroundStation]:
        """Stations drawn with their visibility circles."""
        return list(self._stations)
