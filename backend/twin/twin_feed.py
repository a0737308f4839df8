"""The twin monitors' data source over a twin session: frontend.feed.TwinFeed backed by telemetry + twin.

Actual side: the telemetered estimated attitude, rates, wheel speeds, MD moments, mode and wheel
fault flags of the session window (telemetry.actual_state) and the GPS orbit; simulated side: the
twin's trajectory (variant 0), its attitude and, for the simulated monitor's wheel plot, its wheel
speeds. Attitudes between samples follow the C¹ splines of seed 000 §7.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from frontend.feed import DEFAULT_STATIONS, FeedWindow, GroundStation, attitude_error_rad
from sim_core import quaternion
from sim_core.attitude_spline import AttitudeSpline
from telemetry.actual_state import ActualTrack
from telemetry.archive.records import AlarmRecord

__all__ = ["SessionFeed"]

NS_PER_S = 1e9
SAME_INSTANT_S = 1e-3  # twin output and telemetry times within 1 ms are one instant (float seconds of ~1.8e9)


class SessionFeed:
    """TwinFeed of one twin session: telemetry (actual) against the twin's trajectory (simulated)."""

    def __init__(
        self,
        track: ActualTrack,
        twin_npz: Path,
        align_utc_ns: int,
        alarms: Sequence[AlarmRecord] = (),
        stations: Sequence[GroundStation] = DEFAULT_STATIONS,
    ) -> None:
        self._track, self._alarms, self._stations = track, list(alarms), list(stations)
        self._t = track.t_utc_ns / NS_PER_S
        self._spline_a = AttitudeSpline(
            self._t, quaternion.normalize(track.series["q_est_ib"]), track.series["omega_est_b_rad_s"]
        )
        with np.load(twin_npz) as twin:
            t_twin = align_utc_ns / NS_PER_S + twin["t_s"]
            self._spline_s = AttitudeSpline(t_twin, twin["q_ib"][0], twin["omega_b_rad_s"][0])
            self._twin_t, self._twin_wheels = t_twin, twin["wheel_speed_rad_s"][0]
        self._t_end = min(float(self._t[-1]), float(t_twin[-1]) + SAME_INSTANT_S)  # both sides have data

    def span_unix_s(self) -> tuple[float, float]:
        """First telemetry sample of the session and the last instant both telemetry and twin cover."""
        return float(self._t[0]), self._t_end

    def attitude_actual(self, t_unix_s: np.ndarray) -> np.ndarray:
        """Telemetered attitude q_ib (spline through the estimated attitude and rates)."""
        return self._spline_a.attitude(np.clip(t_unix_s, *self._spline_a.t_s[[0, -1]]))

    def attitude_simulated(self, t_unix_s: np.ndarray) -> np.ndarray:
        """Twin attitude q_ib (spline through the twin's attitude and rates)."""
        return self._spline_s.attitude(np.clip(t_unix_s, *self._spline_s.t_s[[0, -1]]))

    def orbit_eci(self, t_unix_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ECI position and velocity from the GPS fixes (circular fit beyond them)."""
        return self._track.orbit_eci(t_unix_s)

    def window(self, t0_unix_s: float, t1_unix_s: float) -> FeedWindow:
        """Telemetry samples in [t0, t1] with the attitude error against the twin."""
        sel = (self._t >= t0_unix_s) & (self._t <= min(t1_unix_s, self._t_end))
        s, t = self._track.series, self._t[sel]
        faulted = s["fault_wheel"][sel] != 0
        return FeedWindow(
            t_unix_s=t,
            error_angle_rad=attitude_error_rad(quaternion.normalize(s["q_est_ib"][sel]), self.attitude_simulated(t)),
            wheel_speed_rad_s=s["wheel_speed_rad_s"][sel],
            md_dipole_am2=s["md_dipole_am2"][sel],
            mode=np.asarray(s["mode"][sel], dtype=np.int64),
            fault_flags=(faulted * (1 << np.arange(faulted.shape[1]))).sum(axis=1).astype(np.int64),
            observing=np.zeros(t.size, dtype=bool),  # the imaging state is not telemetered
            wheel_speed_simulated_rad_s=self.wheels_simulated(t),
        )

    def wheels_simulated(self, t_unix_s: np.ndarray) -> np.ndarray:
        """The twin's wheel speeds (rad/s) at the given times, linear between its samples, NaN outside its flight."""
        out = np.full((t_unix_s.size, self._twin_wheels.shape[1]), np.nan)
        inside = (t_unix_s >= self._twin_t[0]) & (t_unix_s <= self._twin_t[-1])
        for k in range(out.shape[1]):
            out[inside, k] = np.interp(t_unix_s[inside], self._twin_t, self._twin_wheels[:, k])
        return out

    def active_alarms(self, t_unix_s: float) -> list[str]:
        """Archived alarms raised at or before t and not cleared."""
        t_ns = t_unix_s * NS_PER_S
        return [
            f"{a.parameter}: {a.severity} ({a.state})"
            for a in self._alarms
            if a.first_t_ns <= t_ns and a.state != "cleared"
        ]

    def ground_stations(self) -> list[GroundStation]:
        """Stations drawn with their visibility circles."""
        return list(self._stations)
