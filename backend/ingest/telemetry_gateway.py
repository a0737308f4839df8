"""The backend's seam to the telemetry package: archive, decoding, limits, passes, live stream.

Telemetry is a hard dependency of the backend (never switched on by importability); the archive is
handed out typed as the :class:`~backend.ingest.ports.TelemetryArchive` Protocol. Ingest is the
pipeline decode → validate → archive (with limits) → publish to the live hub; downsampled sample
queries are cached per satellite until its next ingest.

Fan-out of live samples, one policy: a producer never waits on a consumer; newest wins: a full
bounded queue drops its oldest items, counts them and tells its consumer the count, so a consumer
that fell behind resumes at the present (an operator watches what the satellite does now); the
archive, not the fan-out, is the lossless record: telemetry the link accepted is archived whatever a
queue dropped. Every ingested batch (upload or live link) is published once to the hub. The three
queues: telemetry.live's subscriber queue (the next message taken carries the count of packets lost
before it), the ingest process's outbox (``forward_dropped`` in the live stats) and each WebSocket
client's deque in the hub (``dropped`` so far, in every batch sent).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np
import orjson

from backend.core.errors import ApiError
from backend.core.settings import Settings
from backend.core.time import BOUND_NS
from backend.ingest.dictionary_catalogue import DictionaryCatalogue
from backend.ingest.live_hub import LiveHub
from backend.ingest.ports import TelemetryArchive
from backend.ingest.sample_cache import SampleCache
from backend.ingest.upload_decoder import PacketFileJob, RedecodeJob, UploadDecoder, archive_packet_file
from telemetry import decoding, ground_files
from telemetry.archive import Archive
from telemetry.archive.records import IngestResult, PassRecord
from telemetry.dictionary import Dictionary
from telemetry.downsampling import minmax_indices
from telemetry.ingest_report import DecodeResult, SampleBatch
from telemetry.limits import dictionary_limits

if TYPE_CHECKING:
    import pyarrow as pa

    from backend.ingest.live_link import LiveChild, LiveLink

__all__ = ["COMPONENTS", "TelemetryGateway"]

Result = TypeVar("Result")

# the parts /health lists; all are hard dependencies of the backend, so all are present
COMPONENTS = (
    "archive",
    "queries",
    "decoding",
    "dictionary",
    "limits",
    "ground_files",
    "passes",
    "live",
    "emulator",
    "engine",
)


class TelemetryGateway:
    """Reaches telemetry through one object: the archive, ingest, passes, queries and the live link."""

    def __init__(self, settings: Settings, hub: LiveHub) -> None:
        self._settings, self._hub = settings, hub
        self.dictionaries = DictionaryCatalogue(settings.data_dir / "dictionaries")
        self._archive: Archive | None = None
        self._upload_decoder: UploadDecoder | None = None
        self._live: LiveLink | None = None
        self._live_spawned: LiveChild | None = None  # the ingest process acs-twin serve spawned ahead
        self._samples = SampleCache()
        self._committed: list[Callable[[str, str, list[SampleBatch]], None]] = []
        self._backfilled: list[Callable[[str, str, int, int], None]] = []

    def on_commit(self, listener: Callable[[str, str, list[SampleBatch]], None]) -> None:
        """Call ``listener(satellite, dictionary_name, batches)`` for every upload the archive committed and every
        live batch (the ingest process commits those within telemetry.live.ARCHIVE_INTERVAL_S); the live twins'
        one input path."""
        self._committed.append(listener)

    def on_backfill(self, listener: Callable[[str, str, int, int], None]) -> None:
        """Call ``listener(satellite, dictionary_name, t0_ns, t1_ns)`` for every upload committed without handing its
        samples over (a file of more than one decode chunk): the live twins read that span back from the archive."""
        self._backfilled.append(listener)

    def opened_archive(self) -> TelemetryArchive | None:
        """The archive once started, else None (no 503: for background workers)."""
        return self._archive

    def invalidate(self, satellite: str, t0_ns: int, t1_ns: int) -> None:
        """Forget cached sample answers of ``satellite`` touching [t0_ns, t1_ns] (derived parameters archived)."""
        self._samples.invalidate(satellite, t0_ns, t1_ns)

    def components(self) -> dict[str, bool]:
        """The telemetry parts of this build (all of them: they are dependencies, not plug-ins)."""
        return dict.fromkeys(COMPONENTS, True)

    @property
    def archive(self) -> TelemetryArchive:
        """The telemetry archive over the server's database (503 until started)."""
        return self._opened()

    def _opened(self) -> Archive:
        if self._archive is None:
            raise ApiError(503, "archive not started", "archive")
        return self._archive

    def start(self) -> None:
        """Open (and migrate) the archive on the server's database URL."""
        self._archive = Archive(self._settings.resolved_database_url())
        self._upload_decoder = UploadDecoder(self._archive.url, self._settings.data_dir / "dictionaries")

    def adopt_live_ingest(self, child: LiveChild) -> None:
        """Use the live-ingest process ``child`` (spawned ahead by ``acs-twin serve``, its start-up beside the
        server's) for the live link, instead of spawning one in :meth:`start_live`."""
        self._live_spawned = child

    async def start_live(self) -> None:
        """Start the live link (backend.ingest.live_link: the ingest process and the relay of its batches)."""
        if not (self._settings.live_enabled and self._archive is not None):
            return
        from backend.ingest.live_link import LiveLink

        self.dictionaries.load(self._settings.live_dictionary)  # fail here, naming the dictionary
        self._live = LiveLink(self._settings, self._on_live_batch, self._live_spawned)
        self._live_spawned = None
        try:
            await self._live.start()
        except RuntimeError:
            self._live = None
            raise

    @property
    def live_port(self) -> int | None:
        """The port the live link listens on (None while it does not)."""
        return None if self._live is None else self._live.port

    def _on_live_batch(self, satellite: str, batch: SampleBatch) -> None:
        """A batch of ``satellite`` the ingest process decoded and archives (within telemetry.live.ARCHIVE_INTERVAL_S):
        caches, hub, commit listeners (called from the link's relay thread, in arrival order)."""
        if len(batch.t_utc_ns):
            self._samples.mark_live(satellite, int(batch.t_utc_ns.min()))
        self._invalidate_batches(satellite, [batch])
        self._publish(satellite, [batch], 0)
        for listener in self._committed:
            listener(satellite, self._settings.live_dictionary, [batch])

    async def stop_live(self) -> None:
        """Stop the live link (the ingest process archives what is pending first)."""
        if self._live is not None:
            await self._live.stop()
            self._live = None

    def live_stats(self) -> dict[str, Any]:
        """Tallies of the live stream (packets received/archived, errors), empty when off."""
        return {} if self._live is None else self._live.stats()

    def close(self) -> None:
        """Stop the upload decoder (a file mid-decode is not archived) and release the archive's connections."""
        if self._upload_decoder is not None:
            self._upload_decoder.stop()
            self._upload_decoder = None
        if self._archive is not None:
            self._archive.close()
            self._archive = None

    def ingest_packets(
        self, satellite: str, data: bytes, dictionary_name: str, source: str, uploaded_by: str
    ) -> dict[str, Any]:
        """Decode a CCSDS byte stream, archive it with limit checking, publish it; the ingest report."""
        dictionary = self.dictionaries.load(dictionary_name)
        decoded = decoding.decode_stream(data, dictionary, source=source)
        return self._archive_and_publish(satellite, decoded, dictionary_name, source, uploaded_by)

    def ingest_packet_file(
        self, satellite: str, path: Path, dictionary_name: str, source: str, uploaded_by: str
    ) -> dict[str, Any]:
        """Decode a CCSDS packet file on disk chunk by chunk (bounded memory) and archive it as one upload
        (blocking: call from a thread). A file of more than one chunk is decoded by the upload decoder
        process (backend.ingest.upload_decoder), a smaller one in this thread.

        Subscribers and commit listeners get the batches of a file of one chunk (telemetry.packet_files
        .CHUNK_OCTETS); a longer file is an archive backfill: archived, caches invalidated, passes made from
        its data, not replayed to live subscribers ("published": false in the report), and its span handed to the
        backfill listeners (the live twins read it back from the archive).
        """
        from telemetry.packet_files import CHUNK_OCTETS

        dictionary = self.dictionaries.load(dictionary_name)  # a bad name or definition: 422 before any decode
        job = PacketFileJob(path, satellite, dictionary_name, source, uploaded_by)
        if path.stat().st_size > CHUNK_OCTETS:
            outcome = self.upload_decoder.run(job)
        else:
            outcome = archive_packet_file(self._opened(), job, dictionary)
        if outcome.span_ns is not None:
            self._samples.invalidate(satellite, *outcome.span_ns)
        if not outcome.result.duplicate_upload and outcome.chunks == 1:
            self._publish(satellite, outcome.first_batches, outcome.result.alarm_events)
            for listener in self._committed:
                listener(satellite, dictionary_name, outcome.first_batches)
        if not outcome.result.duplicate_upload and outcome.chunks > 1 and outcome.span_ns is not None:
            for backfill in self._backfilled:
                backfill(satellite, dictionary_name, *outcome.span_ns)
        if not outcome.result.duplicate_upload:
            self._publish_commit(satellite, outcome.result, outcome.span_ns, published=outcome.chunks == 1)
        return {
            "satellite": satellite,
            "dictionary": dictionary_name_of(dictionary),
            "archive": outcome.result.as_report(),
            "decoding": outcome.report.to_dict(),
            "published": outcome.chunks == 1,
            "passes": [{**asdict(p), "completeness": p.completeness} for p in outcome.passes],
        }

    def redecode(
        self, satellite: str, dictionary_name: str, apids: tuple[int, ...], uploaded_by: str
    ) -> dict[str, Any]:
        """Decode, with a dictionary that now defines them, the packets of ``satellite`` kept raw for want of a
        definition (all APIDs it defines, or ``apids``) and archive them as one upload, in the decoder process
        (blocking: call from a thread). Packets it quarantines stay kept; "archive" is None when none was kept."""
        dictionary = self.dictionaries.load(dictionary_name)
        self._opened().undefined_counts(satellite)  # an unknown satellite: 422 before the decoder starts
        outcome = self.upload_decoder.run(RedecodeJob(satellite, dictionary_name, apids, uploaded_by))
        if outcome.span_ns is not None:
            self._samples.invalidate(satellite, *outcome.span_ns)
        if outcome.result is not None:
            self._publish_commit(satellite, outcome.result, outcome.span_ns, published=False)
        return {
            "satellite": satellite,
            "dictionary": dictionary_name_of(dictionary),
            "apids": list(outcome.apids),
            "archive": None if outcome.result is None else outcome.result.as_report(),
            "decoding": outcome.report.to_dict(),
            "passes": [{**asdict(p), "completeness": p.completeness} for p in outcome.passes],
        }

    @property
    def upload_decoder(self) -> UploadDecoder:
        """The process that decodes and archives large packet files (503 until the archive is started)."""
        if self._upload_decoder is None:
            raise ApiError(503, "archive not started", "archive")
        return self._upload_decoder

    def ingest_ground_file(
        self, satellite: str, data: bytes, kind: str, dictionary_name: str, source: str, uploaded_by: str
    ) -> dict[str, Any]:
        """Archive a CSV or JSONL ground file (telemetry.ground_files) like a packet upload."""
        dictionary = self.dictionaries.load(dictionary_name)
        read = ground_files.read_ground_csv if kind == "csv" else ground_files.read_ground_jsonl
        decoded = read(data, dictionary, source=source)
        return self._archive_and_publish(satellite, decoded, dictionary_name, source, uploaded_by)

    def _archive_and_publish(
        self, satellite: str, decoded: DecodeResult, dictionary_name: str, source: str, uploaded_by: str
    ) -> dict[str, Any]:
        dictionary = self.dictionaries.load(dictionary_name)
        result = self.archive.ingest_decoded(
            satellite, decoded, uploaded_by=uploaded_by, limits=dictionary_limits(dictionary)
        )
        self._invalidate_batches(satellite, decoded.batches)
        passes: list[PassRecord] = []
        if not result.duplicate_upload:
            self._publish(satellite, decoded.batches, result.alarm_events)
            for listener in self._committed:
                listener(satellite, dictionary_name, decoded.batches)
            passes = self.passes_from_data(satellite, decoded.batches)
            spans = [(int(b.t_utc_ns.min()), int(b.t_utc_ns.max())) for b in decoded.batches if len(b.t_utc_ns)]
            span = (min(a for a, _ in spans), max(b for _, b in spans)) if spans else None
            self._publish_commit(satellite, result, span, published=True)
        return {
            "satellite": satellite,
            "dictionary": dictionary_name_of(dictionary),
            "archive": result.as_report(),
            "decoding": decoded.report.to_dict(),
            "passes": [{**asdict(p), "completeness": p.completeness} for p in passes],
        }

    def passes_from_data(self, satellite: str, batches: list[SampleBatch]) -> list[PassRecord]:
        """The passes the batches' samples fall in, made from the data where no predicted pass covers them
        (telemetry.passes.passes_from_data), reception recounted."""
        from telemetry import passes

        spans = [(int(b.t_utc_ns.min()), int(b.t_utc_ns.max())) for b in batches if len(b.t_utc_ns)]
        if not spans:
            return []
        return passes.passes_from_data(self._opened(), satellite, min(s[0] for s in spans), max(s[1] for s in spans))

    def _publish_commit(
        self, satellite: str, result: IngestResult, span_ns: tuple[int, int] | None, *, published: bool
    ) -> None:
        """One "archive" item per commit; when its samples were not replayed on "parameters/" (a backfill: a file of
        more than one chunk, a redecode) dashboards reload their plots and latest values from the archive, and
        "alarms" subscribers hear of its alarm events here."""
        if self._hub.wants_any("archive"):
            self._hub.publish(
                "archive",
                {
                    "satellite": satellite,
                    "upload_id": result.upload_id,
                    "packets_accepted": result.packets_accepted,
                    "t_first_utc_ns": None if span_ns is None else span_ns[0],
                    "t_last_utc_ns": None if span_ns is None else span_ns[1],
                    "published": published,
                },
            )
        if not published:
            self._publish(satellite, [], result.alarm_events)

    def _publish(self, satellite: str, batches: list[SampleBatch], alarm_events: int) -> None:
        for batch in batches:
            for name, column in batch.values.items():
                topic = f"parameters/{name}"
                if self._hub.wants_any(topic):
                    self._hub.publish(
                        topic,
                        {
                            "satellite": satellite,
                            "t_utc_ns": batch.t_utc_ns.tolist(),
                            "values": np.asarray(column, dtype=float).tolist(),
                        },
                    )
        if alarm_events and self._hub.wants_any("alarms"):
            alarms = self.archive.alarms(satellite)
            self._hub.publish("alarms", {"satellite": satellite, "alarms": [asdict(a) for a in alarms]})

    def predict_passes(self, satellite: str, station: str, t0_ns: int, t1_ns: int) -> list[PassRecord]:
        """Passes from the newest TLE over ``station`` in [t0_ns, t1_ns] (telemetry.passes), stored."""
        from telemetry import passes

        if t1_ns <= t0_ns:
            raise ValueError("end: must be after start")
        span_days, limit_days = (t1_ns - t0_ns) / 86_400e9, self._settings.max_prediction_days
        if span_days > limit_days:
            raise ValueError(f"end: the window spans {span_days:,.1f} days, over max_prediction_days = {limit_days:g}")
        tle_id, line1, line2 = self.archive.latest_tle(satellite, before_ns=t1_ns)
        site = self.archive.ground_station(station)
        predicted = passes.predict_passes(
            line1,
            line2,
            site.lat_deg,
            site.lon_deg,
            site.alt_m,
            site.min_elevation_deg,
            t0_ns,
            (t1_ns - t0_ns) / 86_400e9,
        )
        ids = set(self.archive.save_passes(satellite, station, predicted.rows(), tle_id=tle_id))
        return [p for p in self.archive.passes(satellite, t0_ns, t1_ns) if p.id in ids]

    def record_reception(self, satellite: str, t0_ns: int, t1_ns: int) -> list[PassRecord]:
        """Recount what was received in each pass of [t0_ns, t1_ns] (completeness from gaps)."""
        from telemetry import passes  # skyfield and sgp4: imported on first use, not at server start

        archive = self._opened()
        return passes.record_reception(archive, satellite, archive.passes(satellite, t0_ns, t1_ns))

    def pass_summary(self, satellite: str, pass_id: int) -> dict[str, Any]:
        """Reception, per-parameter statistics and alarms of one pass (telemetry.queries)."""
        from telemetry import queries  # pyarrow: imported on first use, not at server start

        return queries.pass_summary(self._opened(), satellite, pass_id)

    def export_stream(
        self, satellite: str, names: list[str], t0_ns: int, t1_ns: int
    ) -> tuple[pa.Schema, Iterator[pa.RecordBatch]]:
        """Every sample of the parameters, window by window (telemetry.export); unknown names and a window over
        max_export_rows raise now (ValueError naming the field)."""
        from telemetry import export

        limit = self._settings.max_export_rows
        return export.export_batches(self._opened(), satellite, names, t0_ns, t1_ns, max_rows=limit)

    def export_table(self, satellite: str, names: list[str], t0_ns: int, t1_ns: int) -> pa.Table:
        """Wide pyarrow table of the parameters (telemetry.queries.export_table)."""
        from telemetry import queries

        return queries.export_table(self._opened(), satellite, names, t0_ns, t1_ns)

    def _invalidate_batches(self, satellite: str, batches: list[SampleBatch]) -> None:
        spans = [(int(b.t_utc_ns.min()), int(b.t_utc_ns.max())) for b in batches if len(b.t_utc_ns)]
        if spans:
            self._samples.invalidate(satellite, min(s[0] for s in spans), max(s[1] for s in spans))

    def samples_from_memory(self, satellite: str, name: str, t0_ns: int, t1_ns: int, max_points: int) -> bytes | None:
        """The answer of :meth:`samples_json` when no database access is needed (cached answer or series),
        else None; costs ≲ 1 ms, so it runs in the event loop."""
        key = (satellite, name, t0_ns, t1_ns, max_points)
        hit = self._samples.answer(key)
        if hit is not None or self._samples.hot_start_ns(satellite) is not None:
            return hit
        generation = self._samples.generation(satellite)
        whole = self._samples.series(satellite, name)
        return None if whole is None else self._answer(key, generation, *_window_of(whole, t0_ns, t1_ns))

    def _read(
        self, satellite: str, name: str, t0_ns: int, t1_ns: int, generation: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Samples in [t0_ns, t1_ns]: sliced from the whole cached series, read whole once, or (live) per window."""
        whole = self._samples.series(satellite, name)
        if whole is None and self._samples.hot_start_ns(satellite) is not None:
            return self.archive.read_parameter(satellite, name, t0_ns, t1_ns)
        if whole is None:
            whole = self.archive.read_parameter(satellite, name, -BOUND_NS, BOUND_NS)
            self._samples.store_series(satellite, name, generation, *whole)
        return _window_of(whole, t0_ns, t1_ns)

    def window_result(
        self,
        satellite: str,
        what: str,
        t0_ns: int,
        t1_ns: int,
        compute: Callable[[], Result],
        dictionary: str | None = None,
    ) -> Result:
        """``compute()``, a result read from the archive window [t0_ns, t1_ns] of ``satellite`` and named ``what``
        (including whatever else it depends on), kept until an ingest overlaps the window; failures are not kept.
        A result decoded with ``dictionary`` is kept per version of it: an upload under the same name recomputes."""
        if dictionary is not None:
            what = f"{what} decoded with {dictionary} v{self.dictionaries.version(dictionary)}"
        key = (satellite, what, t0_ns, t1_ns)
        hit = self._samples.computed(key)
        if hit is not None:
            return cast(Result, hit)  # stored under this key by this method only
        generation = self._samples.generation(satellite)
        value = compute()
        self._samples.store_computed(key, generation, value)
        return value

    def samples_json(self, satellite: str, name: str, t0_ns: int, t1_ns: int, max_points: int) -> bytes:
        """JSON of one parameter's samples in [t0_ns, t1_ns], min/max-downsampled to max_points (cached)."""
        key = (satellite, name, t0_ns, t1_ns, max_points)
        hit = self._samples.answer(key)
        if hit is not None:
            return hit
        generation = self._samples.generation(satellite)
        return self._answer(key, generation, *self._read(satellite, name, t0_ns, t1_ns, generation))

    def _answer(self, key: tuple[str, str, int, int, int], generation: int, t: np.ndarray, v: np.ndarray) -> bytes:
        keep = minmax_indices(v, key[4]) if v.size else np.arange(0)
        answer = orjson.dumps(
            {
                "satellite": key[0],
                "name": key[1],
                "total_points": int(t.size),
                "t_utc_ns": np.ascontiguousarray(t[keep], dtype=np.int64),
                "values": np.ascontiguousarray(v[keep], dtype=np.float64),
            },
            option=orjson.OPT_SERIALIZE_NUMPY,
        )  # NaN → null; ~16× faster than json here
        self._samples.store_answer(key, generation, answer)
        return answer


def _window_of(series: tuple[np.ndarray, np.ndarray], t0_ns: int, t1_ns: int) -> tuple[np.ndarray, np.ndarray]:
    t, v = series
    lo, hi = np.searchsorted(t, t0_ns, side="left"), np.searchsorted(t, t1_ns, side="right")
    return t[lo:hi], v[lo:hi]


def dictionary_name_of(dictionary: Dictionary) -> str:
    """Display name of a loaded dictionary."""
    return str(getattr(dictionary, "name", ""))
