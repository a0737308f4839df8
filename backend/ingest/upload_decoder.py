"""Uploaded packet files decoded and archived in a process of the server's own, away from its GIL.

A file of more than one decode chunk (telemetry.packet_files.CHUNK_OCTETS) is decoded and committed by
the upload decoder, a process the server owns (backend.core.processes.become_owned_child: own
process group, SIGTERM when the server dies) and stops with it, at a lower CPU priority (BULK_NICENESS); the
event loop only waits on a pipe, so /health keeps answering during a 200 MB upload
(benchmarks/upload_health.py). A smaller file costs
less to decode than a round trip to the process and is decoded in a thread of the server.

Bad input loses nothing: a file is committed in one transaction (telemetry.archive), so a decoder that
dies mid-file leaves nothing of it archived; the file (still on disk) is then decoded by a fresh
process, and if that one dies too the upload is refused with 503, nothing archived, and may be sent
again.

Decoders are forked by a multiprocessing fork server (started with the first one, single-threaded, with the
decoder's modules imported and its numba kernels loaded: PRELOAD), so a decoder replacing a dead one starts in
milliseconds instead of importing numpy, numba, SQLAlchemy and the telemetry package and loading the kernels
again (seconds of CPU). The fork server lowers its own priority to BULK_NICENESS before it imports anything
(backend.ingest.decoder_warmup, first in PRELOAD): its imports and warm-up, and every decoder it forks (they inherit
it), run below the server's requests.
"""

from __future__ import annotations

import multiprocessing as mp
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from multiprocessing.sharedctypes import Synchronized
from pathlib import Path
from typing import Protocol, TypeVar, cast

from backend.core.errors import ApiError
from telemetry.archive import Archive, IngestResult
from telemetry.archive.records import PassRecord
from telemetry.dictionary import Dictionary
from telemetry.ingest_report import DecodeResult, IngestReport, SampleBatch
from telemetry.limits import dictionary_limits

__all__ = [
    "PacketFileJob",
    "PacketFileOutcome",
    "RedecodeJob",
    "RedecodeOutcome",
    "UploadDecoder",
    "archive_packet_file",
    "redecode_kept",
]

T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)

REPLY_POLL_S = 0.2  # how often a waiting request checks that the decoder is still alive
STOP_GRACE_S = 5.0  # a decoder mid-file rolls back at once on SIGTERM
PRELOAD = [  # imported once by the fork server, not by each decoder it forks
    "backend.ingest.decoder_warmup",  # first: lowers the fork server's priority, then loads the decode kernels
    __name__,
    "backend.ingest.dictionary_catalogue",
    "telemetry.decoding",
    "telemetry.packet_files",
    "telemetry.passes",
]


class DecoderJob(Protocol[T_co]):
    """Work for the decoder process: a dictionary to load there and what to do with it."""

    @property
    def dictionary(self) -> str: ...

    def perform(
        self, archive: Archive, dictionary: Dictionary, on_octets: Callable[[int], None] | None = None
    ) -> T_co: ...


@dataclass(frozen=True)
class PacketFileJob:
    """One packet file to decode and archive as one upload."""

    path: Path
    satellite: str
    dictionary: str
    source: str
    uploaded_by: str

    def perform(
        self, archive: Archive, dictionary: Dictionary, on_octets: Callable[[int], None] | None = None
    ) -> PacketFileOutcome:
        """archive_packet_file of this job."""
        return archive_packet_file(archive, self, dictionary, on_octets)


@dataclass(frozen=True)
class RedecodeJob:
    """Packets of a satellite kept raw for want of a definition, decoded with ``dictionary`` (the APIDs it defines,
    or only ``apids``) and archived as one upload."""

    satellite: str
    dictionary: str
    apids: tuple[int, ...]
    uploaded_by: str

    def perform(
        self, archive: Archive, dictionary: Dictionary, on_octets: Callable[[int], None] | None = None
    ) -> RedecodeOutcome:
        """redecode_kept of this job."""
        return redecode_kept(archive, self, dictionary, on_octets)


@dataclass(frozen=True)
class PacketFileOutcome:
    """What archiving a packet file did: decode report, archive result, time span, passes, and the batches of a
    one-chunk file (the ones published live; a longer file is a backfill, see TelemetryGateway)."""

    report: IngestReport
    result: IngestResult
    chunks: int
    span_ns: tuple[int, int] | None
    passes: list[PassRecord] = field(default_factory=list)
    first_batches: list[SampleBatch] = field(default_factory=list)


@dataclass(frozen=True)
class RedecodeOutcome:
    """What decoding kept raw packets did: decode report, archive result (None: none kept), span and passes."""

    apids: tuple[int, ...]
    report: IngestReport
    result: IngestResult | None
    span_ns: tuple[int, int] | None
    passes: list[PassRecord] = field(default_factory=list)


def redecode_kept(
    archive: Archive, job: RedecodeJob, dictionary: Dictionary, on_octets: Callable[[int], None] | None = None
) -> RedecodeOutcome:
    """Decode the packets kept raw of the APIDs ``dictionary`` defines (Archive.redecode_undefined) and make the
    passes of their data; ValueError naming ``apid`` for an APID the dictionary does not define."""
    from telemetry import passes
    from telemetry.decoding import decode_stream

    foreign = sorted(set(job.apids) - set(dictionary.packets))
    if foreign:
        raise ValueError(f"apid: dictionary {job.dictionary} defines no APID {foreign[0]}")
    apids = tuple(sorted(job.apids or dictionary.packets))
    source = f"redecode of APIDs {', '.join(map(str, apids))} with {job.dictionary}"
    report = IngestReport(source=source)
    spans: list[tuple[int, int]] = []

    def decode(octets: bytes) -> DecodeResult:
        decoded = decode_stream(octets, dictionary, source=source)
        spans.extend((int(b.t_utc_ns.min()), int(b.t_utc_ns.max())) for b in decoded.batches if len(b.t_utc_ns))
        if on_octets is not None:
            on_octets(len(octets))
        return decoded

    result = archive.redecode_undefined(
        job.satellite,
        apids,
        decode,
        source=source,
        uploaded_by=job.uploaded_by,
        report=report,
        limits=dictionary_limits(dictionary),
    )
    span = (min(s[0] for s in spans), max(s[1] for s in spans)) if spans else None
    made = passes.passes_from_data(archive, job.satellite, *span) if span and result is not None else []
    return RedecodeOutcome(apids, report, result, span, made)


def archive_packet_file(
    archive: Archive,
    job: PacketFileJob,
    dictionary: Dictionary,
    on_octets: Callable[[int], None] | None = None,
) -> PacketFileOutcome:
    """Decode ``job``'s file chunk by chunk, commit it as one upload, make the passes of its data (new uploads).

    ``on_octets(n)`` hears the octets each chunk consumed (the decoder's progress).
    """
    from telemetry import packet_files, passes

    first: list[SampleBatch] = []
    spans: list[tuple[int, int]] = []
    chunks = 0

    def on_chunk(decoded: DecodeResult) -> None:
        nonlocal chunks
        chunks += 1
        spans.extend((int(b.t_utc_ns.min()), int(b.t_utc_ns.max())) for b in decoded.batches if len(b.t_utc_ns))
        first.extend(decoded.batches if chunks == 1 else [])
        if chunks == 2:
            first.clear()
        if on_octets is not None:
            on_octets(decoded.consumed)

    report, result = packet_files.ingest_packet_file(
        archive,
        job.path,
        dictionary,
        satellite=job.satellite,
        uploaded_by=job.uploaded_by,
        limits=dictionary_limits(dictionary),
        source=job.source,
        on_chunk=on_chunk,
    )
    if result is None:
        raise RuntimeError("packet_files.ingest_packet_file returned no archive result")
    span = (min(s[0] for s in spans), max(s[1] for s in spans)) if spans else None
    made = passes.passes_from_data(archive, job.satellite, *span) if span and not result.duplicate_upload else []
    return PacketFileOutcome(report, result, chunks, span, made, first if chunks == 1 else [])


def _serve(jobs: Connection, database_url: str, dictionaries_dir: str, progress: Synchronized[int]) -> None:
    """The decoder process: one job at a time from ``jobs``, ("ok", outcome) or ("error", exception) back."""
    from backend.core.processes import become_owned_child
    from backend.ingest.dictionary_catalogue import DictionaryCatalogue

    become_owned_child()  # at BULK_NICENESS already: the fork server's (backend.ingest.decoder_warmup)
    archive = Archive(database_url, migrate=False)  # the server migrated it

    def advance(octets: int) -> None:
        with progress.get_lock():
            progress.value += octets

    while True:
        try:
            job = jobs.recv()
        except (EOFError, OSError):  # the server closed its end
            return
        if job is None:
            return
        progress.value = 0
        try:
            dictionary = DictionaryCatalogue(Path(dictionaries_dir)).load(job.dictionary)  # fresh: may be replaced
            reply: tuple[str, object] = ("ok", job.perform(archive, dictionary, advance))
        except Exception as exc:  # sent back and raised in the server, as if decoded there
            reply = ("error", exc)
        try:
            jobs.send(reply)
        except Exception as exc:  # an exception that does not pickle
            jobs.send(("error", RuntimeError(f"{type(reply[1]).__name__}: {reply[1]} ({exc})")))


class _DecoderDied(Exception):
    """The decoder process exited before answering."""


class UploadDecoder:
    """The server's upload-decoding process: started on first use, one file at a time, replaced when it dies."""

    def __init__(self, database_url: str, dictionaries_dir: Path) -> None:
        self._database_url, self._dictionaries_dir = database_url, dictionaries_dir
        self._ctx = mp.get_context("forkserver")
        self._ctx.set_forkserver_preload(PRELOAD)  # for the fork server this process starts (first decoder)
        self._progress: Synchronized[int] | None = None  # made with the first decoder (a semaphore: a tracker process)
        self._busy = threading.Lock()
        self._process: BaseProcess | None = None
        self._jobs: Connection | None = None
        self._stopping = False

    @property
    def pid(self) -> int | None:
        """The decoder's process id while it runs, else None."""
        process = self._process
        return process.pid if process is not None and process.is_alive() else None

    @property
    def octets_decoded(self) -> int:
        """Octets of the current (or last) file decoded so far."""
        return 0 if self._progress is None else int(self._progress.value)

    def run(self, job: DecoderJob[T]) -> T:
        """Perform ``job`` in the decoder process (blocking: call from a thread); a second death of the decoder
        on the same job is a 503 with nothing of it archived."""
        with self._busy:
            for _attempt in range(2):
                if self._stopping:
                    raise ApiError(503, "body: the server is stopping; nothing of this upload was archived", "body")
                try:
                    jobs = self._started()
                    jobs.send(job)
                    kind, payload = self._reply(jobs)
                except (_DecoderDied, OSError):  # OSError: the pipe broke as it died
                    self._discard()
                    continue
                if kind == "error":
                    assert isinstance(payload, BaseException)
                    raise payload
                return cast(T, payload)
        raise ApiError(
            503, "body: the upload decoder died twice on this work; nothing of it was archived (send it again)", "body"
        )

    def _started(self) -> Connection:
        if self._process is None or self._jobs is None or not self._process.is_alive():
            self._discard()
            if self._progress is None:
                self._progress = self._ctx.Value("q", 0)
            self._progress.value = 0
            ours, theirs = self._ctx.Pipe()
            args = (theirs, self._database_url, str(self._dictionaries_dir), self._progress)
            process = self._ctx.Process(target=_serve, args=args, name="acs-twin-upload-decoder", daemon=True)
            process.start()
            theirs.close()
            self._process, self._jobs = process, ours
        return self._jobs

    def _reply(self, jobs: Connection) -> tuple[str, object]:
        process = self._process
        assert process is not None
        while True:
            try:
                if jobs.poll(REPLY_POLL_S):
                    kind, payload = jobs.recv()
                    return str(kind), payload
            except (EOFError, OSError) as exc:
                raise _DecoderDied from exc
            if not process.is_alive() and not jobs.poll(0):
                raise _DecoderDied

    def _discard(self) -> None:
        """Forget (and reap) a dead or stopping decoder."""
        if self._jobs is not None:
            self._jobs.close()
        if self._process is not None:
            _stop(self._process)
        self._process, self._jobs = None, None

    def stop(self) -> None:
        """Stop the decoder (a file mid-decode rolls back: nothing of it archived) and refuse further files."""
        self._stopping = True
        process = self._process
        if process is not None:
            _stop(process)
        with self._busy:  # a waiting request has seen the death and left
            self._discard()


def _stop(process: BaseProcess) -> None:
    """SIGTERM the decoder's process group, then SIGKILL (backend.core.processes.stop_owned), reaped."""
    from backend.core.processes import stop_owned

    if process.is_alive():
        stop_owned(process, STOP_GRACE_S)
    if process.is_alive():  # killed before it made its own process group
        process.kill()
    process.join(STOP_GRACE_S)
