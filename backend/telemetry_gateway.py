"""The backend's seam to the telemetry package: archive, decoding, limits, passes, live stream.

Telemetry modules are built alongside the server; the gateway wires each one that is importable
and answers 503 naming the missing module for the others, so routes never change. Ingest is the
pipeline decode → validate → archive (with limits) → publish to the live hub; downsampled sample
queries are cached per satellite until its next ingest.
"""

from __future__ import annotations

import asyncio
import importlib.util
import json
import multiprocessing as mp
import queue
import threading
import time
from collections import OrderedDict, deque
from dataclasses import asdict
from typing import Any

import numpy as np

from backend.dictionary_catalogue import DictionaryCatalogue
from backend.downsampling import minmax_indices
from backend.errors import ApiError
from backend.live_hub import LiveHub
from backend.settings import Settings

__all__ = ["TelemetryGateway", "COMPONENT_MODULES", "SAMPLE_CACHE_ENTRIES"]

COMPONENT_MODULES = {
    "archive": "telemetry.archive.store",
    "queries": "telemetry.queries",
    "decoding": "telemetry.decoding",
    "dictionary": "telemetry.dictionary",
    "limits": "telemetry.limits",
    "ground_files": "telemetry.ground_files",
    "passes": "telemetry.passes",
    "live": "telemetry.live",
    "emulator": "telemetry.emulator",
    "engine": "sim_core.engine",
}
SAMPLE_CACHE_ENTRIES = 4096  # distinct (parameter, window, max_points) answers kept between ingests
LIVE_START_TIMEOUT_S = 120.0  # spawn + imports of the ingest process on a loaded 2-core machine
LIVE_STOP_TIMEOUT_S = 30.0  # the ingest process archives its pending batches before it exits
HOT_S = 5.0  # live data younger than this may still wait for the archive flush (every 0.5 s): no caching


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


class TelemetryGateway:
    """Reaches telemetry through one object; knows which parts are present."""

    def __init__(self, settings: Settings, hub: LiveHub) -> None:
        self._settings, self._hub = settings, hub
        self.dictionaries = DictionaryCatalogue(settings.data_dir / "dictionaries")
        self._archive: Any = None
        self._live: Any = None
        self._outbox: Any = None
        self._stop_live: Any = None
        self._relay: threading.Thread | None = None
        self._live_stats: dict[str, Any] = {}
        self.live_port: int | None = None
        self._cache: OrderedDict[tuple, bytes] = OrderedDict()
        self._generation: dict[str, int] = {}
        self._hot: deque[tuple[float, str, int]] = deque()
        self._cache_lock = threading.Lock()

    def components(self) -> dict[str, bool]:
        """Which optional modules are importable in this build."""
        return {name: _importable(module) for name, module in COMPONENT_MODULES.items()}

    def require(self, component: str) -> None:
        """503 naming the module when ``component`` has not landed in this build."""
        if not _importable(COMPONENT_MODULES[component]):
            raise ApiError(503, f"{COMPONENT_MODULES[component]} is not available in this build",
                           field=component)

    @property
    def archive(self) -> Any:
        """The telemetry.archive.Archive over the server's database (503 if not built)."""
        if self._archive is None:
            self.require("archive")
            raise ApiError(503, "archive not started", "archive")
        return self._archive

    def start(self) -> None:
        """Open (and migrate) the archive on the server's database URL."""
        if _importable(COMPONENT_MODULES["archive"]):
            from telemetry.archive import Archive

            self._archive = Archive(self._settings.resolved_database_url())

    async def start_live(self) -> None:
        """Start the live-ingest process (telemetry.live) and the thread relaying it to the hub."""
        if not (self._settings.live_enabled and self._archive is not None and _importable(COMPONENT_MODULES["live"])):
            return
        from backend.live_ingest import OUTBOX_MESSAGES, run_ingest_process

        self.dictionaries.load(self._settings.live_dictionary)  # fail here, naming the dictionary
        ctx = mp.get_context("spawn")
        self._outbox, self._stop_live = ctx.Queue(OUTBOX_MESSAGES), ctx.Event()
        args = (self._settings.resolved_database_url(), str(self._settings.data_dir / "dictionaries"),
                self._settings.live_dictionary, self._settings.live_satellite, self._settings.host,
                self._settings.telemetry_port, self._outbox, self._stop_live)
        self._live = ctx.Process(target=run_ingest_process, args=args, name="acs-twin-live-ingest", daemon=True)
        self._live.start()
        kind, port = await asyncio.to_thread(self._outbox.get, True, LIVE_START_TIMEOUT_S)
        self.live_port = int(port)
        self._relay = threading.Thread(target=self._relay_loop, name="live-relay", daemon=True)
        self._relay.start()

    def _relay_loop(self) -> None:
        satellite = self._settings.live_satellite
        while True:
            try:
                kind, payload = self._outbox.get(timeout=0.2)
            except queue.Empty:
                if self._stop_live.is_set() and not self._live.is_alive():
                    return
                continue
            if kind == "stats":
                self._live_stats = payload
                continue
            if len(payload.t_utc_ns):
                self._hot.append((time.monotonic(), satellite, int(payload.t_utc_ns.min())))
            self._invalidate_batches(satellite, [payload])
            self._publish(satellite, [payload], 0)

    async def stop_live(self) -> None:
        """Stop the ingest process (it archives what is pending first) and the relay thread."""
        if self._live is None:
            return
        self._stop_live.set()
        await asyncio.to_thread(self._live.join, LIVE_STOP_TIMEOUT_S)
        if self._live.is_alive():
            self._live.terminate()
        await asyncio.to_thread(self._relay.join, LIVE_STOP_TIMEOUT_S)
        self._live = None

    def live_stats(self) -> dict[str, Any]:
        """Tallies of the live stream (packets received/archived, errors), empty when off."""
        return {} if self._live is None else {"port": self.live_port, **self._live_stats}

    def close(self) -> None:
        """Release the archive's connections."""
        if self._archive is not None:
            self._archive.close()
            self._archive = None

    def ingest_packets(self, satellite: str, data: bytes, dictionary_name: str, source: str,
                       uploaded_by: str) -> dict[str, Any]:
        """Decode a CCSDS byte stream, archive it with limit checking, publish it; the ingest report."""
        self.require("decoding")
        from telemetry.decoding import decode_stream

        dictionary = self.dictionaries.load(dictionary_name)
        decoded = decode_stream(data, dictionary, source=source)
        return self._archive_and_publish(satellite, decoded, dictionary, source, uploaded_by)

    def ingest_ground_file(self, satellite: str, data: bytes, kind: str, dictionary_name: str,
                           source: str, uploaded_by: str) -> dict[str, Any]:
        """Archive a CSV or JSONL ground file (telemetry.ground_files) like a packet upload."""
        self.require("ground_files")
        from telemetry import ground_files

        dictionary = self.dictionaries.load(dictionary_name)
        read = ground_files.read_ground_csv if kind == "csv" else ground_files.read_ground_jsonl
        decoded = read(data, dictionary, source=source)
        return self._archive_and_publish(satellite, decoded, dictionary, source, uploaded_by)

    def _archive_and_publish(self, satellite: str, decoded: Any, dictionary: Any, source: str,
                             uploaded_by: str) -> dict[str, Any]:
        from telemetry.limits import dictionary_limits

        result = self.archive.ingest_decoded(satellite, decoded, uploaded_by=uploaded_by,
                                             limits=dictionary_limits(dictionary))
        self._invalidate_batches(satellite, decoded.batches)
        if not result.duplicate_upload:
            self._publish(satellite, decoded.batches, result.alarm_events)
        return {"satellite": satellite, "dictionary": dictionary_name_of(dictionary),
                "archive": result.as_report(), "decoding": decoded.report.to_dict()}

    def _publish(self, satellite: str, batches: list[Any], alarm_events: int) -> None:
        for batch in batches:
            for name, column in batch.values.items():
                topic = f"parameters/{name}"
                if self._hub.wants_any(topic):
                    self._hub.publish(topic, {"satellite": satellite, "t_utc_ns": batch.t_utc_ns.tolist(),
                                              "values": np.asarray(column, dtype=float).tolist()})
        if alarm_events and self._hub.wants_any("alarms"):
            alarms = self.archive.alarms(satellite)
            self._hub.publish("alarms", {"satellite": satellite,
                                         "alarms": [asdict(a) for a in alarms]})

    def predict_passes(self, satellite: str, station: str, t0_ns: int, t1_ns: int) -> list[Any]:
        """Passes from the newest TLE over ``station`` in [t0_ns, t1_ns] (telemetry.passes), stored."""
        self.require("passes")
        from telemetry import passes

        if t1_ns <= t0_ns:
            raise ValueError("end: must be after start")
        tle_id, line1, line2 = self.archive.latest_tle(satellite, before_ns=t1_ns)
        site = self.archive.ground_station(station)
        predicted = passes.predict_passes(line1, line2, site.lat_deg, site.lon_deg, site.alt_m,
                                          site.min_elevation_deg, t0_ns, (t1_ns - t0_ns) / 86_400e9)
        ids = set(self.archive.save_passes(satellite, station, predicted.rows(), tle_id=tle_id))
        return [p for p in self.archive.passes(satellite, t0_ns, t1_ns) if p.id in ids]

    def record_reception(self, satellite: str, t0_ns: int, t1_ns: int) -> list[Any]:
        """Recount what was received in each pass of [t0_ns, t1_ns] (completeness from gaps)."""
        self.require("passes")
        from telemetry import passes

        return passes.record_reception(self.archive, satellite, self.archive.passes(satellite, t0_ns, t1_ns))

    def pass_summary(self, satellite: str, pass_id: int) -> dict[str, Any]:
        """Reception, per-parameter statistics and alarms of one pass (telemetry.queries)."""
        self.require("queries")
        from telemetry import queries

        return queries.pass_summary(self.archive, satellite, pass_id)

    def export_table(self, satellite: str, names: list[str], t0_ns: int, t1_ns: int) -> Any:
        """Wide pyarrow table of the parameters (telemetry.queries.export_table)."""
        self.require("queries")
        from telemetry import queries

        return queries.export_table(self.archive, satellite, names, t0_ns, t1_ns)

    def _invalidate(self, satellite: str, t0_ns: int = -(2**63), t1_ns: int = 2**63 - 1) -> None:
        """Forget cached answers of ``satellite`` whose window overlaps new data in [t0_ns, t1_ns]."""
        with self._cache_lock:
            self._generation[satellite] = self._generation.get(satellite, 0) + 1
            for key in [k for k in self._cache if k[0] == satellite and k[2] <= t1_ns and k[3] >= t0_ns]:
                del self._cache[key]

    def _invalidate_batches(self, satellite: str, batches: list[Any]) -> None:
        spans = [(int(b.t_utc_ns.min()), int(b.t_utc_ns.max())) for b in batches if len(b.t_utc_ns)]
        if spans:
            self._invalidate(satellite, min(s[0] for s in spans), max(s[1] for s in spans))

    def _hot_start_ns(self, satellite: str) -> int | None:
        """Earliest time of live data of ``satellite`` received within HOT_S (maybe not archived yet)."""
        while self._hot and time.monotonic() - self._hot[0][0] > HOT_S:
            self._hot.popleft()
        starts = [t for _, sat, t in list(self._hot) if sat == satellite]
        return min(starts) if starts else None

    def cached_samples(self, satellite: str, name: str, t0_ns: int, t1_ns: int, max_points: int) -> bytes | None:
        """The JSON answer of :meth:`samples_json` if cached (no database access; safe in the event loop)."""
        key = (satellite, name, t0_ns, t1_ns, max_points)
        with self._cache_lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
            return hit

    def samples_json(self, satellite: str, name: str, t0_ns: int, t1_ns: int, max_points: int) -> bytes:
        """JSON of one parameter's samples in [t0_ns, t1_ns], min/max-downsampled to max_points (cached)."""
        hit = self.cached_samples(satellite, name, t0_ns, t1_ns, max_points)
        if hit is not None:
            return hit
        with self._cache_lock:
            generation = self._generation.get(satellite, 0)
        t, v = self.archive.read_parameter(satellite, name, t0_ns, t1_ns)
        keep = minmax_indices(v, max_points) if v.size else np.arange(0)
        values = np.asarray(v[keep], dtype=float)
        listed = values.tolist() if np.all(np.isfinite(values)) else [x if np.isfinite(x) else None for x in values]
        answer = json.dumps({"satellite": satellite, "name": name, "total_points": int(t.size),
                             "t_utc_ns": t[keep].tolist(), "values": listed}).encode()
        hot = self._hot_start_ns(satellite)
        with self._cache_lock:
            if self._generation.get(satellite, 0) == generation and (hot is None or t1_ns < hot):
                self._cache[(satellite, name, t0_ns, t1_ns, max_points)] = answer
                if len(self._cache) > SAMPLE_CACHE_ENTRIES:
                    self._cache.popitem(last=False)
        return answer


def dictionary_name_of(dictionary: Any) -> str:
    """Display name of a loaded dictionary."""
    return str(getattr(dictionary, "name", ""))
