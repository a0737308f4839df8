"""Packet files of any size: decoded chunk by chunk (bounded memory) and archived as one upload.

A chunk ends on a packet boundary (:func:`telemetry.decoding.decode_stream` with ``final=False``
leaves a trailing, possibly cut segment for the next chunk), so chunked and whole-file decoding
frame the same packets. A chunk is as long as its decoded values allow (:func:`chunk_octets_for`):
peak memory is bounded whatever the file size (benchmarks/foreign.py --memory-gb measures it).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import io
import mmap
import os
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from telemetry.archive import Archive, IngestResult
from telemetry.decoding import decode_stream, decoded_octets_per_octet
from telemetry.dictionary import Dictionary
from telemetry.ingest_report import DecodeResult, IngestReport
from telemetry.limits import LimitSet
from telemetry.validation import SequenceState

__all__ = ["CHUNK_OCTETS", "chunk_octets_for", "decode_chunks", "file_sha256", "ingest_packet_file", "keep_freed_heap"]

CHUNK_OCTETS = 1 << 20  # smallest chunk, 1 MiB: decode CPU +12 % vs 2 MiB, +68 % at 512 KiB
MAX_CHUNK_OCTETS = 8 << 20  # largest: the chunk's octets are copied a few times (framing, raw packets kept)
CHUNK_DECODED_OCTETS = 6 << 20  # decoded octets a chunk may yield at its densest: 1 GB CYGNSS peak RSS, docs/archive.md
# A dictionary whose density is only bounded (XTCE containers, variable layouts: a value per field of the shortest
# packet) gets chunks sized by the values the previous chunk actually yielded, at most this many times the bounded
# size: at worst (a sparse stretch, then the densest packets) a chunk yields 4 x CHUNK_DECODED_OCTETS. IMAP IDEX
# (XTCE) yields 0.09 decoded octets per octet against a bound of 4.5: its 1.4 MB chunks cost ~30 % more CPU than
# 8 MiB ones (per-chunk, per-parameter work), issue 12.
GROWTH = 4
# Chunks decoded at most while the file's SHA-256 is computed beside them (the archive needs the checksum before it
# writes: a repeated upload adds nothing). Each holds at most ~GROWTH x CHUNK_DECODED_OCTETS: bounded memory.
AHEAD_WHILE_HASHING = 3
HASH_WINDOW_OCTETS = 16 << 20  # a multiple of mmap.ALLOCATIONGRANULARITY; one GIL hand-over per window
# glibc malloc: blocks below MMAP_THRESHOLD_OCTETS come from the heap, and the heap keeps up to TRIM_THRESHOLD_OCTETS
# free at its top (see keep_freed_heap); both are the ceilings glibc's own adaptive thresholds reach (32 MiB, twice it)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt parameters, <malloc.h>
MMAP_THRESHOLD_OCTETS = 32 << 20
TRIM_THRESHOLD_OCTETS = 64 << 20


@functools.cache
def keep_freed_heap() -> bool:
    """Have glibc's malloc keep the memory a decoded chunk frees for the next one (once per process; True when set).

    By default glibc maps each block above 128 KiB on its own, unmaps it when freed and only then raises that
    threshold to the block's size (trimming the heap's top at twice it): a process's first large file -- the upload
    decoder's, the CLI's -- freed and faulted its chunks' read buffers, value matrices, raw packets and merged
    archive chunks page by page again, ~10-11 k minor faults (40 MB CYGNSS file) where the working set needs ~7 k:
    sys CPU 0.028-0.039 s of 0.26-0.30 s. With the thresholds at glibc's own ceilings from the start, freed blocks
    stay in the heap for the next chunk (docs/archive.md, issue 12). No effect elsewhere than glibc. Set by
    ingest_packet_file for a file of more than one chunk: in the upload decoder's process and the CLI's, not in the
    server's (it decodes files of one chunk in a thread of its own).
    """
    try:
        if not (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc"):
            return False
        mallopt = ctypes.CDLL(None).mallopt
    except (ValueError, OSError, AttributeError):  # no such confstr name (not glibc), no C library symbols
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_OCTETS)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_OCTETS)
    )


def chunk_octets_for(dictionary: Dictionary) -> int:
    """Decode chunk length for streams of a dictionary: CHUNK_DECODED_OCTETS at its densest packet type
    (telemetry.decoding.decoded_octets_per_octet), within CHUNK_OCTETS..MAX_CHUNK_OCTETS (long chunks cost less
    per octet)."""
    densest = max((decoded_octets_per_octet(p) for p in dictionary.packets.values()), default=0.0)
    fits = int(CHUNK_DECODED_OCTETS / densest) if densest > 0 else MAX_CHUNK_OCTETS
    return min(max(fits, CHUNK_OCTETS), MAX_CHUNK_OCTETS)


def decode_chunks(
    stream: io.BufferedIOBase,
    dictionary: Dictionary,
    source: str = "",
    now_utc_ns: int | None = None,
    chunk_octets: int | None = None,
) -> Iterator[tuple[int, DecodeResult]]:
    """(byte offset of the chunk, its decode result) for consecutive chunks of a packet stream (chunk_octets:
    by default chunk_octets_for the dictionary, grown as GROWTH says where that is only a bound); a stream of at
    most chunk_octets is one chunk.

    Each chunk is read into a buffer of its own behind the octets the previous one left (no other copy); neither
    that buffer nor a yielded result is held while the next chunk is read and decoded (peak memory)."""
    bounded = chunk_octets or chunk_octets_for(dictionary)
    grows = chunk_octets is None and any(p.xtce is not None or p.fields for p in dictionary.packets.values())
    chunk_octets = bounded
    carry: dict[int, SequenceState] = {}  # each APID's accepted packets: gaps and repeats across chunks
    tail, offset = np.empty(0, np.uint8), 0
    while True:
        buffer = np.empty(tail.size + chunk_octets + 1, np.uint8)  # one octet more tells whether the stream ends
        buffer[: tail.size] = tail
        got = _fill(stream, buffer.data[tail.size :])
        held, final = tail.size + got, got <= chunk_octets
        if held == 0:
            return
        result = decode_stream(
            buffer[:held], dictionary, source=source, now_utc_ns=now_utc_ns, final=final, carry=carry
        )
        consumed = result.consumed
        tail = buffer[consumed:held].copy()  # a copy, so that the chunk's buffer goes now, not after the next read
        del buffer
        if grows:
            chunk_octets = _grown(bounded, result)
        yield offset, result
        del result  # the caller is done with it: its arrays go before the next chunk is decoded
        if final:
            return
        offset += consumed


def _grown(bounded: int, result: DecodeResult) -> int:
    """Length of the next chunk after ``result``: CHUNK_DECODED_OCTETS at the density it yielded, from ``bounded``
    up to GROWTH times it (and MAX_CHUNK_OCTETS)."""
    decoded = sum(v.nbytes for b in result.batches for v in b.values.values())
    fits = int(CHUNK_DECODED_OCTETS * result.consumed / decoded) if decoded else MAX_CHUNK_OCTETS
    return max(bounded, min(fits, GROWTH * bounded, MAX_CHUNK_OCTETS))


def _fill(stream: io.BufferedIOBase, view: memoryview) -> int:
    """Octets read into view: until it is full or the stream ends."""
    got = 0
    while got < len(view):
        n = stream.readinto(view[got:])
        if not n:
            break
        got += n
    return got


def _released_then(ahead: list[DecodeResult], rest: Iterator[DecodeResult]) -> Iterator[DecodeResult]:
    """The items of ``ahead`` (each let go of once yielded: bounded memory), then those of ``rest``."""
    ahead.reverse()
    while ahead:
        yield ahead.pop()
    yield from rest


def file_sha256(path: Path, window: int = HASH_WINDOW_OCTETS) -> str:
    """SHA-256 of a file, hashed one memory-mapped window at a time: hashlib releases the GIL for each whole
    window, and an unmapped window's pages leave the process (its peak RSS grows by one window, not the file)."""
    digest = hashlib.sha256()
    size = path.stat().st_size
    with path.open("rb") as f:
        for offset in range(0, size, window):
            with mmap.mmap(f.fileno(), min(window, size - offset), offset=offset, access=mmap.ACCESS_READ) as mapped:
                digest.update(mapped)
    return digest.hexdigest()


def ingest_packet_file(
    archive: Archive | None,
    path: Path,
    dictionary: Dictionary,
    *,
    satellite: str,
    uploaded_by: str,
    limits: Mapping[str, LimitSet] | None = None,
    now_utc_ns: int | None = None,
    chunk_octets: int | None = None,
    source: str | None = None,
    on_chunk: Callable[[DecodeResult], None] | None = None,
) -> tuple[IngestReport, IngestResult | None]:
    """Decode a packet file chunk by chunk and archive it as one upload (archive None: decode and report only).

    on_chunk sees each chunk's decode result before it is archived.
    """
    report = IngestReport(source=source or str(path))
    if path.stat().st_size > CHUNK_OCTETS:  # a file the process decodes in chunks (the server: one chunk at most)
        keep_freed_heap()

    def results() -> Iterator[DecodeResult]:
        with path.open("rb") as f:
            for offset, result in decode_chunks(f, dictionary, report.source, now_utc_ns, chunk_octets):
                report.absorb(result.report, offset)
                if on_chunk is not None:
                    on_chunk(result)
                yield result
                del result  # not held while the next chunk is decoded

    if archive is None:
        for _ in results():
            pass
        return report, None
    with ThreadPoolExecutor(1, thread_name_prefix="file-sha256") as hasher:
        hashing = hasher.submit(file_sha256, path)  # beside the first chunks' decode (the other core)
        chunks = results()
        ahead: list[DecodeResult] = []
        while not hashing.done() and len(ahead) < AHEAD_WHILE_HASHING and (chunk := next(chunks, None)) is not None:
            ahead.append(chunk)
            del chunk
        sha256 = hashing.result()
    stored = archive.ingest_results(
        satellite,
        _released_then(ahead, chunks),
        source=report.source,
        uploaded_by=uploaded_by,
        sha256=sha256,
        limits=limits,
        report=report,
    )
    return report, stored
