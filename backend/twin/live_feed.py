"""The 3D monitors' feed of one satellite's live twin: frontend.feed.TwinFeed over backend.twin.live.LiveTwins.

Actual side: the mapped attitude (telemetry.attitude_mapping) and the GPS orbit of the last RECENT_S; simulated
side: the twin's attitude at the telemetry instants it was compared at (the actual one for a satellite without
ACS model, which the alarm panel says). The span grows as telemetry arrives, so the monitors' live follow stays a
few seconds behind real time; the panel's alarm list starts with a STALE warning once no telemetry came for
the twins' ``stale_after_s`` (Settings.stale_after_s). A snapshot of the twin's buffers is taken at most every
SNAPSHOT_S (the render loop asks 30 times a s).

Any past window (frontend.feed.WindowSource): :class:`ArchiveWindows` reads the window's archived telemetry (the
mapped attitude, rates, wheels, mode and GPS) and the twin's archived attitude (backend.twin.live
TWIN_ATTITUDE_PARAMETERS) into a LiveFeed that no longer moves. Loading is bounded: a window is at most
MAX_WINDOW_S long, and its samples are cut to MAX_WINDOW_SAMPLES by telemetry.downsampling.minmax_indices.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from frontend.feed import (
    DEFAULT_STATIONS,
    ORBIT_TABLE_STEP_S,
    FeedWindow,
    GroundStation,
    attitude_error_rad,
    hermite_orbit,
)
from sim_core import quaternion
from telemetry.actual_state import ActualTrack
from telemetry.attitude_mapping import AttitudeMapping, actual_attitude
from telemetry.downsampling import minmax_indices

if TYPE_CHECKING:
    from backend.ingest.ports import TelemetryArchive
    from telemetry.archive.records import AlarmRecord

__all__ = ["ArchiveWindows", "LiveFeed", "MAX_WINDOW_S", "MAX_WINDOW_SAMPLES", "TwinSamples"]

NS_PER_S = 1e9
SNAPSHOT_S = 0.5
MIN_GPS_FIXES = 3  # ActualTrack.orbit_eci fits at least three
MAX_WINDOW_S = 7200.0  # longest replay window: more than an orbit (the panel offers up to 120 min)
MAX_WINDOW_SAMPLES = 20_000  # per series of a replay window (a 2 h window of 4 Hz housekeeping is 28,800)
ORBIT_TABLE_MARGIN_S = 60.0  # the orbit table reaches this far past the fixes; renewed once the telemetry is
# half-way there (a 30 s circular-orbit extrapolation from the fitted fixes is far below a displayed pixel)
ARCHIVE_SPAN_CACHE_S = 2.0  # the archive's span is asked by every panel twice a second: one query per this


def _interp_q(t: np.ndarray, t_tab: np.ndarray, q_tab: np.ndarray) -> np.ndarray:
    """q_ib at t, linear between neighbouring (hemisphere-continuous) samples and renormalised; ends held."""
    return quaternion.normalize(np.stack([np.interp(t, t_tab, q_tab[:, j]) for j in range(4)], axis=-1))


def _orbit_table(track: ActualTrack) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, r, v) every ORBIT_TABLE_STEP_S from the first fix to ORBIT_TABLE_MARGIN_S past the last (cubic Hermite
    between its rows is within ~0.2 mm at LEO, frontend.feed), from one vectorised ActualTrack.orbit_eci call; one
    side beyond the fixes only (one circular-orbit fit): live telemetry runs ahead of its newest fix."""
    t_fix = track.gps_t_utc_ns / NS_PER_S
    t = np.arange(t_fix[0], t_fix[-1] + ORBIT_TABLE_MARGIN_S + ORBIT_TABLE_STEP_S, ORBIT_TABLE_STEP_S)
    r, v = track.orbit_eci(t)
    return t, r, v


class TwinSamples(Protocol):
    """What the feed asks of the twins: a satellite's recent samples and public state (backend.twin.live.LiveTwins,
    or a window of the archive frozen)."""

    def recent(self, satellite: str) -> dict[str, Any] | None: ...

    def state(self, satellite: str) -> dict[str, Any] | None: ...


class LiveFeed:
    """TwinFeed of a satellite's live twin (thread-safe: the render loop and the twin worker run apart)."""

    def __init__(
        self,
        twins: TwinSamples,
        satellite: str,
        alarms: Callable[[], Sequence[AlarmRecord]] = tuple,
        stations: Sequence[GroundStation] = DEFAULT_STATIONS,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self._twins, self._satellite, self._alarms, self._clock = twins, satellite, alarms, clock
        self._stations = list(stations)
        self._lock = threading.Lock()
        self._taken = -np.inf
        self._snap: dict[str, Any] = {}
        self._track: ActualTrack | None = None
        self._orbit: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
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
                    newest_s = float(recent["t_ns"][-1]) / NS_PER_S
                    if self._orbit is None or newest_s > self._orbit[0][-1] - ORBIT_TABLE_MARGIN_S / 2:
                        self._orbit = _orbit_table(self._track)  # renewed every ~30 s of telemetry, not per snapshot
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
        """ECI position and velocity from the GPS fixes (telemetry.actual_state.ActualTrack.orbit_eci), near the fixes
        through the snapshot's table (_orbit_table): the render loop asks every frame, the fixes convert once."""
        self._snapshot()
        assert self._orbit is not None and self._track is not None
        t_tab, r_tab, v_tab = self._orbit
        t = np.asarray(t_unix_s, dtype=float)
        if t.size and (t.min() < t_tab[0] or t.max() > t_tab[-1]):  # the drawn tracks, far past the fixes
            return self._track.orbit_eci(t)
        return hermite_orbit(t_tab, r_tab, v_tab, t)

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


class _ArchivedTwin:
    """What LiveFeed asks a twin for (recent samples, state), frozen over an archived window."""

    def __init__(self, satellite: str, recent: dict[str, Any], state: dict[str, Any]) -> None:
        self._satellite, self._recent, self._state = satellite, recent, state

    def recent(self, satellite: str) -> dict[str, Any] | None:
        return self._recent if satellite == self._satellite else None

    def state(self, satellite: str) -> dict[str, Any] | None:
        return self._state if satellite == self._satellite else None


def _bounded(t_ns: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Indices of the samples kept (all, or MAX_WINDOW_SAMPLES by min/max buckets: the one downsampler)."""
    if t_ns.size <= MAX_WINDOW_SAMPLES:
        return np.arange(t_ns.size)
    return minmax_indices(np.nan_to_num(columns), MAX_WINDOW_SAMPLES)


def _continuous(q: np.ndarray) -> np.ndarray:
    """q with each sample in the hemisphere of its predecessor (q and −q are one attitude; interpolation needs one)."""
    if q.shape[0] < 2:
        return q
    sign = np.cumprod(np.where(np.einsum("ij,ij->i", q[1:], q[:-1]) < 0.0, -1.0, 1.0))
    return np.concatenate([q[:1], q[1:] * sign[:, None]])


class ArchiveWindows:
    """Past windows of one satellite's archive for the monitors (frontend.feed.WindowSource)."""

    def __init__(
        self,
        archive: Callable[[], TelemetryArchive | None],
        twins: TwinSamples,
        satellite: str,
        alarms: Callable[[], Sequence[AlarmRecord]] = tuple,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._archive, self._twins, self._satellite, self._alarms, self._clock = (
            archive,
            twins,
            satellite,
            alarms,
            clock,
        )
        self._span: tuple[float, tuple[float, float] | None] = (-np.inf, None)
        self._lock = threading.Lock()

    def archive_span_unix_s(self) -> tuple[float, float] | None:
        """First and last archived telemetry instant of the satellite (the twin's residuals not counted)."""
        from backend.twin.live import TWIN_APID

        with self._lock:
            if self._clock() - self._span[0] < ARCHIVE_SPAN_CACHE_S:
                return self._span[1]
            archive = self._archive()
            rows = [] if archive is None else archive.satellites(exclude_apids=(TWIN_APID,))
            row = next((r for r in rows if r["name"] == self._satellite and r["last_t_ns"] is not None), None)
            span = None if row is None else (row["first_t_ns"] / NS_PER_S, row["last_t_ns"] / NS_PER_S)
            self._span = (self._clock(), span)
            return span

    def window_feed(self, t0_unix_s: float, t1_unix_s: float) -> LiveFeed:
        """Archived telemetry and twin in [t0, t1] as a feed; ValueError naming the field when it cannot be."""
        if not (np.isfinite(t0_unix_s) and np.isfinite(t1_unix_s) and t1_unix_s > t0_unix_s):
            raise ValueError(f"window: need finite t0 < t1, got {t0_unix_s} … {t1_unix_s}")
        if t1_unix_s - t0_unix_s > MAX_WINDOW_S:
            raise ValueError(f"length: at most {MAX_WINDOW_S / 60:.0f} min, got {(t1_unix_s - t0_unix_s) / 60:.0f} min")
        span = self.archive_span_unix_s()
        if span is None or t1_unix_s < span[0] or t0_unix_s > span[1]:
            raise ValueError(f"from: no telemetry of {self._satellite} archived in that window (archive: {span})")
        recent = self._twins.recent(self._satellite)
        if not recent:
            raise ValueError(f"from: {self._satellite} has no attitude mapping (no live twin)")
        window = self._read(recent["mapping"], int(t0_unix_s * NS_PER_S), int(t1_unix_s * NS_PER_S))
        state = self._twins.state(self._satellite) or {}
        note = state.get("model_note")
        if note is None and window["twin_t_ns"].size < 2:  # archived before the twin's attitude was, or no twin flew
            note = "no twin attitude archived in this window: the simulated side shows the actual attitude"
        frozen = _ArchivedTwin(self._satellite, window, {"model_note": note})
        try:
            return LiveFeed(frozen, self._satellite, self._alarms)
        except ValueError:
            raise ValueError(
                f"from: the window holds {window['t_ns'].size} attitude sample(s) and {window['gps_t_ns'].size} "
                f"GPS fix(es) of {self._satellite}; the view needs 2 and {MIN_GPS_FIXES}"
            ) from None

    def _series(self, names: Sequence[str], t0_ns: int, t1_ns: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Times of the first parameter and every parameter's values there (NaN where one has no sample)."""
        archive = self._archive()
        if archive is None:
            raise ValueError("from: the archive is not open")
        t = np.empty(0, np.int64)
        out: dict[str, np.ndarray] = {}
        for name in names:
            try:
                t_n, v_n = archive.read_parameter(self._satellite, name, t0_ns, t1_ns)
            except ValueError:  # not archived (e.g. no twin flew): a column of NaN
                t_n, v_n = np.empty(0, np.int64), np.empty(0)
            if not out:
                t = t_n
            k = np.clip(np.searchsorted(t_n, t), 0, max(t_n.size - 1, 0))
            same = (k < t_n.size) & (t_n[k] == t) if t_n.size else np.zeros(t.size, bool)
            out[name] = np.where(same, v_n[k] if t_n.size else np.nan, np.nan).astype(np.float64)
        return t, out

    def _read(self, m: AttitudeMapping, t0_ns: int, t1_ns: int) -> dict[str, Any]:
        from backend.twin.live import TWIN_ATTITUDE_PARAMETERS

        t, hk = self._series(m.hk_parameters(), t0_ns, t1_ns)
        valid, q, _ = actual_attitude(m, hk)
        t, q, hk = t[valid], q[valid], {n: c[valid] for n, c in hk.items()}
        keep = _bounded(t, np.column_stack([q, *hk.values()]))
        t, q, hk = t[keep], _continuous(q[keep]), {n: c[keep] for n, c in hk.items()}
        twin_t, twin = self._series(TWIN_ATTITUDE_PARAMETERS, t0_ns, t1_ns)
        twin_q = np.stack([twin[n] for n in TWIN_ATTITUDE_PARAMETERS], -1) if twin_t.size else np.empty((0, 4))
        flown = np.all(np.isfinite(twin_q), axis=-1)
        twin_t, twin_q = twin_t[flown], twin_q[flown]
        keep = _bounded(twin_t, twin_q)
        twin_t, twin_q = twin_t[keep], _continuous(quaternion.normalize(twin_q[keep]) if twin_t.size else twin_q)
        gps_t, gps = (
            self._series(m.orbit_parameters(), t0_ns, t1_ns) if m.orbit_parameters() else (np.empty(0, np.int64), {})
        )
        keep = _bounded(gps_t, np.column_stack(list(gps.values())) if gps else np.empty((0, 1)))
        gps_t, gps = gps_t[keep], {n: c[keep] for n, c in gps.items()}
        return {
            "t_ns": t,
            "q_ib": q,
            "hk": hk,
            "twin_t_ns": twin_t,
            "twin_q_ib": twin_q,
            "gps_t_ns": gps_t,
            "gps": gps,
            "mapping": m,
        }
