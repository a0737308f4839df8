"""zstd alone on the archive's own inputs (issue 12): CPU and stored octets of the codec configurations measured.

    .venv/bin/python benchmarks/compression.py [--repeats 7] [--only CYGNSS]

Records what ``telemetry.archive.chunks`` hands to zstd during one ingest of each ``benchmarks/foreign.py``
case (its replicated ~40 MB file, NOAA-20 ~10 MB), of the case's original file from tests/data or ../shared
(one copy: what real data compresses like; the replicated files repeat a 15-510 KB source and compress
25-100:1) and of the emulated reference satellite's 4-minute pass: single buffers (delta-coded times,
sequence counts and lengths, raw packets) and value row matrices (one ``multi_compress_to_buffer`` call
each). Each configuration then compresses the same inputs, configurations alternated --repeats times in
this process; per configuration the least and median process CPU (zstd's own threads included) and wall,
and the stored octets. Configurations: the archive's (level 1, one call per buffer and per matrix), levels
3 and -1/-3/-5, level 1 with ``threads=2`` in the matrix calls, level 1 with every single buffer of a write
batched into one call with the write's value rows.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import zstandard

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks import foreign  # noqa: E402
from telemetry.archive import Archive, chunks  # noqa: E402
from telemetry.dictionary import load_dictionary  # noqa: E402
from telemetry.emulator import REFERENCE_DICTIONARY, emulate  # noqa: E402
from telemetry.packet_files import ingest_packet_file  # noqa: E402

REFERENCE_SCENARIO, REFERENCE_PASS_S, REFERENCE_EPOCH = "somov-ge4-scan", 240.0, "2026-03-20T00:00:00Z"  # a 4-min pass
Input = tuple[list[bytes], list[np.ndarray]]  # one write's single buffers and value matrices (rows: uint8 octets)


@contextmanager
def recording() -> Iterator[list[Input]]:
    """The zstd inputs of the archive writes made inside the block, one entry per run of calls that starts with
    single buffers (a packet chunk: times, sequence counts, lengths, raw packets; then its value matrices)."""
    writes: list[Input] = []
    single, rows = chunks._compress, chunks._compress_rows

    def record_single(data: bytes | memoryview) -> bytes:
        if not writes or writes[-1][1]:
            writes.append(([], []))
        writes[-1][0].append(bytes(data))
        return single(data)

    def record_rows(block: np.ndarray) -> list[bytes]:
        octets = np.ascontiguousarray(block)
        writes[-1][1].append(octets.view(np.uint8).reshape(octets.shape[0], -1).copy())
        return rows(block)

    chunks._compress, chunks._compress_rows = record_single, record_rows  # type: ignore[assignment]
    try:
        yield writes
    finally:
        chunks._compress, chunks._compress_rows = single, rows  # type: ignore[assignment]


def archive_inputs(path: Path, dictionary: object, workdir: Path) -> list[Input]:
    """The zstd inputs of ingesting ``path`` into a fresh SQLite archive."""
    url = f"sqlite:///{workdir / 'compression.db'}"
    Path(url.removeprefix("sqlite:///")).unlink(missing_ok=True)
    with Archive(url) as archive, recording() as writes:
        ingest_packet_file(archive, path, dictionary, satellite="BENCH", uploaded_by="bench")  # type: ignore[arg-type]
    return writes


def _segments(matrix: np.ndarray) -> zstandard.BufferWithSegments:
    n, width = matrix.shape
    segments = np.empty((n, 2), dtype=np.uint64)
    segments[:, 0] = np.arange(n, dtype=np.uint64) * np.uint64(width)
    segments[:, 1] = width
    return zstandard.BufferWithSegments(matrix.data.cast("B"), segments.tobytes())


def _multi_octets(compressor: zstandard.ZstdCompressor, data: object, threads: int = 0) -> int:
    blobs = compressor.multi_compress_to_buffer(data, threads=threads)
    return sum(len(blobs[i]) for i in range(len(blobs)))


def per_call(level: int, threads: int = 0) -> Callable[[list[Input]], int]:
    """The archive's way at ``level``: one compress per single buffer, one multi call per matrix."""

    def run(writes: list[Input]) -> int:
        compressor = zstandard.ZstdCompressor(level=level)
        octets = 0
        for singles, matrices in writes:
            octets += sum(len(compressor.compress(data)) for data in singles)
            octets += sum(_multi_octets(compressor, _segments(m), threads) for m in matrices if m.size)
        return octets

    return run


def batched(writes: list[Input]) -> int:
    """Level 1, a write's single buffers and every row of its matrices in one multi call (the rows as bytes,
    made before timing would be fairer to it; they are made here, as the archive would have to)."""
    compressor = zstandard.ZstdCompressor(level=1)
    octets = 0
    for singles, matrices in writes:
        octets += _multi_octets(compressor, singles + [row.tobytes() for m in matrices for row in m])
    return octets


CONFIGS: dict[str, Callable[[list[Input]], int]] = {
    "level 1": per_call(1),
    "level 3": per_call(3),
    "level -1": per_call(-1),
    "level -3": per_call(-3),
    "level -5": per_call(-5),
    "1, threads 2": per_call(1, threads=2),
    "1, batched": batched,
}


def compare(label: str, writes: list[Input], repeats: int) -> None:
    """Every configuration on the same inputs, alternated; least and median CPU and wall, stored octets."""
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in CONFIGS}
    stored: dict[str, int] = {}
    for _ in range(repeats):
        for name, config in CONFIGS.items():
            t0, c0 = time.perf_counter(), time.process_time()
            stored[name] = config(writes)
            runs[name].append((time.perf_counter() - t0, time.process_time() - c0))
    given = sum(len(s) for w in writes for s in w[0]) + sum(m.size for w in writes for m in w[1])
    print(f"{label}: {given / 1e6:.2f} MB given to zstd  load {os.getloadavg()[0]:.1f}")
    for name, timed in runs.items():
        wall, cpu = [t[0] * 1e3 for t in timed], [t[1] * 1e3 for t in timed]
        print(
            f"  {name:<13} CPU {min(cpu):6.1f} / {statistics.median(cpu):6.1f} ms  wall {min(wall):6.1f} /"
            f" {statistics.median(wall):6.1f} ms  stored {stored[name] / 1e6:7.3f} MB",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mb", type=float, default=40.0, help="size of each replicated file (MB)")
    parser.add_argument("--repeats", type=int, default=7, help="alternated runs per configuration")
    parser.add_argument("--only", default="", help="cases whose name contains this (e.g. ECM, IDEX)")
    args = parser.parse_args()
    print("per configuration: least / median of --repeats runs")
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        for key, case in foreign.CASES.items():
            if args.only.lower() not in case.label.lower() or not case.source.exists():
                continue
            dictionary = case.dictionary()
            path = workdir / f"{key}.bin"
            case.build(args.mb, path)
            compare(f"{case.label}, replicated", archive_inputs(path, dictionary, workdir), args.repeats)
            compare(f"{case.label}, original file", archive_inputs(case.source, dictionary, workdir), args.repeats)
        if args.only.lower() in "reference pass":
            path = workdir / "reference_pass.bin"
            packets = emulate(REFERENCE_SCENARIO, [], REFERENCE_PASS_S, REFERENCE_EPOCH, truth_seed=None)[2]
            path.write_bytes(packets.data)
            dictionary = load_dictionary(REFERENCE_DICTIONARY)
            compare("reference pass (emulated, nominal)", archive_inputs(path, dictionary, workdir), args.repeats)


if __name__ == "__main__":
    main()
