"""Full-resolution export: every archived sample of some parameters, one row per time, in bounded windows.

Rows are the union of the parameters' sample times in [t0, t1]; a ``t_utc`` column (UTC, ns) and one
column per parameter, empty where that parameter has no sample at that time. Nothing is downsampled.
The archive is read in windows of about WINDOW_SAMPLES samples (cut between chunk starts), so memory
stays bounded whatever the span and the number of parameters; CSV and Parquet are written and streamed
window by window.
"""

from __future__ import annotations

import io
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from telemetry.archive import Archive

__all__ = [
    "WINDOW_SAMPLES",
    "export_batches",
    "csv_chunks",
    "parquet_chunks",
    "rows_about",
    "write_export",
    "iso_utc_ns",
]

WINDOW_SAMPLES = 250_000  # samples (rows × parameters) per window, at least one archive chunk: a few MB


def iso_utc_ns(t_ns: np.ndarray) -> np.ndarray:
    """ISO 8601 UTC strings with nanoseconds and a ``Z`` (2021-04-09T00:00:00.000000000Z)."""
    return np.char.add(np.datetime_as_string(np.asarray(t_ns, dtype="datetime64[ns]"), unit="ns"), "Z")


def _windows(spans: np.ndarray, t0_ns: int, t1_ns: int, budget: int) -> Iterator[tuple[int, int]]:
    """Consecutive [start, end] windows covering [t0, t1], each cut before a chunk start once ``budget`` packets of
    the chunks starting in it are reached (a window holds at least one chunk)."""
    start, count = t0_ns, 0
    for t_start, _, n in spans.tolist():
        if count >= budget and start < t_start <= t1_ns:
            yield start, t_start - 1
            start, count = t_start, 0
        count += n
    if start <= t1_ns:
        yield start, t1_ns


def rows_about(spans: np.ndarray, t0_ns: int, t1_ns: int) -> int:
    """The export's rows as the chunk spans tell before any is read: each chunk's packets in proportion to the part
    of its span inside [t0, t1], summed (packets of several APIDs at one time count once per APID)."""
    if spans.size == 0:
        return 0
    start, end, n = spans[:, 0].astype(float), spans[:, 1].astype(float), spans[:, 2].astype(float)
    inside = np.clip(np.minimum(end, t1_ns) - np.maximum(start, t0_ns) + 1, 0, None)
    return int(np.ceil(np.sum(n * inside / (end - start + 1))))


def _schema(names: Sequence[str], dtypes: dict[str, np.dtype]) -> pa.Schema:
    return pa.schema([("t_utc", pa.timestamp("ns", tz="UTC"))] + [(n, pa.from_numpy_dtype(dtypes[n])) for n in names])


def export_batches(
    archive: Archive,
    satellite: str,
    names: Sequence[str],
    t0_ns: int,
    t1_ns: int,
    max_rows: int | None = None,
) -> tuple[pa.Schema, Iterator[pa.RecordBatch]]:
    """The schema and the record batches (one per window of about WINDOW_SAMPLES samples, time-ordered) of the
    export; ValueError naming ``end`` when its chunks may hold more than ``max_rows`` rows (checked first)."""
    if not names:
        raise ValueError("parameters: at least one parameter to export")
    if t1_ns < t0_ns:
        raise ValueError(f"end: {t1_ns} is before start {t0_ns}")
    dtypes, spans = archive.series_layout(satellite, names)
    if max_rows is not None and (rows := rows_about(spans, t0_ns, t1_ns)) > max_rows:
        raise ValueError(
            f"end: the window holds about {rows:,} rows, over max_export_rows = {max_rows:,}; "
            "export it in shorter windows (start/end)"
        )
    schema = _schema(names, dtypes)
    budget = max(WINDOW_SAMPLES // len(names), 1)  # packets per window: rows × columns stay near WINDOW_SAMPLES

    def batches() -> Iterator[pa.RecordBatch]:
        for lo, hi in _windows(spans, t0_ns, t1_ns, budget):
            series = {n: archive.read_parameter(satellite, n, lo, hi) for n in names}
            t_all = np.unique(np.concatenate([t for t, _ in series.values()]))
            if t_all.size == 0:
                continue
            columns = [pa.array(t_all.astype("datetime64[ns]"), type=schema.field("t_utc").type)]
            for n in names:
                t, v = series[n]
                present = np.zeros(t_all.size, dtype=bool)
                values = np.zeros(t_all.size, dtype=dtypes[n])
                at = np.searchsorted(t_all, t)
                present[at], values[at] = True, v
                columns.append(pa.array(values, mask=~present, type=schema.field(n).type))
            yield pa.record_batch(columns, schema=schema)

    return schema, batches()


def _csv_text(batch: pa.RecordBatch, header: bool) -> bytes:
    """CSV of one batch, a leading UTC time stamp column (t_utc) as ISO 8601 ``…T…Z`` (ns)."""
    table = pa.Table.from_batches([batch])
    if pa.types.is_timestamp(batch.schema.field(0).type):
        t = batch.column(0).cast(pa.int64()).to_numpy()
        table = pa.table([pa.array(iso_utc_ns(t)), *batch.columns[1:]], names=batch.schema.names)
    sink = io.BytesIO()
    pa_csv.write_csv(table, sink, pa_csv.WriteOptions(include_header=header, quoting_style="needed"))
    return sink.getvalue()


def csv_chunks(schema: pa.Schema, batches: Iterator[pa.RecordBatch]) -> Iterator[bytes]:
    """The export as CSV text, window by window (the header alone when there is no sample)."""
    first = True
    for batch in batches:
        yield _csv_text(batch, header=first)
        first = False
    if first:
        yield (",".join(f'"{n}"' for n in schema.names) + "\n").encode()


class _Chunks(io.RawIOBase):
    """A write-only sink whose written bytes are taken in pieces (Parquet streamed as it is written)."""

    def __init__(self) -> None:
        self._pending: list[bytes] = []
        self._written = 0

    def writable(self) -> bool:
        return True

    def write(self, data: bytes | bytearray | memoryview) -> int:  # type: ignore[override]
        piece = bytes(data)
        self._pending.append(piece)
        self._written += len(piece)
        return len(piece)

    def tell(self) -> int:
        return self._written

    def take(self) -> bytes:
        """The bytes written since the last take."""
        out, self._pending = b"".join(self._pending), []
        return out


def parquet_chunks(schema: pa.Schema, batches: Iterator[pa.RecordBatch]) -> Iterator[bytes]:
    """The export as a Parquet file (zstd), its bytes yielded window by window as they are written."""
    sink = _Chunks()
    with pq.ParquetWriter(sink, schema, compression="zstd") as writer:
        for batch in batches:
            writer.write_batch(batch)
            if piece := sink.take():
                yield piece
    yield sink.take()


def write_export(schema: pa.Schema, batches: Iterator[pa.RecordBatch], sink: BinaryIO | Path, fmt: str) -> int:
    """Write the export as ``csv`` or ``parquet`` (zstd) to a file or binary stream; the number of rows."""
    if fmt not in ("csv", "parquet"):
        raise ValueError(f"format: expected csv or parquet, got {fmt!r}")
    rows = 0

    def counted() -> Iterator[pa.RecordBatch]:
        nonlocal rows
        for batch in batches:
            rows += batch.num_rows
            yield batch

    if fmt == "parquet":
        with pq.ParquetWriter(sink, schema, compression="zstd") as writer:
            for batch in counted():
                writer.write_batch(batch)
        return rows
    out = sink.open("wb") if isinstance(sink, Path) else sink
    try:
        for text in csv_chunks(schema, counted()):
            out.write(text)
    finally:
        if isinstance(sink, Path):
            out.close()
    return rows
