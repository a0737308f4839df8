"""The backend's seam to the telemetry package: archive, decoding, limits, passes, live stream.

Telemetry modules are built alongside the server; the gateway wires each one that is importable
and answers 503 naming the missing module for the others, so routes never change. Ingest is the
pipeline decode → validate → archive (with limits) → publish to the live hub; downsampled sample
queries are cached per satellite until its next ingest.
"""

from __future__ import annotations

import importlib.util
import threading
from collections import OrderedDict
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


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def packet_batches(sample_batches: list[Any]) -> list[Any]:
    """Decoded SampleBatches → the archive's PacketBatches (raw packets kept byte-exact)."""
    from telemetry.archive import PacketBatch

    out = []
    for b in sample_batches:
        n = len(b.t_utc_ns)
        raw = b.packets.tobytes() if b.packets is not None else b""
        lengths = np.full(n, b.packets.shape[1] if b.packets is not None else 0, dtype=np.int64)
        out.append(PacketBatch(b.apid, b.t_utc_ns, np.asarray(b.sequence_count, dtype=np.int64), raw,
                               lengths, b.values))
    return out


class TelemetryGateway:
    """Reaches telemetry through one object; knows which parts are present."""

    def __init__(self, settings: Settings, hub: LiveHub) -> None:
        self._settings, self._hub = settings, hub
        self.dictionaries = DictionaryCatalogue(settings.data_dir / "dictionaries")
        self._archive: Any = None
        self._cache: OrderedDict[tuple, dict[str, Any]] = OrderedDict()
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
        from telemetry import ground_files  # type: ignore[attr-defined]

        dictionary = self.dictionaries.load(dictionary_name)
        decoded = ground_files.read_ground_file(data, kind, dictionary, source=source)
        return self._archive_and_publish(satellite, decoded, dictionary, source, uploaded_by)

    def _archive_and_publish(self, satellite: str, decoded: Any, dictionary: Any, source: str,
                             uploaded_by: str) -> dict[str, Any]:
        from telemetry.limits import dictionary_limits

        result = self.archive.ingest(satellite, packet_batches(decoded.batches), source=source,
                                     uploaded_by=uploaded_by, limits=dictionary_limits(dictionary))
        self._invalidate(satellite)
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
        from telemetry import passes  # type: ignore[attr-defined]

        tle_id, line1, line2 = self.archive.latest_tle(satellite, before_ns=t1_ns)
        site = self.archive.ground_station(station)
        predicted = passes.predict_passes(line1, line2, site, t0_ns, t1_ns)
        ids = set(self.archive.save_passes(satellite, station, predicted, tle_id=tle_id))
        return [p for p in self.archive.passes(satellite, t0_ns, t1_ns) if p.id in ids]

    def _invalidate(self, satellite: str) -> None:
        with self._cache_lock:
            for key in [k for k in self._cache if k[0] == satellite]:
                del self._cache[key]

    def samples(self, satellite: str, name: str, t0_ns: int, t1_ns: int, max_points: int) -> dict[str, Any]:
        """Samples of one parameter in [t0_ns, t1_ns], min/max-downsampled to max_points (cached)."""
        key = (satellite, name, t0_ns, t1_ns, max_points)
        with self._cache_lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                return hit
        t, v = self.archive.read_parameter(satellite, name, t0_ns, t1_ns)
        keep = minmax_indices(v, max_points) if v.size else np.arange(0)
        answer = {"satellite": satellite, "name": name, "total_points": int(t.size),
                  "t_utc_ns": t[keep].tolist(), "values": np.asarray(v[keep], dtype=float).tolist()}
        with self._cache_lock:
            self._cache[key] = answer
            if len(self._cache) > SAMPLE_CACHE_ENTRIES:
                self._cache.popitem(last=False)
        return answer


def dictionary_name_of(dictionary: Any) -> str:
    """Display name of a loaded dictionary."""
    return str(getattr(dictionary, "name", ""))
