"""Live twins: one per satellite that sends telemetry, always on, beside it (seed 000 §6–7 in-flight support).

Fed by what the archive commits (uploads, replays and the live stream take one path: :meth:`LiveTwins.submit`);
an upload too large to hand over decoded (a file of several decode chunks, decoded in the upload decoder process)
is read back from the archive by the twins' worker one ``BACKFILL_WINDOW_S`` at a time, between live batches
(:meth:`LiveTwins.submit_archived`).
Per satellite a :class:`LiveTwin` goes *waiting* → *synchronised* (state taken from telemetry: q_ib, ω, wheel
speeds, isolated wheels, time, the GPS orbit) → *propagating* (the onboard-equivalent ACS of the satellite's
library scenario flown by :func:`sim_core.engine.simulate` over a segment of ``RESYNC_S``, compared with every
sample as it arrives) → re-synchronised when the segment ends, or at once when a residual stays beyond what the
sensors' noise explains → *stale* once no telemetry arrived for ``stale_after_s`` (Settings.stale_after_s,
default ``STALE_S``). A satellite whose attitude mapping
declares no ACS model is *actual_only*: its attitude is followed, no twin is flown.

Residuals, twin minus telemetry at each telemetry instant: attitude angle |Λ̃_tm ∘ Λ_twin| (arcsec), body rates
(rad/s, per axis), wheel speeds (rad/s, per wheel). They are archived as parameters of their own (APID
``TWIN_APID``, no raw packet) with limits, so they plot, export and raise alarms like any other, and published
on the hub (``parameters/<name>`` and the twin state on ``twin``). The twin's own attitude at those instants is
archived beside them (``TWIN_ATTITUDE_PARAMETERS``, scalar-first q_ib), so that the 3D monitors replay actual and
simulated for any past window from the archive alone (backend.twin.live_feed.ArchiveWindows).

Detection (the diagnosis hook): each twin's wheel-speed and body-rate residuals go through the window test of
:mod:`backend.twin.live_detection` (stated false-alarm rate, `false_alarms_per_day` in the twin state). When it
fires the twin archives the parameter ``twin_anomaly`` = 1 at that instant (red limit 0.5: the archive raises the
alarm) and, once ``POST_ALARM_S`` of telemetry followed it, :class:`LiveTwins` calls ``on_detection`` (the server
starts a diagnosis of the ``PRE_ALARM_S`` before to now, linked to the alarm). The detector then stays latched for
``REARM_S`` of telemetry: one automatic diagnosis per anomaly, the alarm stays until acknowledged.

Re-sync cadence RESYNC_S = 60 s: (1) the twin restarted from telemetry stays at the sensor-noise level over a
segment (measured: 2–4″ RMS against σ_st = 3″, wheels within one tachometer count over 60 s), so nothing is gained
by re-syncing more often, while a shorter segment hides slow faults (a drifting gyro, a wheel's friction) in
its restart; (2) a fault's fast signature (a failed wheel stops answering torque commands: its speed residual
crosses EXCEED limits within seconds) shows inside any segment and forces an immediate re-sync; (3) one re-sync
(orbit fit, engine set-up and a 60 s segment) costs ≈ 10 ms of CPU (benchmarks/live_twin.py --resync), i.e. 100
satellites need ≈ 2 % of one core.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from backend.twin.live_detection import Detection, ResidualDetector
from sim_core import quaternion
from sim_core.scenario import Scenario
from telemetry.actual_state import MIN_GPS_FIXES
from telemetry.archive.batch import DERIVED_APID
from telemetry.attitude_mapping import (
    SHIPPED_MAPPINGS,
    AttitudeMapping,
    actual_attitude,
    mapping_for_parameters,
    shipped_mapping,
)
from telemetry.housekeeping import calibration_step
from telemetry.ingest_report import SampleBatch
from telemetry.limits import LimitSet

if TYPE_CHECKING:
    from backend.ingest.live_hub import Publisher
    from backend.ingest.ports import TelemetryArchive
    from telemetry.archive import PendingUpload
    from telemetry.dictionary import Dictionary

__all__ = [
    "ANOMALY_PARAMETER",
    "LiveDetection",
    "RESIDUAL_PARAMETERS",
    "RESYNC_S",
    "STALE_S",
    "TWIN_APID",
    "TWIN_ATTITUDE_PARAMETERS",
    "LiveTwin",
    "LiveTwins",
    "TwinState",
    "residual_limits",
]

log = logging.getLogger(__name__)

NS_PER_S = 1_000_000_000
ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0
TWIN_APID = DERIVED_APID  # the residuals are parameters derived on the ground: no raw packets
RESYNC_S = 60.0  # segment length: see the module docstring
STALE_S = 10.0  # default: no telemetry for this long (ten 1 Hz packets missed) = stale (Settings.stale_after_s)
GAP_RESYNC_S = 10.0  # a gap this long in telemetry time forces a re-sync (whatever the staleness threshold shown)
RECENT_S = 600.0  # telemetry kept per satellite: the sync sample may lie before a 100 s scheduled turn
GPS_FULL_SPAN_S = 30.0  # a fit over 30 s of fixes is at the receiver noise; the first one, over the first three fixes
# (positions and velocities: actual_state.fit_circular_orbit, a few arcseconds), is refined by a re-sync once the
# fixes span this long, so that the twin propagates ~3 s after the first packets instead of 30 s
GPS_WINDOW_S = 60.0  # GPS fixes around the sync instant fitted into the twin's orbit (actual_state.aligned_scenario)
EXCEED_SAMPLES = 3  # consecutive samples beyond the limits that force a re-sync (one outlier does not)
MIN_RESYNC_S = 10.0  # residual-forced re-syncs no closer than this (a failed wheel would force one per sample)
ARCHIVE_PERIOD_S = 10.0  # residuals handed to the archive writer per satellite this often; the writer commits what
# is queued in one transaction (one fsync for every satellite: Archive.ingest_many); the twin never waits for it.
# An upload costs ~10–30 ms of CPU whatever its length (a row per parameter, limit and duplicate checks), so 100
# satellites make 10 uploads/s; residuals are published at once, the archive holds them ≤ 10 s later
GROUP_MAX_UPLOADS = 100  # one transaction holds the SQLite write lock: bounded well below its 30 s busy timeout
TICK_S = 0.5  # staleness checked this often
MAX_TAKEN = 2_000  # queued items the worker takes at once (grouped by satellite: LiveTwins._take)
BACKFILL_WINDOW_S = 300.0  # an archived span is read back, decoded and flown this much at a time: bounded memory
# (≈ 1,500 packets of the reference satellite), and live batches queued meanwhile wait for one window only
MAX_ISSUES = 20  # bad-input reports kept per satellite
SAME_INSTANT_NS = 1_000_000
# Forced re-sync / yellow limits from the reference sensors: σ_st = 3″ star tracker (the estimate's error is a few σ),
# 0.25 rpm tachometer count, gyro noise 1e-6 rad/s behind a 0.25 s MEKF. Ten times those is no longer noise.
ATTITUDE_LIMIT_ARCSEC = 30.0
RATE_LIMIT_RAD_S = 1e-4
WHEEL_LIMIT_RAD_S = 10 * 0.25 * np.pi / 30.0
RED_FACTOR = 10.0
ANOMALY_PARAMETER = "twin_anomaly"  # 1 where the detector fired, else 0; red above 0.5
POST_ALARM_S = 20.0  # telemetry after the detection that the diagnosis waits for (the fault's signature grows)
PRE_ALARM_S = 600.0  # telemetry before the detection the diagnosis looks at (the onset lies before the alarm)
REARM_S = 1800.0  # telemetry time after a detection before the detector may fire again

WAITING, SYNCHRONISED, PROPAGATING, STALE, ACTUAL_ONLY = (
    "waiting",
    "synchronised",
    "propagating",
    "stale",
    "actual_only",
)


def residual_names(n_wheels: int) -> list[str]:
    """Archived parameter names of the residuals of a satellite with ``n_wheels`` wheels."""
    return (
        ["twin_attitude_residual_arcsec"]
        + [f"twin_rate_residual_b_rad_s_{a}" for a in "xyz"]
        + [f"twin_wheel_speed_residual_rad_s_{k + 1}" for k in range(n_wheels)]
    )


RESIDUAL_PARAMETERS = residual_names(4)
TWIN_ATTITUDE_PARAMETERS = tuple(f"twin_q_ib_{k}" for k in range(4))  # the twin's q_ib, scalar first


def residual_limits(n_wheels: int) -> dict[str, LimitSet]:
    """Yellow/red limits of the residual parameters (yellow = the forced re-sync level, red = ten times it)."""

    def band(limit: float, signed: bool) -> LimitSet:
        low = -limit if signed else -np.inf  # an angle is ≥ 0: no low limit
        return LimitSet(yellow_low=low, yellow_high=limit, red_low=low * RED_FACTOR, red_high=limit * RED_FACTOR)

    names = residual_names(n_wheels)
    limits = [ATTITUDE_LIMIT_ARCSEC] + [RATE_LIMIT_RAD_S] * 3 + [WHEEL_LIMIT_RAD_S] * n_wheels
    out = {n: band(lim, signed=i > 0) for i, (n, lim) in enumerate(zip(names, limits))}
    out[ANOMALY_PARAMETER] = LimitSet(yellow_low=-np.inf, yellow_high=0.5, red_low=-np.inf, red_high=0.5)
    return out


@dataclass
class Segment:
    """One flown twin segment: UTC ns of its samples and the twin's q_ib, ω_b, wheel speeds there."""

    t_ns: np.ndarray
    q_ib: np.ndarray
    omega_b_rad_s: np.ndarray
    wheel_speed_rad_s: np.ndarray
    forced: bool = False

    @property
    def start_ns(self) -> int:
        return int(self.t_ns[0])

    @property
    def end_ns(self) -> int:
        return int(self.t_ns[-1])

    def at(self, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Twin q_ib, ω, wheel speeds at t_ns (linear between samples, q renormalised)."""
        x = (t_ns - self.t_ns[0]) / 1e9
        grid = (self.t_ns - self.t_ns[0]) / 1e9

        def lin(a: np.ndarray) -> np.ndarray:
            return np.stack([np.interp(x, grid, a[:, j]) for j in range(a.shape[1])], axis=-1)

        return quaternion.normalize(lin(self.q_ib)), lin(self.omega_b_rad_s), lin(self.wheel_speed_rad_s)


@dataclass(frozen=True)
class LiveDetection:
    """A live twin's detection handed to ``LiveTwins.on_detection``: the satellite, its dictionary and ACS model,
    the detection, the newest telemetry time (ns) and an Event set once the alarm is archived."""

    satellite: str
    dictionary: str
    scenario: Scenario
    detection: Detection
    newest_utc_ns: int
    archived: threading.Event

    @property
    def window_ns(self) -> tuple[int, int]:
        """The telemetry the diagnosis reads: PRE_ALARM_S before the detection to the newest sample."""
        return self.detection.t_utc_ns - int(PRE_ALARM_S * NS_PER_S), self.newest_utc_ns


@dataclass(frozen=True)
class _Backfill:
    """What is left of an archived span of one satellite for its twin."""

    satellite: str
    dictionary: str
    t0_ns: int
    t1_ns: int


_Committed = tuple[str, str, list[SampleBatch], float]  # satellite, dictionary, batches, when they arrived (clock)
_Inbox = _Committed | _Backfill | threading.Event  # an Event: set once everything queued before it is archived
_Group = dict[tuple[str, str], tuple[list[SampleBatch], float]]  # (satellite, dictionary) -> batches, first arrival


@dataclass
class TwinState:
    """What the API and the ``twin`` topic tell about one satellite's live twin."""

    satellite: str
    dictionary: str
    acs_model: str | None
    state: str = WAITING
    telemetry_utc_ns: int | None = None
    twin_utc_ns: int | None = None
    synchronised_utc_ns: int | None = None
    horizon_utc_ns: int | None = None
    last_arrival_unix_s: float | None = None
    actual_q_ib: list[float] | None = None
    twin_q_ib: list[float] | None = None
    attitude_residual_arcsec: float | None = None
    rate_residual_b_rad_s: list[float] | None = None
    wheel_speed_residual_rad_s: list[float] | None = None
    resyncs: int = 0
    forced_resyncs: int = 0
    samples_compared: int = 0
    note: str | None = None
    issues: deque = field(default_factory=lambda: deque(maxlen=MAX_ISSUES))
    detection: dict[str, Any] | None = None  # the detector's last firing (and the diagnosis it started)
    false_alarms_per_day: float | None = None


def _stack(columns: dict[str, np.ndarray], names: Sequence[str] | None) -> np.ndarray:
    """(n, k) array of the named columns."""
    return np.stack([columns[n] for n in names or ()], axis=-1)


def _iso(t_ns: int | None) -> str | None:
    return None if t_ns is None else f"{np.datetime64(int(t_ns), 'ns').astype('datetime64[ms]')}Z"


class LiveTwin:
    """The twin of one satellite: its recent telemetry, its flown segment and its state machine."""

    def __init__(
        self,
        satellite: str,
        mapping: AttitudeMapping,
        model: Scenario | None,
        epoch_ns: int | None = None,
        resync_s: float = RESYNC_S,
        epoch_from_run: bool = False,
        wheel_quantum_rad_s: float = 0.0,
        stale_after_s: float = STALE_S,
    ) -> None:
        self.mapping, self.model, self._epoch_ns, self._resync_s = mapping, model, epoch_ns, resync_s
        self.stale_after_s = stale_after_s
        self._epoch_from_run = epoch_from_run  # the route starts with each run of telemetry (an emulator's flight)
        self._epoch_model: tuple[int, Scenario] | None = None  # (epoch ns, the model at that epoch)
        self.state = TwinState(
            satellite, mapping.dictionary, mapping.acs_model if model is not None else None, state=WAITING
        )
        self._t = np.empty(0, np.int64)
        self._hk: dict[str, np.ndarray] = {}
        self._q = np.empty((0, 4))
        self._gps_t = np.empty(0, np.int64)
        self._gps: dict[str, np.ndarray] = {}
        self._segment: Segment | None = None
        self._unsynced_ns: int | None = None  # the sample a failed synchronisation stopped at (None: none failed)
        self._last_forced_ns = -(2**62)
        self._twin_t = np.empty(0, np.int64)
        self._twin_q = np.empty((0, 4))
        n_wheels = len(mapping.wheel_speeds_rad_s or ())
        self.detector = ResidualDetector(n_wheels, wheel_quantum_rad_s)
        self.detections: list[Detection] = []  # fired and not yet taken by LiveTwins

    # --- bad input -------------------------------------------------------------------------------
    def report(self, kind: str, message: str, t_ns: int | None = None) -> None:
        """Keep a bad-input finding (newest last; a repeat of the newest message is not stored twice)."""
        issues = self.state.issues
        if issues and issues[-1]["kind"] == kind and issues[-1]["message"] == message:
            issues[-1]["count"] += 1
            return
        issues.append({"kind": kind, "message": message, "utc": _iso(t_ns), "count": 1})
        log.info("twin %s: %s", self.state.satellite, message)

    # --- input -----------------------------------------------------------------------------------
    def _columns(self, batch: SampleBatch, names: Sequence[str]) -> dict[str, np.ndarray] | None:
        missing = [n for n in names if n not in batch.values]
        if missing:
            self.report(
                "mapping",
                f"{self.mapping.source}: mapping names parameters {missing} that packet "
                f"{batch.packet} does not carry: ignored until the mapping is fixed",
            )
            return None
        return {n: np.asarray(batch.values[n], dtype=np.float64) for n in names}

    def _restart(self, why: str, kind: str, t_ns: int) -> None:
        self.report(kind, f"{why}: twin re-synchronises", t_ns)
        self._t, self._hk, self._q = np.empty(0, np.int64), {}, np.empty((0, 4))
        self._segment, self._unsynced_ns = None, None
        self.state.state = WAITING
        if self._epoch_from_run:
            self._epoch_ns = None

    def _add_gps(self, batch: SampleBatch) -> None:
        cols = self._columns(batch, self.mapping.orbit_parameters())
        if cols is None or not len(batch.t_utc_ns):
            return
        t = np.asarray(batch.t_utc_ns, np.int64)
        if self._gps_t.size and int(t.min()) < int(self._gps_t[-1]) - SAME_INSTANT_NS:  # back in time: start over
            self._gps_t, self._gps = np.empty(0, np.int64), {}
        keep = t > (self._gps_t[-1] if self._gps_t.size else -(2**62))
        self._gps_t = np.concatenate([self._gps_t, t[keep]])
        self._gps = {n: np.concatenate([self._gps.get(n, np.empty(0)), c[keep]]) for n, c in cols.items()}
        self._trim_gps()

    def _trim_gps(self) -> None:
        if self._gps_t.size:
            first = np.searchsorted(self._gps_t, self._gps_t[-1] - int(RECENT_S * NS_PER_S))
            self._gps_t = self._gps_t[first:]
            self._gps = {n: c[first:] for n, c in self._gps.items()}

    def _add_hk(self, batch: SampleBatch) -> bool:
        """Append the batch's new samples (checked); True if the twin had to restart (all buffered samples new)."""
        cols = self._columns(batch, self.mapping.hk_parameters())
        t = np.asarray(batch.t_utc_ns, np.int64)
        if cols is None or t.size == 0:
            return False
        order = np.argsort(t, kind="stable")
        t, cols = t[order], {n: c[order] for n, c in cols.items()}
        newest = int(self._t[-1]) if self._t.size else None
        restarted = False
        if newest is not None and int(t[0]) < newest - SAME_INSTANT_NS:
            self._restart(
                f"time went back {(newest - int(t[0])) / 1e9:.3f} s (from {_iso(newest)} to "
                f"{_iso(int(t[0]))}); everything is archived",
                "time_backwards",
                int(t[0]),
            )
            restarted = True
        elif newest is not None and int(t[0]) - newest > GAP_RESYNC_S * NS_PER_S:
            self._restart(
                f"gap of {(int(t[0]) - newest) / 1e9:.1f} s in telemetry (from {_iso(newest)})", "gap", int(t[0])
            )
            restarted = True
        fresh = t > (self._t[-1] + SAME_INSTANT_NS // 2 if self._t.size else -(2**62))
        t, cols = t[fresh], {n: c[fresh] for n, c in cols.items()}
        valid, q, check = actual_attitude(self.mapping, cols, self._q[-1] if self._q.size else None)
        for message in check.messages():
            if "flip" not in message:  # flips are a convention (q and −q are one attitude), not an error
                self.report("quaternion", message, int(t[0]) if t.size else None)
        t, q, cols = t[valid], q[valid], {n: c[valid] for n, c in cols.items()}
        self._t = np.concatenate([self._t, t])
        self._q = np.concatenate([self._q, q])
        self._hk = {n: np.concatenate([self._hk.get(n, np.empty(0)), c]) for n, c in cols.items()}
        first = int(np.searchsorted(self._t, self._t[-1] - int(RECENT_S * NS_PER_S))) if self._t.size else 0
        self._t, self._q = self._t[first:], self._q[first:]
        self._hk = {n: c[first:] for n, c in self._hk.items()}
        return restarted

    def observe(self, batches: Sequence[SampleBatch], arrived_unix_s: float) -> dict[str, np.ndarray] | None:
        """Take one committed set of decoded batches; the residual columns computed (with ``t_utc_ns``), or None."""
        newest_fix = self._gps_t[-1] if self._gps_t.size else None
        for batch in batches:
            if self.mapping.orbit_packet and batch.packet == self.mapping.orbit_packet:
                self._add_gps(batch)
        fixes_came = self._gps_t.size > 0 and self._gps_t[-1] != newest_fix
        before = int(self._t[-1]) if self._t.size else None
        for batch in batches:
            if batch.packet == self.mapping.packet and self._add_hk(batch):
                before = None
        new = np.flatnonzero(self._t > before) if before is not None else np.arange(self._t.size)
        if new.size == 0 and fixes_came and self._unsynced_ns is not None and self.model is not None:
            # the live link relays each packet type apart: the GPS fixes a failed synchronisation waited for may
            # come after the last housekeeping samples (the end of a pass): synchronise again where it stopped
            return self._compare(np.flatnonzero(self._t >= self._unsynced_ns))
        if new.size == 0:
            return None
        s = self.state
        s.telemetry_utc_ns, s.actual_q_ib = int(self._t[-1]), self._q[-1].tolist()
        s.last_arrival_unix_s = arrived_unix_s
        if self.model is None:
            s.state = ACTUAL_ONLY
            return None
        return self._compare(new)

    # --- twin ------------------------------------------------------------------------------------
    def _sync_index(self, k: int) -> int | None:
        """Newest buffered sample at or before k outside a scheduled turn (the route cannot restart inside one),
        preferring one on the onboard control clock (elapsed time since the epoch a multiple of T_u): a twin whose
        zero-order-hold torques tick 0.25 s off the satellite's drifts by minutes of arc through a turn."""
        assert self.model is not None
        modes = self._hk.get(self.mapping.mode) if self.mapping.mode else None
        period_ns = round(self.model.control_dt_s * NS_PER_S)
        epoch_ns = self._epoch()
        fallback = None
        for i in range(k, -1, -1):
            if modes is not None and int(modes[i]) in self.mapping.turn_modes:
                continue
            phase = (int(self._t[i]) - epoch_ns) % period_ns
            if min(phase, period_ns - phase) <= SAME_INSTANT_NS:
                return i
            if fallback is None:
                fallback = i
            if self._t[fallback] - self._t[i] > period_ns:  # telemetry off the control clock: the newest
                return fallback
        return fallback

    def _fly(self, k: int) -> Segment | None:
        """Synchronise at (or just before) buffered sample k and fly a segment past it; None if it cannot."""
        from sim_core.engine import simulate
        from telemetry.actual_state import ActualTrack, aligned_scenario

        i = self._sync_index(k)
        if i is None:
            self.report(
                "sync", "no sample outside a scheduled turn in the recent telemetry yet: waiting", int(self._t[k])
            )
            return None
        t_sync = int(self._t[i])
        near = np.abs(self._gps_t - t_sync) <= GPS_WINDOW_S / 2 * NS_PER_S
        if np.count_nonzero(near) < MIN_GPS_FIXES:
            self.state.note = f"waiting: the orbit fit needs {MIN_GPS_FIXES} GPS fixes, has {np.count_nonzero(near)}"
            return None
        span_s = (self._gps_t[near].max() - self._gps_t[near].min()) / 1e9
        m, hk = self.mapping, self._hk
        track = ActualTrack(
            self._t,
            {
                "q_est_ib": self._q,
                "omega_est_b_rad_s": _stack(hk, m.rates_b_rad_s),
                "wheel_speed_rad_s": _stack(hk, m.wheel_speeds_rad_s),
                "fault_wheel": _stack(hk, m.wheel_isolated),
            },
            self._gps_t[near],
            {"r_ecef_m": _stack(self._gps, m.r_ecef_m)[near], "v_ecef_m_s": _stack(self._gps, m.v_ecef_m_s)[near]},
        )
        ahead_s = self._resync_s if span_s >= GPS_FULL_SPAN_S else max(GPS_FULL_SPAN_S - span_s, 1.0)  # then refine
        duration = (int(self._t[k]) - t_sync) / 1e9 + ahead_s
        try:
            twin = aligned_scenario(self._model_at_epoch(), track, t_sync, duration)
        except ValueError as exc:
            self.report("sync", f"cannot synchronise at {_iso(t_sync)}: {exc}", t_sync)
            return None
        twin = twin.model_copy(update={"output_dt_s": twin.measurement_dt_s})
        flown = simulate(twin, wheel_available=track.series["fault_wheel"][i][None, :] == 0.0, fdir=True)
        self.state.resyncs += 1
        self.state.note = None
        return Segment(
            t_sync + np.round(flown.t_s * 1e9).astype(np.int64),
            flown["q_ib"][0],
            flown["omega_b_rad_s"][0],
            flown["wheel_speed_rad_s"][0],
        )

    def _epoch(self) -> int:
        """When the satellite started its scenario's route (registered, else its first telemetry)."""
        if self._epoch_ns is None:
            self._epoch_ns = int(self._t[0])
        return self._epoch_ns

    def _model_at_epoch(self) -> Scenario:
        """The satellite's model with its route's epoch (built once per epoch, not per re-sync)."""
        assert self.model is not None
        epoch = self._epoch()
        if self._epoch_model is None or self._epoch_model[0] != epoch:
            data = self.model.model_dump()
            data["orbit"]["epoch_utc"] = f"{np.datetime64(epoch, 'ns')}Z"
            self._epoch_model = epoch, Scenario.model_validate(data)
        return self._epoch_model[1]

    def _compare(self, new: np.ndarray) -> dict[str, np.ndarray] | None:
        """Residuals of the new samples, flying (re-synchronising) segments as needed."""
        out: list[dict[str, np.ndarray]] = []
        k = int(new[0])
        while k < self._t.size:
            seg = self._segment
            if seg is None or int(self._t[k]) > seg.end_ns:
                self._segment = seg = self._fly(k)
                if seg is None:
                    self.state.state, self._unsynced_ns = WAITING, int(self._t[k])
                    break
                self.state.state, self._unsynced_ns = SYNCHRONISED, None
            stop = int(np.searchsorted(self._t, seg.end_ns, side="right"))
            rows = np.arange(k, stop)
            rows = rows[self._t[rows] >= seg.start_ns]
            if rows.size == 0:
                k = stop
                continue
            res = self._residuals(seg, rows)
            cut = self._first_exceedance(res, seg)
            if cut is not None:
                rows, res = rows[:cut], {n: v[:cut] for n, v in res.items()}
                self._segment, self._last_forced_ns = None, int(self._t[rows[-1]])
                self.state.forced_resyncs += 1
                self.report(
                    "residual",
                    "residual beyond the sensors' noise for "
                    f"{EXCEED_SAMPLES} samples: re-synchronised (diagnosis hook)",
                    int(self._t[rows[-1]]),
                )
            out.append(res)
            k = int(rows[-1]) + 1
        if not out:
            return None
        return {n: np.concatenate([o[n] for o in out]) for n in out[0]}

    def _residuals(self, seg: Segment, rows: np.ndarray) -> dict[str, np.ndarray]:
        t = self._t[rows]
        q_twin, w_twin, h_twin = seg.at(t)
        m = self.mapping
        w_tm = _stack(self._hk, m.rates_b_rad_s)[rows]
        h_tm = _stack(self._hk, m.wheel_speeds_rad_s)[rows]
        angle = quaternion.angle(quaternion.multiply(quaternion.conjugate(self._q[rows]), q_twin))
        names = residual_names(h_tm.shape[1])
        columns = [angle * ARCSEC_PER_RAD, *(w_twin - w_tm).T, *(h_twin - h_tm).T]
        s = self.state
        s.state, s.twin_utc_ns, s.twin_q_ib = PROPAGATING, int(t[-1]), q_twin[-1].tolist()
        s.synchronised_utc_ns, s.horizon_utc_ns = seg.start_ns, seg.end_ns
        s.attitude_residual_arcsec = float(columns[0][-1])
        s.rate_residual_b_rad_s = [float(c[-1]) for c in columns[1:4]]
        s.wheel_speed_residual_rad_s = [float(c[-1]) for c in columns[4:]]
        s.samples_compared += int(t.size)
        keep = self._twin_t < t[0]  # a re-sync after time went back replaces what the twin said there
        self._twin_t = np.concatenate([self._twin_t[keep], t])
        self._twin_q = np.concatenate([self._twin_q[keep], q_twin])
        first = int(np.searchsorted(self._twin_t, self._twin_t[-1] - int(RECENT_S * NS_PER_S)))
        self._twin_t, self._twin_q = self._twin_t[first:], self._twin_q[first:]
        return {
            "t_utc_ns": t,
            **dict(zip(names, columns)),
            **{name: q_twin[:, k] for k, name in enumerate(TWIN_ATTITUDE_PARAMETERS)},
            ANOMALY_PARAMETER: self._detect(seg, t, columns),
        }

    def _detect(self, seg: Segment, t: np.ndarray, columns: list[np.ndarray]) -> np.ndarray:
        """The detector on the wheel and rate residuals of these rows; 1 where it fired, else 0."""
        flag = np.zeros(t.size)
        rows = np.searchsorted(self._t, t)
        isolated = _stack(self._hk, self.mapping.wheel_isolated)[rows] if self.mapping.wheel_isolated else None
        det = self.detector.update(seg.start_ns, t, np.stack([*columns[4:], *columns[1:4]], axis=-1), isolated)
        self.state.false_alarms_per_day = self.detector.false_alarms_per_day
        if det is not None:
            flag[np.searchsorted(t, det.t_utc_ns)] = 1.0
            self.detections.append(det)
            self.state.detection = {
                "utc": _iso(det.t_utc_ns),
                "channel": det.channel,
                "window_s": det.window_s,
                "ratio_sigma": det.ratio,
                "diagnosis_id": None,
            }
            test = "" if det.ratio is None else f" ({det.ratio:.1f} σ over {det.window_s:g} s)"
            why = f"anomaly detected: {det.channel}{test}"
            self.report("anomaly", why, det.t_utc_ns)
        elif self.detector.fired is not None and int(t[-1]) - self.detector.fired.t_utc_ns > REARM_S * NS_PER_S:
            self.detector.rearm()
        return flag

    def _first_exceedance(self, res: dict[str, np.ndarray], seg: Segment) -> int | None:
        """Rows to keep when EXCEED_SAMPLES consecutive samples pass a limit (None: keep going)."""
        over = np.abs(res["twin_attitude_residual_arcsec"]) > ATTITUDE_LIMIT_ARCSEC
        for name, values in res.items():
            if name.startswith("twin_rate"):
                over |= np.abs(values) > RATE_LIMIT_RAD_S
            elif name.startswith("twin_wheel"):
                over |= np.abs(values) > WHEEL_LIMIT_RAD_S
        run = np.convolve(over.astype(int), np.ones(EXCEED_SAMPLES, int), "valid")
        hits = np.flatnonzero(run == EXCEED_SAMPLES)
        t = res["t_utc_ns"]
        hits = hits[t[hits] - max(seg.start_ns, self._last_forced_ns) >= MIN_RESYNC_S * NS_PER_S]
        return None if hits.size == 0 else int(hits[0]) + EXCEED_SAMPLES

    def recent(self) -> dict[str, Any]:
        """Copies of the recent telemetry and twin samples (the live 3D monitors' feed): UTC ns times, actual and
        twin q_ib, the mapped HK columns and the GPS fixes."""
        return {
            "t_ns": self._t.copy(),
            "q_ib": self._q.copy(),
            "hk": {n: c.copy() for n, c in self._hk.items()},
            "twin_t_ns": self._twin_t.copy(),
            "twin_q_ib": self._twin_q.copy(),
            "gps_t_ns": self._gps_t.copy(),
            "gps": {n: c.copy() for n, c in self._gps.items()},
            "mapping": self.mapping,
        }

    def public(self, now_unix_s: float) -> dict[str, Any]:
        """The twin state as JSON (see routes/satellites.py for the shape)."""
        s = self.state
        age = None if s.last_arrival_unix_s is None else max(now_unix_s - s.last_arrival_unix_s, 0.0)
        stale = age is None or age > self.stale_after_s
        return {
            "satellite": s.satellite,
            "dictionary": s.dictionary,
            "acs_model": s.acs_model,
            "model_note": None
            if s.acs_model
            else f"no ACS model is configured for {s.satellite}: actual attitude only",
            "state": STALE if stale and s.telemetry_utc_ns is not None else s.state,
            "stale": stale,
            "last_packet_age_s": age,
            "stale_after_s": self.stale_after_s,
            "telemetry_utc": _iso(s.telemetry_utc_ns),
            "twin_utc": _iso(s.twin_utc_ns),
            "twin_behind_telemetry_s": None
            if s.twin_utc_ns is None or s.telemetry_utc_ns is None
            else (s.telemetry_utc_ns - s.twin_utc_ns) / 1e9,
            "synchronised_utc": _iso(s.synchronised_utc_ns),
            "route_epoch_utc": _iso(self._epoch_ns) if self.model is not None else None,
            "horizon_utc": _iso(s.horizon_utc_ns),
            "actual_q_ib": s.actual_q_ib,
            "twin_q_ib": s.twin_q_ib,
            "attitude_residual_arcsec": s.attitude_residual_arcsec if s.acs_model else None,
            "rate_residual_b_rad_s": s.rate_residual_b_rad_s,
            "wheel_speed_residual_rad_s": s.wheel_speed_residual_rad_s,
            "resyncs": s.resyncs,
            "forced_resyncs": s.forced_resyncs,
            "samples_compared": s.samples_compared,
            "note": s.note,
            "issues": list(s.issues),
            "detection": s.detection,
            "false_alarms_per_day": s.false_alarms_per_day,
        }


class LiveTwins:
    """Every satellite's live twin, run by one worker thread off the ingest and request paths.

    ``archive`` is a callable giving the telemetry.archive.Archive (None while not open), ``hub`` the live hub
    (``publish``, ``wants_any``), ``dictionary(name)`` the catalogue's loader, ``on_archived(satellite, t0_ns,
    t1_ns)`` the sample cache's invalidation; mappings are looked up in ``mapping_folders`` before the shipped ones;
    a twin without telemetry for ``stale_after_s`` of wall time is stale.
    """

    def __init__(
        self,
        archive: Callable[[], TelemetryArchive | None],
        hub: Publisher,
        dictionary: Callable[[str], Dictionary],
        on_archived: Callable[[str, int, int], None] | None = None,
        mapping_folders: Sequence[Path] = (),
        clock: Callable[[], float] = time.time,
        stale_after_s: float = STALE_S,
    ) -> None:
        self._archive, self._hub, self._dictionary = archive, hub, dictionary
        self.stale_after_s = stale_after_s
        self._on_archived, self._clock = on_archived, clock
        self._folders = [*mapping_folders, SHIPPED_MAPPINGS]
        self._twins: dict[str, LiveTwin] = {}
        self._models: dict[str, tuple[str, int | None, bool]] = {}
        self._inbox: queue.Queue[_Inbox] = queue.Queue()
        self._pending: dict[str, list[dict[str, np.ndarray]]] = {}
        self._flushed_at: dict[str, float] = {}
        self._stale_published: set[str] = set()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._writer: threading.Thread | None = None
        self._ticked_at = 0.0
        self._writes: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self.latencies_s: deque = deque(maxlen=100_000)
        self._detected: dict[str, list[Detection]] = {}  # waiting for POST_ALARM_S of telemetry after them
        self._recovering = False
        self._backfills = 0  # archived spans not yet read to their end
        self.on_detection: Callable[[LiveDetection], str | None] | None = None  # starts a diagnosis: its id

    def register_model(self, satellite: str, scenario: str, epoch_ns: int | None, from_run: bool = False) -> None:
        """Tell the twin of ``satellite`` its scenario and when its route started (``from_run``: with each run of
        telemetry after a gap, like the demo emulator started with the server)."""
        with self._lock:
            self._models[satellite] = (scenario, epoch_ns, from_run)
            self._twins.pop(satellite, None)

    def submit(self, satellite: str, dictionary_name: str, batches: Sequence[SampleBatch]) -> None:
        """Queue committed batches of ``satellite`` for its twin (never waits)."""
        self._inbox.put((satellite, dictionary_name, list(batches), self._clock()))

    def submit_archived(self, satellite: str, dictionary_name: str, t0_ns: int, t1_ns: int) -> None:
        """Queue the archived telemetry of ``satellite`` in [t0_ns, t1_ns] for its twin (never waits): a backfill
        the worker reads back from the archive BACKFILL_WINDOW_S at a time."""
        with self._lock:
            self._backfills += 1
        self._inbox.put(_Backfill(satellite, dictionary_name, t0_ns, t1_ns))

    def start(self, recover: bool = True) -> None:
        """Start the worker thread (after recovering the twins from the archive)."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(recover,), name="live-twins", daemon=True)
        self._writer = threading.Thread(target=self._write_loop, name="live-twins-archive", daemon=True)
        self._writer.start()
        self._thread.start()

    def stop(self) -> None:
        """Finish what is queued, archive pending residuals, stop the worker and the writer."""
        self._stop.set()
        if self._thread is not None:
            self._inbox.put(threading.Event())  # wakes a worker waiting on an empty inbox (it looks every 0.5 s)
            self._thread.join(30.0)
            self._thread = None
        if self._writer is not None:
            self._writes.put(None)
            self._writer.join(30.0)
            self._writer = None

    def drain(self, timeout_s: float = 30.0) -> None:
        """Wait until everything submitted so far, backfills to their end, has been processed and archived (tests,
        benchmarks)."""
        deadline = time.monotonic() + timeout_s
        while True:
            done = threading.Event()
            self._inbox.put(done)
            done.wait(max(deadline - time.monotonic(), 0.0))
            with self._lock:
                if not self._backfills or time.monotonic() >= deadline:
                    return

    # --- queries ---------------------------------------------------------------------------------
    def backlog(self) -> dict[str, int]:
        """Satellites with a twin, committed batches waiting for their twin, residual uploads waiting for the
        archive writer (a growing figure means the twins or the writer do not keep up)."""
        return {
            "satellites": len(self._twins),
            "batches_waiting": self._inbox.qsize(),
            "residual_uploads_waiting": self._writes.qsize(),
        }

    def satellites(self) -> list[str]:
        """Satellites that have a twin."""
        with self._lock:
            return sorted(self._twins)

    def recent(self, satellite: str) -> dict[str, Any] | None:
        """The satellite twin's recent samples (LiveTwin.recent), None without a twin."""
        with self._lock:
            twin = self._twins.get(satellite)
            return None if twin is None else twin.recent()

    def state(self, satellite: str) -> dict[str, Any] | None:
        """Public state of the twin of ``satellite`` (None if it has none)."""
        with self._lock:
            twin = self._twins.get(satellite)
            return None if twin is None else twin.public(self._clock())

    # --- worker ----------------------------------------------------------------------------------
    def _run(self, recover: bool) -> None:
        if recover:
            try:
                self.recover()
            except Exception:  # a damaged archive must not stop the live twins of new telemetry
                log.exception("live twins: recovery from the archive failed")
        while not (self._stop.is_set() and self._inbox.empty()):
            try:
                items = [self._inbox.get(timeout=0.5)]
            except queue.Empty:
                self._tick()
                continue
            while len(items) < MAX_TAKEN:  # everything queued meanwhile: see _take
                try:
                    items.append(self._inbox.get_nowait())
                except queue.Empty:
                    break
            self._take(items)
            self._tick()
        self._flush_all()

    def _take(self, items: list[_Inbox]) -> None:
        """Process queued items in order, the batches of one satellite queued one after another in one call (a twin
        costs ~1 ms of numpy overhead per call whatever the samples: a worker that fell behind catches up instead
        of falling further behind, and each satellite's new samples are compared at once)."""
        group: _Group = {}
        for item in items:
            if isinstance(item, tuple):
                satellite, dictionary_name, batches, arrived = item
                taken, first = group.get((satellite, dictionary_name), ([], arrived))
                group[(satellite, dictionary_name)] = (taken + batches, first)
                continue
            self._process_all(group)
            group = {}
            if isinstance(item, threading.Event):
                self._flush_all()
                self._writes.put(item)  # set by the writer once the flushed residuals are committed
            else:
                try:
                    self._backfill(item)
                except Exception:
                    log.exception("live twin of %s failed on an archived span", item.satellite)
        self._process_all(group)

    def _process_all(self, group: _Group) -> None:
        for (satellite, dictionary_name), (batches, arrived) in group.items():
            try:
                self._process(satellite, dictionary_name, batches, arrived)
            except Exception:
                log.exception("live twin of %s failed on a batch", satellite)

    def _twin(self, satellite: str, dictionary_name: str) -> LiveTwin | None:
        twin = self._twins.get(satellite)
        if twin is not None and twin.mapping.dictionary == dictionary_name:
            return twin
        mapping = next((m for f in self._folders if (m := shipped_mapping(dictionary_name, f)) is not None), None)
        if mapping is None:
            return twin
        dictionary = self._dictionary(dictionary_name)
        mapping.check(dictionary)
        quantum = calibration_step(dictionary, mapping.wheel_speeds_rad_s[0]) if mapping.wheel_speeds_rad_s else 0.0
        scenario, epoch_ns, from_run = self._models.get(satellite, (mapping.acs_model, None, False))
        model = None
        if scenario is not None:
            from sim_core import scenario_library

            model = scenario_library.get(scenario)
            if epoch_ns is None and not from_run:
                epoch_ns = self._first_telemetry_ns(satellite)
        with self._lock:
            self._twins[satellite] = twin = LiveTwin(
                satellite,
                mapping,
                model,
                epoch_ns,
                epoch_from_run=from_run,
                wheel_quantum_rad_s=quantum,
                stale_after_s=self.stale_after_s,
            )
        return twin

    def _first_telemetry_ns(self, satellite: str) -> int | None:
        archive = self._archive()
        for row in archive.satellites(exclude_apids=(TWIN_APID,)) if archive is not None else []:
            if row["name"] == satellite:
                return row["first_t_ns"]
        return None

    def _process(self, satellite: str, dictionary_name: str, batches: list[SampleBatch], arrived: float) -> None:
        try:
            twin = self._twin(satellite, dictionary_name)
        except ValueError as exc:
            log.warning("live twin of %s: %s", satellite, exc)
            return
        if twin is None:
            return
        with self._lock:
            rows = twin.observe(batches, arrived)
            self._detected.setdefault(satellite, []).extend(twin.detections)
            twin.detections.clear()
        self.latencies_s.append(self._clock() - arrived)
        if rows is not None and rows["t_utc_ns"].size:
            self._pending.setdefault(satellite, []).append(rows)
            self._publish_rows(satellite, rows)
        if self._clock() - self._flushed_at.get(satellite, 0.0) >= ARCHIVE_PERIOD_S:
            self._flush(satellite)
        self._start_diagnoses(satellite, twin)
        self._stale_published.discard(satellite)
        self._hub.publish("twin", twin.public(self._clock()))

    def _backfill(self, item: _Backfill) -> None:
        """Read, decode and fly the first BACKFILL_WINDOW_S of an archived span; queue the rest behind what waits."""
        from telemetry.decoding import decode_stream

        archive = self._archive()
        end = min(item.t1_ns, item.t0_ns + int(BACKFILL_WINDOW_S * NS_PER_S))
        rest = _Backfill(item.satellite, item.dictionary, end + 1, item.t1_ns) if end < item.t1_ns else None
        try:
            if archive is not None:
                packets = archive.replay(item.satellite, item.t0_ns, end)
                data = b"".join(p for _, p in packets)
                decoded = decode_stream(data, self._dictionary(item.dictionary), source="twin backfill")
                self._process(item.satellite, item.dictionary, decoded.batches, self._clock())
        finally:
            if rest is not None and not self._stop.is_set():  # a stopping server drops the rest (it is archived)
                self._inbox.put(rest)
            else:
                with self._lock:
                    self._backfills -= 1

    def _start_diagnoses(self, satellite: str, twin: LiveTwin) -> None:
        """Detections followed by POST_ALARM_S of telemetry: archive what is pending, then ``on_detection``."""
        if self._recovering:
            return
        newest = twin.state.telemetry_utc_ns or 0
        ready = [d for d in self._detected.get(satellite, []) if newest - d.t_utc_ns >= POST_ALARM_S * NS_PER_S]
        if not ready:
            return
        self._detected[satellite] = [d for d in self._detected[satellite] if d not in ready]
        for det in ready:
            self._flush(satellite)
            archived = threading.Event()  # set by the writer once twin_anomaly (the alarm) is committed
            self._writes.put(archived)
            run_id = None
            if self.on_detection is not None and twin.model is not None:
                live = LiveDetection(satellite, twin.mapping.dictionary, twin.model, det, newest, archived)
                try:
                    run_id = self.on_detection(live)
                except Exception:  # the twin goes on; the alarm stays for the operator
                    log.exception("live twin of %s: the automatic diagnosis did not start", satellite)
            if twin.state.detection is not None and twin.state.detection["utc"] == _iso(det.t_utc_ns):
                twin.state.detection["diagnosis_id"] = run_id

    def _publish_rows(self, satellite: str, rows: dict[str, np.ndarray]) -> None:
        t = rows["t_utc_ns"].tolist()
        for name, values in rows.items():
            if name != "t_utc_ns" and self._hub.wants_any(f"parameters/{name}"):
                self._hub.publish(
                    f"parameters/{name}", {"satellite": satellite, "t_utc_ns": t, "values": values.tolist()}
                )

    def _tick(self) -> None:
        """Publish the transition to stale once per satellite; archive residuals that waited long enough (at most
        every TICK_S)."""
        now = self._clock()
        if now - self._ticked_at < TICK_S:
            return
        self._ticked_at = now
        for satellite, twin in list(self._twins.items()):
            public = twin.public(now)
            if public["stale"] and public["telemetry_utc"] and satellite not in self._stale_published:
                self._stale_published.add(satellite)
                self._hub.publish("twin", public)
            if self._pending.get(satellite) and now - self._flushed_at.get(satellite, 0.0) >= ARCHIVE_PERIOD_S:
                self._flush(satellite)

    def _flush_all(self) -> None:
        for satellite in list(self._pending):
            self._flush(satellite)

    def _flush(self, satellite: str) -> None:
        """Hand the satellite's pending residuals to the archive writer."""
        parts = self._pending.pop(satellite, [])
        self._flushed_at[satellite] = self._clock()
        if parts:
            self._writes.put((satellite, parts))

    def _write_loop(self) -> None:
        """Archive-writer thread: commit residuals, everything queued at once in one transaction (group commit: one
        fsync for every satellite that flushed meanwhile); a marker Event is set once everything queued before it
        is committed, None stops the thread."""
        stop = False
        while not stop:
            group: list[tuple[str, list[dict[str, np.ndarray]]]] = []
            item = self._writes.get()
            while isinstance(item, tuple):
                group.append(item)
                if len(group) >= GROUP_MAX_UPLOADS:
                    item = False  # commit this group, the rest in the next
                    break
                try:
                    item = self._writes.get_nowait()
                except queue.Empty:
                    item = False  # nothing more queued: commit the group
            self._write(group)
            if isinstance(item, threading.Event):
                item.set()
            stop = item is None

    def _write(self, group: list[tuple[str, list[dict[str, np.ndarray]]]]) -> None:
        from telemetry.archive import PacketBatch, PendingUpload

        archive = self._archive()
        if archive is None or not group:
            return
        uploads, spans = [], []
        for satellite, parts in group:
            columns = {n: np.concatenate([p[n] for p in parts]) for n in parts[0]}
            t = columns.pop("t_utc_ns")
            n = t.size
            batch = PacketBatch(TWIN_APID, t, np.zeros(n, np.int64), b"", np.zeros(n, np.int64), columns)
            n_wheels = sum(1 for name in columns if name.startswith("twin_wheel"))
            uploads.append(PendingUpload(satellite, [batch], "live twin", "live twin", residual_limits(n_wheels)))
            spans.append((satellite, int(t.min()), int(t.max())))
        try:
            archive.ingest_many(uploads)
            done = spans
        except Exception:  # one bad upload must not cost the others theirs: one transaction each
            log.exception("live twins: group commit failed, committing one satellite at a time")
            done = [span for upload, span in zip(uploads, spans) if self._write_one(archive, upload)]
        if self._on_archived is not None:
            for satellite, t0, t1 in done:
                self._on_archived(satellite, t0, t1)

    @staticmethod
    def _write_one(archive: TelemetryArchive, upload: PendingUpload) -> bool:
        try:
            archive.ingest_many([upload])
        except Exception:
            log.exception("live twin of %s: residuals not archived", upload.satellite)
            return False
        return True

    def recover(self) -> None:
        """Re-create the twins of every archived satellite with a shipped mapping from its newest RECENT_S."""
        from telemetry.decoding import decode_stream

        archive = self._archive()
        if archive is None:
            return
        for row in archive.satellites(exclude_apids=(TWIN_APID,)):
            if row["last_t_ns"] is None or row["name"] in self._twins:
                continue
            archived = set(archive.parameters(row["name"]))
            mapping = next((m for f in self._folders if (m := mapping_for_parameters(archived, f)) is not None), None)
            if mapping is None:
                continue
            t1 = int(row["last_t_ns"])
            packets = archive.replay(row["name"], t1 - int(RECENT_S * NS_PER_S), t1)
            decoded = decode_stream(
                b"".join(p for _, p in packets), self._dictionary(mapping.dictionary), source="twin recovery"
            )
            self._recovering = True  # detections in what was archived before the restart had their diagnosis
            try:
                self._process(row["name"], mapping.dictionary, decoded.batches, t1 / 1e9)
            finally:
                self._recovering = False
                self._detected.pop(row["name"], None)
