"""Repository of the telemetry archive: the only code that opens transactions on its tables.

An upload is one transaction: the upload row, its packet and value chunks and its alarm events
commit together or not at all, and the upload's SHA-256 makes a repeated upload a reported no-op.
Writers are serialised per database (SQLite ``BEGIN IMMEDIATE``) or per satellite (PostgreSQL
``SELECT ... FOR UPDATE`` on the satellite row), so duplicate detection is exact.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from sqlalchemy import Connection, Row, Table, bindparam, delete, func, insert, select, update

from telemetry.archive import alarms as alarm_state
from telemetry.archive.batch import ColumnMatrices, PacketBatch, sequence_gaps, value_matrices
from telemetry.archive.chunks import (
    decode_int64,
    decode_raw,
    decode_values,
    encode_int64,
    encode_raw,
    encode_value_rows,
)
from telemetry.archive.engine import (
    WalCheckpointer,
    create_archive_engine,
    fetch_rows,
    insert_returning_ids,
    insert_rows,
    run_update,
)
from telemetry.archive.migrate import upgrade
from telemetry.archive.models import (
    NAME_MAX,
    Alarm,
    AlarmEvent,
    GroundStation,
    PacketChunk,
    Parameter,
    Pass,
    Satellite,
    Tle,
    UndefinedPacketChunk,
    Upload,
    ValueChunk,
)
from telemetry.archive.records import (
    AlarmEventRecord,
    AlarmRecord,
    Gap,
    IngestResult,
    PassRecord,
    PendingUpload,
    StationRecord,
    UploadRecord,
)
from telemetry.ingest_report import UndefinedPackets, absent_in_rows
from telemetry.limits import LimitSet, level_changes, limit_levels

if TYPE_CHECKING:
    from telemetry.ingest_report import DecodeResult, IngestReport

__all__ = ["Archive", "CHUNK_PACKETS"]

# Packets per chunk. benchmarks/ingest.py (bench_chunk_sizes) measures bigger chunks committing
# faster (1k: ~7 M samples/s, 16k: 8-19 M on this shared machine) with short queries alike (2-4 ms).
CHUNK_PACKETS = 16_384
PENDING_OCTETS = 6 << 20  # decoded values and raw packets held back to fill archive chunks (memory bound)
SAT, STATION, TLE, PASS = (cast(Table, m.__table__) for m in (Satellite, GroundStation, Tle, Pass))
UPLOAD, PARAM, CHUNK, VALUE = (cast(Table, m.__table__) for m in (Upload, Parameter, PacketChunk, ValueChunk))
ALARM, EVENT = (cast(Table, m.__table__) for m in (Alarm, AlarmEvent))
UNDEFINED = cast(Table, UndefinedPacketChunk.__table__)
# Built once: an upload asks it per APID and archive chunk (building the expression cost more than running it)
_PACKET_KEYS = select(CHUNK.c.t_blob, CHUNK.c.seq_blob).where(
    CHUNK.c.satellite_id == bindparam("sat"),
    CHUNK.c.apid == bindparam("apid"),
    CHUNK.c.t_start_ns <= bindparam("t1"),
    CHUNK.c.t_end_ns >= bindparam("t0"),
)
# ... and per APID its parameters' ids (an IN list given as values builds no clause per name: ~0.4 ms per name list)
_PARAMETER_IDS = select(PARAM.c.name, PARAM.c.id).where(
    PARAM.c.satellite_id == bindparam("sat"), PARAM.c.name.in_(bindparam("names", expanding=True))
)

# ... and per upload its look-up by checksum, its row and its result (built per call, each cost ~1 ms of SQLAlchemy:
# most of a live group commit's small uploads)
_UPLOAD_BY_SHA = select(UPLOAD.c.id).where(
    UPLOAD.c.satellite_id == bindparam("sat"), UPLOAD.c.sha256 == bindparam("sha")
)
_UPLOAD_COLUMNS = (
    "satellite_id",
    "uploaded_by",
    "uploaded_at_ns",
    "source",
    "sha256",
    "packets_accepted",
    "samples_accepted",
    "report_json",
)
_UPLOAD_RESULT = (
    update(UPLOAD)
    .where(UPLOAD.c.id == bindparam("upload"))
    .values(
        packets_accepted=bindparam("packets"), samples_accepted=bindparam("samples"), report_json=bindparam("report")
    )
)


def _now_ns() -> int:
    return time.time_ns()


def _check_name(field: str, what: str, name: str) -> None:
    """ValueError naming ``field`` unless ``name`` has 1 to NAME_MAX characters, the width of the archive's name
    columns (PostgreSQL refuses a longer one; SQLite would store it)."""
    if not name:
        raise ValueError(f"{field}: {what} is required")
    if len(name) > NAME_MAX:
        raise ValueError(f"{field}: {what} has at most {NAME_MAX} characters, got {len(name)}")


class Archive:
    """The telemetry archive at a database URL (migrated to the newest schema on open)."""

    def __init__(self, url: str, *, migrate: bool = True) -> None:
        self.url = url
        self._writer = create_archive_engine(url, autocheckpoint=False)
        self._is_postgres = self._writer.dialect.name == "postgresql"
        self.engine = self._writer if self._is_postgres else create_archive_engine(url, writer=False)
        self._checkpoints = None if self._is_postgres else WalCheckpointer(self._writer)
        self._satellite_ids: dict[str, int] = {}
        if migrate:
            upgrade(url, self._writer)

    def close(self) -> None:
        """Release the database connections (on SQLite after the WAL checkpoint under way, if any)."""
        if self._checkpoints is not None:
            self._checkpoints.close()
        self.engine.dispose()
        self._writer.dispose()

    def wait_for_checkpoint(self) -> None:
        """Return once the WAL checkpoint after every commit so far has run (SQLite; at once on PostgreSQL).

        A commit returns without checkpointing the WAL into the database file (engine.WalCheckpointer): that runs
        on the archive's own thread after it."""
        if self._checkpoints is not None:
            self._checkpoints.wait()

    @contextmanager
    def _write(self) -> Iterator[Connection]:
        """A write transaction; once it has committed, the WAL checkpoint of its pages is started (SQLite)."""
        with self._writer.begin() as conn:
            yield conn
        if self._checkpoints is not None:
            self._checkpoints.committed()

    def __enter__(self) -> Archive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- satellites, stations, TLEs -------------------------------------------------------
    def satellite_id(self, name: str, norad_id: int | None = None) -> int:
        """Id of the satellite called ``name``, registering it on first use."""
        _check_name("satellite", "a satellite name", name)
        if name in self._satellite_ids:
            return self._satellite_ids[name]
        with self._write() as conn:
            found = conn.execute(select(SAT.c.id).where(SAT.c.name == name)).scalar()
            if found is None:
                found = conn.execute(insert(SAT).values(name=name, norad_id=norad_id).returning(SAT.c.id)).scalar_one()
        self._satellite_ids[name] = int(found)
        return int(found)

    def _known_satellite(self, name: str) -> int:
        """Id of an archived satellite (reads never create one)."""
        if name in self._satellite_ids:
            return self._satellite_ids[name]
        with self.engine.connect() as conn:
            found = conn.execute(select(SAT.c.id).where(SAT.c.name == name)).scalar()
        if found is None:
            raise ValueError(f"satellite: nothing archived for a satellite named {name!r}")
        self._satellite_ids[name] = int(found)
        return int(found)

    def add_ground_station(
        self, name: str, lat_deg: float, lon_deg: float, alt_m: float, min_elevation_deg: float
    ) -> int:
        """Register (or update) a ground station; returns its id."""
        _check_name("name", "a station name", name)
        if not -90.0 <= lat_deg <= 90.0:
            raise ValueError(f"lat_deg: {lat_deg} outside -90..90")
        if not -180.0 <= lon_deg <= 360.0:
            raise ValueError(f"lon_deg: {lon_deg} outside -180..360")
        if not -90.0 <= min_elevation_deg < 90.0:
            raise ValueError(f"min_elevation_deg: {min_elevation_deg} outside -90..90")
        values = {"lat_deg": lat_deg, "lon_deg": lon_deg, "alt_m": alt_m, "min_elevation_deg": min_elevation_deg}
        with self._write() as conn:
            found = conn.execute(select(STATION.c.id).where(STATION.c.name == name)).scalar()
            if found is not None:
                conn.execute(update(STATION).where(STATION.c.id == found).values(**values))
                return int(found)
            return int(conn.execute(insert(STATION).values(name=name, **values).returning(STATION.c.id)).scalar_one())

    def ground_station(self, name: str) -> StationRecord:
        """The ground station called ``name``."""
        with self.engine.connect() as conn:
            row = conn.execute(select(STATION).where(STATION.c.name == name)).one_or_none()
        if row is None:
            raise ValueError(f"station: no ground station named {name!r}")
        return StationRecord(**row._mapping)

    def add_tle(self, satellite: str, line1: str, line2: str, epoch_ns: int | None = None) -> int:
        """Store a validated TLE of ``satellite`` (idempotent on its epoch, read from it if not given)."""
        from sim_core import orbit  # imported on use: SGP4 and numba are not needed to read the archive

        satrec = orbit.parse_tle(line1, line2)  # ValueError naming the TLE field
        if epoch_ns is None:
            epoch_ns = round(orbit.tle_epoch_unix_s(satrec) * 1e9)
        sat_id = self.satellite_id(satellite)
        with self._write() as conn:
            found = conn.execute(
                select(TLE.c.id).where(TLE.c.satellite_id == sat_id, TLE.c.epoch_ns == epoch_ns)
            ).scalar()
            if found is not None:
                return int(found)
            row = {"satellite_id": sat_id, "epoch_ns": int(epoch_ns), "line1": line1, "line2": line2}
            return int(conn.execute(insert(TLE).values(**row).returning(TLE.c.id)).scalar_one())

    def latest_tle(self, satellite: str, before_ns: int | None = None) -> tuple[int, str, str]:
        """(id, line1, line2) of the newest TLE of ``satellite`` (optionally with epoch <= before_ns)."""
        sat_id = self._known_satellite(satellite)
        query = select(TLE.c.id, TLE.c.line1, TLE.c.line2).where(TLE.c.satellite_id == sat_id)
        if before_ns is not None:
            query = query.where(TLE.c.epoch_ns <= before_ns)
        with self.engine.connect() as conn:
            row = conn.execute(query.order_by(TLE.c.epoch_ns.desc()).limit(1)).one_or_none()
        if row is None:
            raise ValueError(f"satellite: no TLE stored for {satellite!r}")
        return int(row[0]), row[1], row[2]

    # --- ingest --------------------------------------------------------------------------
    def ingest(
        self,
        satellite: str,
        batches: Iterable[PacketBatch],
        *,
        source: str,
        uploaded_by: str,
        sha256: str | None = None,
        limits: Mapping[str, LimitSet] | None = None,
        decode_report: Mapping[str, object] | None = None,
        undefined: Sequence[UndefinedPackets] = (),
    ) -> IngestResult:
        """Commit decoded batches atomically as one upload (duplicates dropped, limits checked).

        Raw packets of undefined APIDs are kept with the upload; a repeated upload adds nothing and
        reports, per APID, how many of its packets are already archived.
        """
        _check_name("uploaded_by", "the uploader's name", uploaded_by)
        batches = _merge_by_apid(list(batches))
        sat_id = self.satellite_id(satellite)
        with self._write() as conn:
            self._lock_satellite(conn, sat_id)
            return self._ingest_in(
                conn, sat_id, batches, source, uploaded_by, sha256, limits or {}, decode_report or {}, undefined
            )

    def ingest_many(self, uploads: Sequence[PendingUpload]) -> list[IngestResult]:
        """Commit several uploads (of one or many satellites) in one transaction: one commit, one fsync for all.

        The live paths' group commit (the live twins' residuals of every satellite, a fleet's telemetry): a commit
        costs an fsync (~10–20 ms, synchronous=FULL), so one per upload caps the archive at ~50–100 uploads/s
        whatever their size. Each upload stays its own row with its own result (in the order given); when this
        returns, every one of them is durable, as after :meth:`ingest`; if one fails, none is archived.
        """
        for u in uploads:
            _check_name("uploaded_by", "the uploader's name", u.uploaded_by)
        sat_ids = [self.satellite_id(u.satellite) for u in uploads]
        merged = [_merge_by_apid(list(u.batches)) for u in uploads]
        with self._write() as conn:
            for sat_id in sorted(set(sat_ids)):  # one lock order for every writer (PostgreSQL)
                self._lock_satellite(conn, sat_id)
            return [
                self._ingest_in(conn, sat_id, batches, u.source, u.uploaded_by, None, u.limits or {}, {}, ())
                for u, sat_id, batches in zip(uploads, sat_ids, merged)
            ]

    def _ingest_in(
        self,
        conn: Connection,
        sat_id: int,
        batches: list[PacketBatch],
        source: str,
        uploaded_by: str,
        sha256: str | None,
        limits: Mapping[str, LimitSet],
        decode_report: Mapping[str, object],
        undefined: Sequence[UndefinedPackets],
    ) -> IngestResult:
        """One upload inside the caller's transaction (satellite locked): duplicates dropped, limits checked."""
        checksum = sha256 or _batches_sha256(batches)
        existing = _upload_by_sha(conn, sat_id, checksum)
        if existing is not None:
            archived = {b.apid: self._drop_archived(conn, sat_id, _order_and_dedupe(b)[0])[1] for b in batches}
            return IngestResult(
                upload_id=int(existing),
                duplicate_upload=True,
                packets_duplicate=sum(archived.values()),
                duplicates_by_apid=archived,
            )
        upload_id = self._insert_upload(conn, sat_id, source, uploaded_by, checksum)
        result = self._write_batches(conn, sat_id, upload_id, batches, limits)
        self._write_undefined(conn, sat_id, upload_id, undefined)
        return self._store_result(conn, upload_id, result, decode_report)

    def ingest_decoded(
        self,
        satellite: str,
        decoded: DecodeResult,
        *,
        uploaded_by: str,
        sha256: str | None = None,
        limits: Mapping[str, LimitSet] | None = None,
    ) -> IngestResult:
        """Commit a decoder result (telemetry.decoding) as one upload, keeping its report."""
        batches = [PacketBatch.from_sample_batch(b) for b in decoded.batches]
        return self.ingest(
            satellite,
            batches,
            source=decoded.report.source,
            uploaded_by=uploaded_by,
            sha256=sha256,
            limits=limits,
            decode_report=decoded.report.to_dict(),
            undefined=decoded.undefined,
        )

    def ingest_results(
        self,
        satellite: str,
        results: Iterable[DecodeResult],
        *,
        source: str,
        uploaded_by: str,
        sha256: str,
        limits: Mapping[str, LimitSet] | None = None,
        report: IngestReport | None = None,
    ) -> IngestResult:
        """Commit the decoded chunks of one input (consumed one at a time: bounded memory) as one upload.

        The upload's stored report is ``report`` as it stands once every chunk is consumed. A repeated
        upload (same SHA-256) adds nothing and reports, per APID, how many of its packets are archived.
        """
        if not uploaded_by:
            raise ValueError("uploaded_by: the uploader's name is required")
        sat_id = self.satellite_id(satellite)
        with self._write() as conn:
            self._lock_satellite(conn, sat_id)
            existing = _upload_by_sha(conn, sat_id, sha256)
            upload_id = (
                int(existing)
                if existing is not None
                else self._insert_upload(conn, sat_id, source, uploaded_by, sha256)
            )
            parts: list[IngestResult] = []
            archived: dict[int, int] = {}
            pending = _PendingBatches()
            last_written: dict[int, tuple[int, int]] = {}  # gaps between two archive chunks counted once
            param_ids: dict[str, int] = {}  # parameter ids met in this transaction: looked up once per upload
            for decoded in results:
                batches = _merge_by_apid([PacketBatch.from_sample_batch(b) for b in decoded.batches])
                if existing is not None:
                    for b in batches:
                        n = self._drop_archived(conn, sat_id, _order_and_dedupe(b)[0])[1]
                        archived[b.apid] = archived.get(b.apid, 0) + n
                    continue
                ready = pending.add(batches)
                if ready:
                    parts.append(
                        self._write_batches(conn, sat_id, upload_id, ready, limits or {}, last_written, param_ids)
                    )
                self._write_undefined(conn, sat_id, upload_id, decoded.undefined)
                del decoded, batches, ready  # written or pending: not held while the next chunk is decoded
            if pending.batches:
                parts.append(
                    self._write_batches(conn, sat_id, upload_id, pending.flush(), limits or {}, last_written, param_ids)
                )
            if existing is not None:
                return IngestResult(
                    upload_id, True, packets_duplicate=sum(archived.values()), duplicates_by_apid=archived
                )
            return self._close_upload(conn, upload_id, parts, report)

    def _close_upload(
        self, conn: Connection, upload_id: int, parts: list[IngestResult], report: IngestReport | None
    ) -> IngestResult:
        """The upload's result from those of its chunks, stored on its row with the decoder's report."""
        by_apid: dict[int, int] = {}
        for part in parts:
            for apid, n in part.duplicates_by_apid.items():
                by_apid[apid] = by_apid.get(apid, 0) + n
        result = IngestResult(
            upload_id,
            False,
            sum(p.packets_accepted for p in parts),
            sum(p.packets_duplicate for p in parts),
            sum(p.samples_accepted for p in parts),
            sum(p.alarm_events for p in parts),
            [g for p in parts for g in p.gaps],
            by_apid,
        )
        return self._store_result(conn, upload_id, result, report.to_dict() if report else {})

    @staticmethod
    def _store_result(
        conn: Connection, upload_id: int, result: IngestResult, decode_report: Mapping[str, object]
    ) -> IngestResult:
        """``result``: its counts and report (with the decoder's) stored on the upload's row."""
        stored = {**result.as_report(), "decode": dict(decode_report)}
        values = {"packets": result.packets_accepted, "samples": result.samples_accepted, "report": json.dumps(stored)}
        run_update(conn, _UPLOAD_RESULT, {"upload": upload_id, **values})
        return result

    def redecode_undefined(
        self,
        satellite: str,
        apids: Sequence[int],
        decode: Callable[[bytes], DecodeResult],
        *,
        source: str,
        uploaded_by: str,
        report: IngestReport,
        limits: Mapping[str, LimitSet] | None = None,
    ) -> IngestResult | None:
        """Decode the packets of ``apids`` kept raw (no definition when they came) and commit them as one upload.

        ``decode(octets)`` decodes a run of whole packets (telemetry.decoding.decode_stream with the dictionary
        that now defines them); ``report`` absorbs its reports. A kept packet leaves the keep in the transaction
        that archives it; one the decoder quarantines stays kept (a corrected definition may read it later),
        counted per APID in ``report.undefined_apids``. None when no packet of ``apids`` is kept.
        """
        if not uploaded_by:
            raise ValueError("uploaded_by: the uploader's name is required")
        sat_id = self._known_satellite(satellite)
        with self._write() as conn:
            self._lock_satellite(conn, sat_id)
            kept = UNDEFINED.c.satellite_id == sat_id, UNDEFINED.c.apid.in_(list(apids))
            ids = conn.execute(select(UNDEFINED.c.id).where(*kept).order_by(UNDEFINED.c.id)).scalars().all()
            if not ids:
                return None
            token = f"redecode {sat_id} {ids[0]}..{ids[-1]} {_now_ns()}".encode()
            upload_id = self._insert_upload(conn, sat_id, source, uploaded_by, hashlib.sha256(token).hexdigest())
            parts, offset = [], 0
            for row_id in ids:
                row = conn.execute(select(UNDEFINED).where(UNDEFINED.c.id == row_id)).one()
                raw = decode_raw(row.raw_blob)
                decoded = decode(raw)
                report.absorb(decoded.report, offset)
                offset += len(raw)
                batches = _merge_by_apid([PacketBatch.from_sample_batch(b) for b in decoded.batches])
                parts.append(self._write_batches(conn, sat_id, upload_id, batches, limits or {}))
                self._write_undefined(conn, sat_id, upload_id, decoded.undefined)
                conn.execute(UNDEFINED.delete().where(UNDEFINED.c.id == row_id))
                self._keep_quarantined(conn, row, raw, decoded, report)
            return self._close_upload(conn, upload_id, parts, report)

    def _keep_quarantined(
        self, conn: Connection, row: Row[Any], raw: bytes, decoded: DecodeResult, report: IngestReport
    ) -> None:
        """Keep raw again the packets of an undefined-packet row that its new decode quarantined."""
        lengths = decode_int64(row.length_blob)
        starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
        quarantined = np.zeros(lengths.shape, dtype=bool)
        for q in decoded.report.quarantined:
            quarantined |= (starts < q.offset + q.length) & (starts + lengths > q.offset)
        if not quarantined.any():
            return
        octets = np.frombuffer(raw, dtype=np.uint8)
        picked = np.concatenate([octets[a : a + n] for a, n in zip(starts[quarantined], lengths[quarantined])])
        seq = decode_int64(row.seq_blob)[quarantined]
        again = UndefinedPackets(int(row.apid), picked, lengths[quarantined], seq)
        self._write_undefined(conn, int(row.satellite_id), int(row.upload_id), [again])
        report.undefined_apids[again.apid] = report.undefined_apids.get(again.apid, 0) + int(quarantined.sum())

    def _write_undefined(
        self, conn: Connection, sat_id: int, upload_id: int, undefined: Sequence[UndefinedPackets]
    ) -> None:
        rows = [
            (
                sat_id,
                upload_id,
                int(u.apid),
                len(u.packet_lengths),
                encode_int64(np.asarray(u.sequence_count, dtype=np.int64)),
                encode_int64(np.asarray(u.packet_lengths, dtype=np.int64)),
                encode_raw(u.packets),
            )
            for u in undefined
            if len(u.packet_lengths)
        ]
        if rows:
            insert_rows(conn, UNDEFINED, _UNDEFINED_COLUMNS, rows)

    def undefined_counts(self, satellite: str) -> dict[int, int]:
        """Packets kept raw per APID (no definition when they came, or quarantined by a later one)."""
        sat_id = self._known_satellite(satellite)
        query = (
            select(UNDEFINED.c.apid, func.sum(UNDEFINED.c.n_packets))
            .where(UNDEFINED.c.satellite_id == sat_id)
            .group_by(UNDEFINED.c.apid)
        )
        with self.engine.connect() as conn:
            return {int(a): int(n) for a, n in conn.execute(query.order_by(UNDEFINED.c.apid))}

    def undefined_packets(self, satellite: str, apid: int | None = None) -> dict[int, list[bytes]]:
        """Raw packets of APIDs that had no definition when ingested, per APID, in upload order (byte-exact)."""
        sat_id = self._known_satellite(satellite)
        query = select(UNDEFINED.c.apid, UNDEFINED.c.length_blob, UNDEFINED.c.raw_blob).where(
            UNDEFINED.c.satellite_id == sat_id
        )
        if apid is not None:
            query = query.where(UNDEFINED.c.apid == apid)
        out: dict[int, list[bytes]] = {}
        with self.engine.connect() as conn:
            for row_apid, length_blob, raw_blob in conn.execute(query.order_by(UNDEFINED.c.id)):
                ends = np.cumsum(decode_int64(length_blob))
                raw = decode_raw(raw_blob)
                starts = np.concatenate(([0], ends[:-1]))
                out.setdefault(int(row_apid), []).extend(raw[a:b] for a, b in zip(starts.tolist(), ends.tolist()))
        return out

    def _lock_satellite(self, conn: Connection, sat_id: int) -> None:
        if self._is_postgres:
            conn.execute(select(SAT.c.id).where(SAT.c.id == sat_id).with_for_update())

    def _insert_upload(self, conn: Connection, sat_id: int, source: str, uploaded_by: str, checksum: str) -> int:
        row = (sat_id, uploaded_by, _now_ns(), source, checksum, 0, 0, "{}")
        return insert_returning_ids(conn, UPLOAD, _UPLOAD_COLUMNS, [row])[0]

    def _write_batches(
        self,
        conn: Connection,
        sat_id: int,
        upload_id: int,
        batches: list[PacketBatch],
        limits: Mapping[str, LimitSet],
        last_written: dict[int, tuple[int, int]] | None = None,
        param_ids: dict[str, int] | None = None,
    ) -> IngestResult:
        """Write the batches' new packets; ``last_written`` (APID → time and sequence count of the upload's last
        packet written so far, updated) counts a gap between two writes of one upload once, as one write would;
        ``param_ids`` (name → id of the satellite's parameters met so far in this transaction, updated) spares
        a look-up per write."""
        param_ids = {} if param_ids is None else param_ids
        accepted = duplicates = samples = 0
        gaps: list[Gap] = []
        changes: list[alarm_state.LevelChanges] = []
        by_apid: dict[int, int] = {}
        for batch in batches:
            ordered, n_dup_inside = _order_and_dedupe(batch)
            fresh, n_dup_archived = self._drop_archived(conn, sat_id, ordered)
            duplicates += n_dup_inside + n_dup_archived
            by_apid[batch.apid] = by_apid.get(batch.apid, 0) + n_dup_inside + n_dup_archived
            if fresh.n_packets == 0:
                continue
            absent = self._write_chunks(conn, sat_id, upload_id, fresh, param_ids)
            accepted += fresh.n_packets
            samples += fresh.n_packets * len(fresh.values) - absent
            if fresh.raw:  # ground files carry no sequence counts
                previous = None if last_written is None else last_written.get(fresh.apid)
                gaps.extend(_gaps_of(fresh, previous))
                if last_written is not None:
                    last_written[fresh.apid] = (int(fresh.t_utc_ns[-1]), int(fresh.seq_count[-1]))
            if limits:
                changes.extend(_limit_changes(fresh, limits, alarm_state.current_levels(conn, sat_id, list(limits))))
        n_events = alarm_state.apply_level_changes(conn, sat_id, upload_id, changes) if changes else 0
        return IngestResult(upload_id, False, accepted, duplicates, samples, n_events, gaps, by_apid)

    def _drop_archived(self, conn: Connection, sat_id: int, batch: PacketBatch) -> tuple[PacketBatch, int]:
        t, seq = batch.t_utc_ns, batch.seq_count
        if t.size == 0:
            return batch, 0
        old_t, old_seq = self._packet_keys(conn, sat_id, batch.apid, int(t[0]), int(t[-1]))
        if old_t.size == 0:  # nothing archived in its time span: the usual case
            return batch, 0
        candidates = np.flatnonzero(np.isin(t, old_t))
        if candidates.size == 0:
            return batch, 0
        near = np.isin(old_t, t[candidates])
        archived = set(zip(old_t[near].tolist(), old_seq[near].tolist()))
        is_dup = np.zeros(t.shape, dtype=bool)
        is_dup[candidates] = [(a, b) in archived for a, b in zip(t[candidates].tolist(), seq[candidates].tolist())]
        return batch.take(np.flatnonzero(~is_dup)), int(is_dup.sum())

    def _packet_keys(
        self, conn: Connection, sat_id: int, apid: int, t0_ns: int, t1_ns: int
    ) -> tuple[np.ndarray, np.ndarray]:
        rows = fetch_rows(conn, _PACKET_KEYS, {"sat": sat_id, "apid": apid, "t0": t0_ns, "t1": t1_ns})
        if not rows:
            return np.empty(0, np.int64), np.empty(0, np.int64)
        return (np.concatenate([decode_int64(r[0]) for r in rows]), np.concatenate([decode_int64(r[1]) for r in rows]))

    def _write_chunks(
        self, conn: Connection, sat_id: int, upload_id: int, batch: PacketBatch, known: dict[str, int]
    ) -> int:
        """Write a time-ordered batch of new packets as archive chunks; the samples its columns lack (NaN)."""
        param_ids = self._parameter_ids(conn, sat_id, batch.apid, list(batch.values), known)
        bounds = list(range(0, batch.n_packets, CHUNK_PACKETS)) + [batch.n_packets]
        raw = np.frombuffer(batch.raw, dtype=np.uint8)
        byte_ends = np.concatenate(([0], np.cumsum(batch.raw_lengths)))
        chunk_rows = [
            (
                sat_id,
                upload_id,
                batch.apid,
                int(batch.t_utc_ns[lo]),
                int(batch.t_utc_ns[hi - 1]),
                hi - lo,
                encode_int64(batch.t_utc_ns[lo:hi]),
                encode_int64(batch.seq_count[lo:hi]),
                encode_int64(batch.raw_lengths[lo:hi]),
                encode_raw(raw[byte_ends[lo] : byte_ends[hi]]),
            )
            for lo, hi in zip(bounds[:-1], bounds[1:])
        ]
        chunk_ids = insert_returning_ids(conn, CHUNK, _CHUNK_COLUMNS, chunk_rows)
        names = list(batch.values)
        rows: list[list[tuple[Any, ...]]] = [[] for _ in names]  # per column, its rows in chunk order
        groups = value_matrices(batch.values)
        for dtype, members, matrix in groups:
            presented = _INT64 if dtype.kind in "iu" and dtype != _UINT64 else None  # integers read back as int64
            for chunk_id, lo, hi in zip(chunk_ids, bounds[:-1], bounds[1:]):
                for i, (spec, blob, v_min, v_max) in zip(members, encode_value_rows(matrix[:, lo:hi], presented)):
                    rows[i].append((param_ids[names[i]], chunk_id, spec, v_min, v_max, blob))
        value_rows = [row for column_rows in rows for row in column_rows]  # by parameter, then chunk, as ever
        if value_rows:
            insert_rows(conn, VALUE, _VALUE_COLUMNS, value_rows)
        return sum(absent_in_rows(matrix) for _, _, matrix in groups)  # NaN: samples the columns lack

    def _parameter_ids(
        self, conn: Connection, sat_id: int, apid: int, names: list[str], known: dict[str, int]
    ) -> dict[str, int]:
        """Ids of the satellite's parameters ``names`` (added with ``apid`` when new); ``known`` (ids found before
        in this transaction) is consulted first and updated."""
        names = [n for n in names if n not in known]
        if not names:
            return known
        rows = fetch_rows(conn, _PARAMETER_IDS, {"sat": sat_id, "names": names})
        ids = {name: int(param_id) for name, param_id in rows}  # a parameter telemetered in several packets: one series
        missing = [(sat_id, n, apid) for n in names if n not in ids]
        if missing:  # their ids as they are inserted (SQLite: lastrowid; else INSERT ... RETURNING), no select again
            added = insert_returning_ids(conn, PARAM, ("satellite_id", "name", "apid"), missing)
            ids.update(zip([row[1] for row in missing], added))
        known.update(ids)
        return known

    # --- reading -------------------------------------------------------------------------
    def satellites(self, exclude_apids: Sequence[int] = ()) -> list[dict[str, Any]]:
        """Every registered satellite, by name: ``name``, ``norad_id`` and the first/last archived packet time
        (``first_t_ns``, ``last_t_ns``; None when nothing is archived), packets of ``exclude_apids`` not counted."""
        on = CHUNK.c.satellite_id == SAT.c.id
        if exclude_apids:
            on = on & CHUNK.c.apid.not_in(list(exclude_apids))
        query = (
            select(SAT.c.name, SAT.c.norad_id, func.min(CHUNK.c.t_start_ns), func.max(CHUNK.c.t_end_ns))
            .select_from(SAT.outerjoin(CHUNK, on))
            .group_by(SAT.c.id, SAT.c.name, SAT.c.norad_id)
            .order_by(SAT.c.name)
        )
        with self.engine.connect() as conn:
            rows = conn.execute(query).all()
        return [
            {
                "name": name,
                "norad_id": norad,
                "first_t_ns": None if t0 is None else int(t0),
                "last_t_ns": None if t1 is None else int(t1),
            }
            for name, norad, t0, t1 in rows
        ]

    def parameters(self, satellite: str) -> dict[str, int]:
        """Archived parameter names of ``satellite`` with the APID that first carried each."""
        sat_id = self._known_satellite(satellite)
        with self.engine.connect() as conn:
            return dict(conn.execute(select(PARAM.c.name, PARAM.c.apid).where(PARAM.c.satellite_id == sat_id)).all())

    def read_parameter(self, satellite: str, name: str, t0_ns: int, t1_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Time-ordered (t_utc_ns, values) of a parameter with t0_ns <= t <= t1_ns."""
        if t1_ns < t0_ns:
            raise ValueError(f"t1_ns: {t1_ns} is before t0_ns {t0_ns}")
        sat_id = self._known_satellite(satellite)
        with self.engine.connect() as conn:
            param = conn.execute(
                select(PARAM.c.id, PARAM.c.apid).where(PARAM.c.satellite_id == sat_id, PARAM.c.name == name)
            ).one_or_none()
            if param is None:
                raise ValueError(f"name: no parameter {name!r} archived for {satellite!r}")
            rows = conn.execute(
                select(CHUNK.c.t_blob, VALUE.c.dtype, VALUE.c.v_blob)
                .join(VALUE, VALUE.c.chunk_id == CHUNK.c.id)
                .where(
                    CHUNK.c.satellite_id == sat_id,
                    VALUE.c.parameter_id == param.id,
                    CHUNK.c.t_start_ns <= t1_ns,
                    CHUNK.c.t_end_ns >= t0_ns,
                )
                .order_by(CHUNK.c.t_start_ns)
            ).all()
        if not rows:
            return np.empty(0, np.int64), np.empty(0, np.float64)
        t = np.concatenate([decode_int64(r[0]) for r in rows])
        v = np.concatenate([decode_values(r[1], r[2]) for r in rows])
        return _ordered_window(t, v, t0_ns, t1_ns)

    def series_layout(self, satellite: str, names: Sequence[str]) -> tuple[dict[str, np.dtype], np.ndarray]:
        """Per parameter the dtype its samples were archived with (float64 when chunks differ), and the
        (t_start_ns, t_end_ns, n_packets) of every chunk holding any of them, by start time."""
        sat_id = self._known_satellite(satellite)
        with self.engine.connect() as conn:
            params = dict(
                conn.execute(
                    select(PARAM.c.name, PARAM.c.id).where(
                        PARAM.c.satellite_id == sat_id, PARAM.c.name.in_(list(names))
                    )
                ).all()
            )
            unknown = [n for n in names if n not in params]
            if unknown:
                raise ValueError(f"names: not archived for {satellite!r}: {unknown}")
            kinds = conn.execute(
                select(VALUE.c.parameter_id, VALUE.c.dtype)
                .where(VALUE.c.parameter_id.in_(list(params.values())))
                .distinct()
            ).all()
            spans = conn.execute(
                select(CHUNK.c.t_start_ns, CHUNK.c.t_end_ns, CHUNK.c.n_packets)
                .where(CHUNK.c.id.in_(select(VALUE.c.chunk_id).where(VALUE.c.parameter_id.in_(list(params.values())))))
                .order_by(CHUNK.c.t_start_ns)
            ).all()
        presented: dict[int, set[str]] = {}
        for param_id, spec in kinds:
            presented.setdefault(param_id, set()).add(spec.split("/")[-1])
        dtypes = {
            n: np.dtype(next(iter(presented.get(i, {"<f8"}))) if len(presented.get(i, ())) == 1 else np.float64)
            for n, i in params.items()
        }
        return dtypes, np.array(spans, dtype=np.int64).reshape(-1, 3)

    def latest_values(self, satellite: str, names: Sequence[str] | None = None) -> dict[str, tuple[int, float]]:
        """Newest (t_utc_ns, value) of each parameter (all archived ones by default)."""
        sat_id = self._known_satellite(satellite)
        with self.engine.connect() as conn:
            query = select(PARAM.c.id, PARAM.c.name).where(PARAM.c.satellite_id == sat_id)
            if names is not None:
                query = query.where(PARAM.c.name.in_(list(names)))
            params = conn.execute(query).all()
            latest = {}
            for param_id, name in params:
                row = conn.execute(
                    select(CHUNK.c.t_blob, VALUE.c.dtype, VALUE.c.v_blob)
                    .join(VALUE, VALUE.c.chunk_id == CHUNK.c.id)
                    .where(VALUE.c.parameter_id == param_id)
                    .order_by(CHUNK.c.t_end_ns.desc())
                    .limit(1)
                ).one()
                t, v = decode_int64(row[0]), decode_values(row[1], row[2])
                i = int(np.argmax(t))
                latest[name] = (int(t[i]), v[i].item())
        if names is not None and (unknown := set(names) - set(latest)):
            raise ValueError(f"names: not archived: {sorted(unknown)}")
        return latest

    def packet_keys(
        self, satellite: str, t0_ns: int, t1_ns: int, apid: int | None = None
    ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Per APID, time-ordered (t_utc_ns, seq_count) of archived packets in [t0_ns, t1_ns]."""
        sat_id = self._known_satellite(satellite)
        query = select(CHUNK.c.apid, CHUNK.c.t_blob, CHUNK.c.seq_blob).where(
            CHUNK.c.satellite_id == sat_id, CHUNK.c.t_start_ns <= t1_ns, CHUNK.c.t_end_ns >= t0_ns
        )
        if apid is not None:
            query = query.where(CHUNK.c.apid == apid)
        with self.engine.connect() as conn:
            rows = conn.execute(query.order_by(CHUNK.c.apid, CHUNK.c.t_start_ns)).all()
        per_apid: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        for row_apid, t_blob, seq_blob in rows:
            per_apid.setdefault(int(row_apid), []).append((decode_int64(t_blob), decode_int64(seq_blob)))
        return {
            a: _ordered_window(
                np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]), t0_ns, t1_ns
            )
            for a, parts in per_apid.items()
        }

    def replay(self, satellite: str, t0_ns: int, t1_ns: int, apid: int | None = None) -> list[tuple[int, bytes]]:
        """Archived raw packets (t_utc_ns, bytes) in [t0_ns, t1_ns], time-ordered, byte-exact."""
        sat_id = self._known_satellite(satellite)
        query = select(CHUNK.c.t_blob, CHUNK.c.length_blob, CHUNK.c.raw_blob).where(
            CHUNK.c.satellite_id == sat_id, CHUNK.c.t_start_ns <= t1_ns, CHUNK.c.t_end_ns >= t0_ns
        )
        if apid is not None:
            query = query.where(CHUNK.c.apid == apid)
        out: list[tuple[int, bytes]] = []
        with self.engine.connect() as conn:
            for t_blob, length_blob, raw_blob in conn.execute(query):
                t, lengths, raw = decode_int64(t_blob), decode_int64(length_blob), decode_raw(raw_blob)
                ends = np.cumsum(lengths)
                out.extend(
                    (int(ti), raw[e - n : e])
                    for ti, e, n in zip(t.tolist(), ends.tolist(), lengths.tolist())
                    if t0_ns <= ti <= t1_ns
                )
        out.sort(key=lambda item: item[0])
        return out

    def uploads(self, satellite: str) -> list[UploadRecord]:
        """Uploads of ``satellite``, oldest first."""
        sat_id = self._known_satellite(satellite)
        with self.engine.connect() as conn:
            rows = conn.execute(select(UPLOAD).where(UPLOAD.c.satellite_id == sat_id).order_by(UPLOAD.c.id)).all()
        return [
            UploadRecord(
                r.id,
                r.uploaded_by,
                r.uploaded_at_ns,
                r.source,
                r.sha256,
                r.packets_accepted,
                r.samples_accepted,
                json.loads(r.report_json),
            )
            for r in rows
        ]

    def upload_contents(self, upload_id: int) -> tuple[int, int]:
        """(packets, samples) actually stored for an upload (to audit it against its report)."""
        with self.engine.connect() as conn:
            packets = conn.execute(
                select(func.coalesce(func.sum(CHUNK.c.n_packets), 0)).where(CHUNK.c.upload_id == upload_id)
            ).scalar_one()
            chunks = conn.execute(select(CHUNK.c.id, CHUNK.c.n_packets).where(CHUNK.c.upload_id == upload_id)).all()
            n_by_chunk = dict(chunks)
            value_chunks = (
                conn.execute(select(VALUE.c.chunk_id).where(VALUE.c.chunk_id.in_(list(n_by_chunk)))).scalars().all()
            )
        return int(packets), int(sum(n_by_chunk[c] for c in value_chunks))

    # --- alarms --------------------------------------------------------------------------
    def alarms(self, satellite: str, *, now_ns: int | None = None, include_cleared: bool = False) -> list[AlarmRecord]:
        """Alarms of ``satellite``; shelved alarms whose shelf time passed are reported active."""
        sat_id = self._known_satellite(satellite)
        now = _now_ns() if now_ns is None else now_ns
        query = select(ALARM).where(ALARM.c.satellite_id == sat_id)
        if not include_cleared:
            query = query.where(ALARM.c.state != "cleared")
        with self.engine.connect() as conn:
            rows = conn.execute(query.order_by(ALARM.c.first_t_ns, ALARM.c.id)).all()
        return [_alarm_record(r, now) for r in rows]

    def alarm_events(self, alarm_id: int) -> list[AlarmEventRecord]:
        """Events of one alarm in the order they happened."""
        with self.engine.connect() as conn:
            rows = conn.execute(
                select(EVENT).where(EVENT.c.alarm_id == alarm_id).order_by(EVENT.c.t_ns, EVENT.c.id)
            ).all()
        return [AlarmEventRecord(r.alarm_id, r.t_ns, r.kind, r.severity, r.value, r.actor) for r in rows]

    def alarm_action(
        self, alarm_id: int, action: str, actor: str, *, t_ns: int | None = None, shelved_until_ns: int | None = None
    ) -> None:
        """Acknowledge, shelve (until ``shelved_until_ns``), unshelve or clear an alarm."""
        _check_name("actor", "the actor's name", actor)
        with self._write() as conn:
            alarm_state.operator_action(
                conn, alarm_id, action, actor, _now_ns() if t_ns is None else t_ns, shelved_until_ns
            )

    # --- passes --------------------------------------------------------------------------
    def save_passes(
        self, satellite: str, station: str, passes: Iterable[tuple[int, int, int, float]], tle_id: int | None = None
    ) -> list[int]:
        """Store predicted passes (aos_ns, los_ns, max_elevation_ns, max_elevation_deg); idempotent on AOS."""
        sat_id, station_id = self.satellite_id(satellite), self.ground_station(station).id
        ids = []
        with self._write() as conn:
            for aos_ns, los_ns, tmax_ns, max_el_deg in passes:
                if not aos_ns <= tmax_ns <= los_ns:
                    raise ValueError(
                        f"passes: need aos_ns <= max_elevation_ns <= los_ns, got {aos_ns, tmax_ns, los_ns}"
                    )
                found = conn.execute(
                    select(PASS.c.id).where(
                        PASS.c.satellite_id == sat_id, PASS.c.station_id == station_id, PASS.c.aos_ns == int(aos_ns)
                    )
                ).scalar()
                if found is None:
                    row = {
                        "satellite_id": sat_id,
                        "station_id": station_id,
                        "tle_id": tle_id,
                        "aos_ns": int(aos_ns),
                        "los_ns": int(los_ns),
                        "max_elevation_ns": int(tmax_ns),
                        "max_elevation_deg": float(max_el_deg),
                        "packets_received": 0,
                        "packets_missing": 0,
                    }
                    found = conn.execute(insert(PASS).values(**row).returning(PASS.c.id)).scalar_one()
                ids.append(int(found))
        return ids

    def save_data_pass(
        self, satellite: str, aos_ns: int, los_ns: int, station: str | None = None, pass_id: int | None = None
    ) -> int:
        """Store (or, with ``pass_id``, widen) a pass made from received data: AOS/LOS = first/last sample."""
        if los_ns < aos_ns:
            raise ValueError(f"passes: need aos_ns <= los_ns, got {aos_ns, los_ns}")
        sat_id = self.satellite_id(satellite)
        station_id = None if station is None else self.ground_station(station).id
        row: dict[str, Any] = {
            "aos_ns": int(aos_ns),
            "los_ns": int(los_ns),
            "max_elevation_ns": (int(aos_ns) + int(los_ns)) // 2,
        }
        with self._write() as conn:
            if pass_id is not None:
                conn.execute(update(PASS).where(PASS.c.id == pass_id, PASS.c.origin == "data").values(**row))
                return pass_id
            row |= {
                "satellite_id": sat_id,
                "station_id": station_id,
                "origin": "data",
                "max_elevation_deg": None,
                "packets_received": 0,
                "packets_missing": 0,
            }
            return int(conn.execute(insert(PASS).values(**row).returning(PASS.c.id)).scalar_one())

    def merge_data_passes(
        self, satellite: str, keep_id: int, merged_ids: Sequence[int], aos_ns: int, los_ns: int, station: str | None
    ) -> int:
        """Make one pass from data out of several, in one transaction: ``keep_id`` spans [aos_ns, los_ns] at
        ``station``, the ``merged_ids`` are deleted (predicted passes are never touched); the kept id."""
        if los_ns < aos_ns:
            raise ValueError(f"passes: need aos_ns <= los_ns, got {aos_ns, los_ns}")
        sat_id = self.satellite_id(satellite)
        station_id = None if station is None else self.ground_station(station).id
        mine = (PASS.c.satellite_id == sat_id) & (PASS.c.origin == "data")
        with self._write() as conn:
            conn.execute(delete(PASS).where(mine, PASS.c.id.in_([int(i) for i in merged_ids if i != keep_id])))
            conn.execute(
                update(PASS)
                .where(mine, PASS.c.id == keep_id)
                .values(
                    aos_ns=int(aos_ns),
                    los_ns=int(los_ns),
                    max_elevation_ns=(int(aos_ns) + int(los_ns)) // 2,
                    station_id=station_id,
                )
            )
        return keep_id

    def passes(self, satellite: str, t0_ns: int, t1_ns: int) -> list[PassRecord]:
        """Passes of ``satellite`` overlapping [t0_ns, t1_ns], in AOS order."""
        sat_id = self._known_satellite(satellite)
        with self.engine.connect() as conn:
            rows = conn.execute(
                select(PASS, STATION.c.name.label("station_name"))
                .outerjoin(STATION, STATION.c.id == PASS.c.station_id)
                .where(PASS.c.satellite_id == sat_id, PASS.c.aos_ns <= t1_ns, PASS.c.los_ns >= t0_ns)
                .order_by(PASS.c.aos_ns)
            ).all()
        return [_pass_record(r) for r in rows]

    def pass_record(self, satellite: str, pass_id: int) -> PassRecord:
        """One pass of ``satellite`` by id."""
        sat_id = self._known_satellite(satellite)
        with self.engine.connect() as conn:
            row = conn.execute(
                select(PASS, STATION.c.name.label("station_name"))
                .outerjoin(STATION, STATION.c.id == PASS.c.station_id)
                .where(PASS.c.satellite_id == sat_id, PASS.c.id == pass_id)
            ).one_or_none()
        if row is None:
            raise ValueError(f"pass_id: no pass {pass_id} for {satellite!r}")
        return _pass_record(row)

    def record_reception(
        self,
        pass_id: int,
        received_start_ns: int | None,
        received_end_ns: int | None,
        packets_received: int,
        packets_missing: int,
    ) -> None:
        """Store what was received during a pass (span, packets, missing packets)."""
        with self._write() as conn:
            conn.execute(
                update(PASS)
                .where(PASS.c.id == pass_id)
                .values(
                    received_start_ns=received_start_ns,
                    received_end_ns=received_end_ns,
                    packets_received=int(packets_received),
                    packets_missing=int(packets_missing),
                )
            )


def _upload_by_sha(conn: Connection, sat_id: int, checksum: str) -> int | None:
    """Id of the satellite's upload with this SHA-256, if any."""
    rows = fetch_rows(conn, _UPLOAD_BY_SHA, {"sat": sat_id, "sha": checksum})
    return int(rows[0][0]) if rows else None


def _batches_sha256(batches: Sequence[PacketBatch]) -> str:
    """Checksum of the raw bytes, or of times and values for batches without raw packets (ground files)."""
    digest = hashlib.sha256()
    for batch in batches:
        digest.update(batch.raw)
        if not batch.raw:
            digest.update(f"{batch.apid}".encode() + batch.t_utc_ns.tobytes() + batch.seq_count.tobytes())
            for name in sorted(batch.values):
                digest.update(name.encode() + np.ascontiguousarray(batch.values[name]).tobytes())
    return digest.hexdigest()


def _merge_by_apid(batches: Sequence[PacketBatch]) -> list[PacketBatch]:
    by_apid: dict[int, list[PacketBatch]] = {}
    for batch in batches:
        by_apid.setdefault(batch.apid, []).append(batch)
    return [parts[0] if len(parts) == 1 else _concatenate(parts) for parts in by_apid.values()]


def _concatenate(parts: list[PacketBatch]) -> PacketBatch:
    names = list(parts[0].values)
    if any(list(p.values) != names for p in parts):
        raise ValueError(f"batches: APID {parts[0].apid} batches carry different parameter sets")
    return PacketBatch(
        parts[0].apid,
        np.concatenate([p.t_utc_ns for p in parts]),
        np.concatenate([p.seq_count for p in parts]),
        b"".join(p.raw for p in parts),
        np.concatenate([p.raw_lengths for p in parts]),
        ColumnMatrices.concatenated([p.values for p in parts], [p.n_packets for p in parts]),
    )


class _PendingBatches:
    """Decoded chunks of one upload gathered per APID into archive chunks of CHUNK_PACKETS packets.

    A file decoded in small chunks (bounded memory) would otherwise commit many small archive chunks,
    each costing a row, a compression call and a min/max per parameter. An APID's packets are written
    once CHUNK_PACKETS are pending, when its parameter set changes (polymorphic layouts), or, largest
    first, while all pending values exceed PENDING_OCTETS (the memory bound); the rest at the end.
    """

    def __init__(self) -> None:
        self.batches: dict[int, list[PacketBatch]] = {}
        self.octets: dict[int, int] = {}

    def add(self, batches: Sequence[PacketBatch]) -> list[PacketBatch]:
        """Take one decoded chunk's batches; return the merged batches to write now (often none)."""
        ready: list[PacketBatch] = []
        for batch in batches:
            parts = self.batches.get(batch.apid, [])
            if parts and list(parts[0].values) != list(batch.values):
                ready.append(self._take(batch.apid))
            self.batches.setdefault(batch.apid, []).append(batch)
            self.octets[batch.apid] = self.octets.get(batch.apid, 0) + _batch_octets(batch)
            if sum(p.n_packets for p in self.batches[batch.apid]) >= CHUNK_PACKETS:
                ready.append(self._take(batch.apid))
        while sum(self.octets.values()) > PENDING_OCTETS:  # the APIDs holding most memory go first
            ready.append(self._take(max(self.octets, key=self.octets.__getitem__)))
        return ready

    def flush(self) -> list[PacketBatch]:
        """Every pending APID's packets, merged, and nothing left pending."""
        return [self._take(apid) for apid in list(self.batches)]

    def _take(self, apid: int) -> PacketBatch:
        parts = self.batches.pop(apid)
        del self.octets[apid]
        return parts[0] if len(parts) == 1 else _concatenate(parts)


def _batch_octets(batch: PacketBatch) -> int:
    """Memory a batch holds: its raw packets and every array its columns keep alive (a column that is a view
    keeps all of the array it views: counted once, whole)."""
    held, bases = {}, {}
    for column in (batch.t_utc_ns, batch.seq_count, batch.raw_lengths, *batch.values.values()):
        base = column.base
        if isinstance(base, np.ndarray):
            bases[id(base)] = base  # columns of one decoded matrix: its chain walked once, not once per column
        else:
            held[id(column)] = column.nbytes
    for base in bases.values():
        while isinstance(base.base, np.ndarray):
            base = base.base
        held[id(base)] = base.nbytes
    return len(batch.raw) + sum(held.values())


def _order_and_dedupe(batch: PacketBatch) -> tuple[PacketBatch, int]:
    t, seq = batch.t_utc_ns, batch.seq_count
    if t.size > 1 and np.all(t[1:] > t[:-1]):
        return batch, 0
    order = np.lexsort((seq, t))
    t_o, s_o = t[order], seq[order]
    keep = np.ones(order.shape, dtype=bool)
    keep[1:] = (t_o[1:] != t_o[:-1]) | (s_o[1:] != s_o[:-1])
    return batch.take(order[keep]), int((~keep).sum())


def _gaps_of(batch: PacketBatch, previous: tuple[int, int] | None = None) -> list[Gap]:
    """Sequence gaps of a time-ordered batch, and before its first packet from ``previous`` (time, count) when it
    follows that one in time."""
    t, seq = batch.t_utc_ns, batch.seq_count
    if previous is not None and t.size and previous[0] < t[0]:
        t, seq = np.concatenate(([previous[0]], t)), np.concatenate(([previous[1]], seq))
    missing = sequence_gaps(seq)
    idx = np.flatnonzero(missing)
    return [Gap(batch.apid, int(t[i - 1]), int(t[i]), int(missing[i])) for i in idx.tolist()]


def _limit_changes(
    batch: PacketBatch, limits: Mapping[str, LimitSet], open_levels: dict[str, tuple[int, int]]
) -> list[alarm_state.LevelChanges]:
    changes: list[alarm_state.LevelChanges] = []
    for name, limit in limits.items():
        if name not in batch.values:
            continue
        values = np.asarray(batch.values[name], dtype=np.float64)
        levels = limit_levels(values, limit)
        idx = level_changes(levels, open_levels.get(name, (0, 0))[1])
        if idx.size:
            changes.append(alarm_state.LevelChanges(name, batch.t_utc_ns[idx], levels[idx], values[idx]))
    return changes


_INT64 = np.dtype(np.int64)
_UINT64 = np.dtype(np.uint64)
_CHUNK_COLUMNS = (
    "satellite_id",
    "upload_id",
    "apid",
    "t_start_ns",
    "t_end_ns",
    "n_packets",
    "t_blob",
    "seq_blob",
    "length_blob",
    "raw_blob",
)
_UNDEFINED_COLUMNS = ("satellite_id", "upload_id", "apid", "n_packets", "seq_blob", "length_blob", "raw_blob")
_VALUE_COLUMNS = ("parameter_id", "chunk_id", "dtype", "v_min", "v_max", "v_blob")


def _ordered_window(t: np.ndarray, v: np.ndarray, t0_ns: int, t1_ns: int) -> tuple[np.ndarray, np.ndarray]:
    if t.size > 1 and np.any(t[1:] < t[:-1]):
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
    lo, hi = np.searchsorted(t, t0_ns, side="left"), np.searchsorted(t, t1_ns, side="right")
    return t[lo:hi], v[lo:hi]


def _alarm_record(row: Row[Any], now_ns: int) -> AlarmRecord:
    state = row.state
    if state == "shelved" and row.shelved_until_ns is not None and row.shelved_until_ns <= now_ns:
        state = "active"
    return AlarmRecord(
        row.id,
        row.parameter,
        state,
        row.severity,
        row.level,
        row.first_t_ns,
        row.last_t_ns,
        row.acknowledged_by,
        row.shelved_until_ns,
    )


def _pass_record(row: Row[Any]) -> PassRecord:
    return PassRecord(
        row.id,
        row.station_name,
        row.aos_ns,
        row.los_ns,
        row.max_elevation_ns,
        row.max_elevation_deg,
        row.received_start_ns,
        row.received_end_ns,
        row.packets_received,
        row.packets_missing,
        row.origin,
    )
