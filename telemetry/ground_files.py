"""Ground-processed telemetry files: CSV and JSON Lines of timed parameter values, validated like packets.

Layout: one row (CSV line or JSON object) per time; a time column ``t_utc`` (ISO 8601, UTC) or
``t_utc_ns`` (int ns since the Unix epoch) and one column per dictionary parameter (raw or
derived), in engineering units; enumeration columns may hold labels or codes; empty = no sample.
Rows are split by the packet that owns each column, so the batches carry that packet's APID
(``packets`` None, sequence counts 0). Unparsable rows are quarantined with their line number and
byte offset (``bad_row``), unknown columns are reported (``unknown_parameter``) and ignored,
times outside the mission window are ``time_out_of_range``; repeated times are duplicates.
CSV lines are located by newline, so quoted fields must not contain line breaks.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np

from telemetry.dictionary import Dictionary, PacketDefinition, parse_utc_ns
from telemetry.ingest_report import ApidSummary, DecodeResult, IngestReport, QuarantineRecord, SampleBatch

__all__ = ["read_ground_file", "read_ground_csv", "read_ground_jsonl", "TIME_COLUMNS"]

TIME_COLUMNS = ("t_utc", "t_utc_ns")


def _line_starts(data: bytes) -> np.ndarray:
    """Byte offset of the start of every line (a final line without newline included)."""
    buf = np.frombuffer(data, dtype=np.uint8)
    starts = np.concatenate([[0], np.flatnonzero(buf == 0x0A) + 1])
    return starts[starts < len(data)] if len(data) else starts[:0]


def _to_float(cells: list[Any], enumeration: dict[int, str]) -> tuple[np.ndarray, np.ndarray]:
    """Float values of text/number cells (None/"" = NaN) and a mask of cells that are not numbers."""
    if not enumeration:
        try:  # vectorised: numpy parses numeric text and numbers alike, None is NaN
            return np.array([None if c == "" else c for c in cells], dtype=np.float64), np.zeros(len(cells), bool)
        except (TypeError, ValueError):
            pass  # some cell is not a number: find which, one by one
    labels = {v: float(k) for k, v in enumeration.items()}
    out = np.full(len(cells), np.nan)
    bad = np.zeros(len(cells), dtype=bool)
    for i, c in enumerate(cells):
        if c is None or c == "":
            continue
        if isinstance(c, str) and c in labels:
            out[i] = labels[c]
            continue
        try:
            out[i] = float(c)
        except (TypeError, ValueError):
            bad[i] = True
    return out, bad


def _to_time_ns(cells: list[Any], column: str) -> tuple[np.ndarray, np.ndarray]:
    """UTC ns of ISO 8601 (``t_utc``) or integer-ns (``t_utc_ns``) cells, and a mask of unreadable ones."""
    try:  # vectorised first; one unreadable cell sends the column to the per-cell path
        if column == "t_utc_ns":
            exact = np.array(cells, dtype=object).astype(np.int64)
            if not np.array_equal(exact.astype(str), np.array(cells, dtype=str)):
                raise ValueError("not integers")
            return exact, np.zeros(len(cells), bool)
        stamps = [c.strip().removesuffix("Z").removesuffix("+00:00") for c in cells]
        return np.array(stamps, dtype="datetime64[ns]").astype(np.int64), np.zeros(len(cells), bool)
    except (TypeError, ValueError, AttributeError, OverflowError):
        pass
    out = np.zeros(len(cells), dtype=np.int64)
    bad = np.zeros(len(cells), dtype=bool)
    for i, c in enumerate(cells):
        try:
            out[i] = int(c) if column == "t_utc_ns" else parse_utc_ns(str(c))
        except (TypeError, ValueError, OverflowError):
            bad[i] = True
    return out, bad


def _validate_rows(
    columns: dict[str, list[Any]],
    row_offset: np.ndarray,
    row_length: np.ndarray,
    line: np.ndarray,
    header_line: int | None,
    dictionary: Dictionary,
    report: IngestReport,
    now_utc_ns: int | None,
) -> list[SampleBatch]:
    """Check rows column by column, then build one time-ordered batch per owning packet."""
    time_col = next((c for c in TIME_COLUMNS if c in columns), None)
    if time_col is None:
        raise ValueError(f"t_utc: a ground file needs a time column, one of {TIME_COLUMNS}")
    t, bad = _to_time_ns(columns[time_col], time_col)
    reasons = np.where(bad, "bad_row", "").astype(object)
    owners: dict[int, list[str]] = {}
    values: dict[str, np.ndarray] = {}
    for name, cells in columns.items():
        if name == time_col:
            continue
        try:
            packet, param = dictionary.parameter(name)
        except ValueError:
            report.quarantined.append(QuarantineRecord(0, 0, "unknown_parameter", line=header_line, detail=name))
            continue
        values[name], bad_cells = _to_float(cells, getattr(param, "enumeration", {}))
        reasons[(reasons == "") & bad_cells] = "bad_row"
        owners.setdefault(packet.apid, []).append(name)
    low, high = dictionary.time_window(now_utc_ns)
    reasons[(reasons == "") & ((t < low) | (t > high))] = "time_out_of_range"
    for i in np.flatnonzero(reasons != ""):
        report.quarantined.append(
            QuarantineRecord(int(row_offset[i]), int(row_length[i]), str(reasons[i]), line=int(line[i]))
        )
    good = reasons == ""
    return [_packet_batch(dictionary.packets[apid], names, t, values, good, report) for apid, names in owners.items()]


def _packet_batch(
    packet: PacketDefinition,
    names: list[str],
    t: np.ndarray,
    values: dict[str, np.ndarray],
    good: np.ndarray,
    report: IngestReport,
) -> SampleBatch:
    """Time-ordered, de-duplicated rows of one packet's columns (rows with at least one value)."""
    has_value = np.any(np.stack([~np.isnan(values[n]) for n in names]), axis=0)
    idx = np.flatnonzero(good & has_value)
    idx = idx[np.argsort(t[idx], kind="stable")]
    repeat = np.zeros(idx.shape, dtype=bool)
    repeat[1:] = t[idx[1:]] == t[idx[:-1]]
    idx = idx[~repeat]
    batch = SampleBatch(
        packet=packet.name,
        apid=packet.apid,
        t_utc_ns=t[idx],
        sequence_count=np.zeros(len(idx), dtype=np.uint16),
        values={n: values[n][idx] for n in names},
    )
    summary = ApidSummary(packet.apid, packet.name, len(idx), duplicates=int(repeat.sum()))
    if len(idx):
        summary.t_first_utc_ns, summary.t_last_utc_ns = int(batch.t_utc_ns[0]), int(batch.t_utc_ns[-1])
    report.apids[packet.apid] = summary
    report.duplicates += int(repeat.sum())
    return batch


def _finish(report: IngestReport, batches: list[SampleBatch]) -> DecodeResult:
    """Totals and ordering of the report."""
    report.quarantined.sort(key=lambda q: (q.offset, q.line or 0))
    report.packets_accepted = sum(len(b.t_utc_ns) for b in batches)
    report.samples_accepted = sum(int(sum(np.count_nonzero(~np.isnan(v)) for v in b.values.values())) for b in batches)
    return DecodeResult(batches=batches, report=report)


def _csv_row(line: str) -> tuple[list[str], str]:
    """The fields of one CSV line and why it is unreadable ("" if readable: no stray CR, no unclosed quote)."""
    if "\r" in line:
        return [], "carriage return inside the line"
    try:
        return next(csv.reader([line], strict=True), []), ""
    except csv.Error as exc:
        return [], f"unreadable CSV: {exc}"


def read_ground_csv(
    data: bytes, dictionary: Dictionary, source: str = "", now_utc_ns: int | None = None
) -> DecodeResult:
    """Validated batches of a CSV of ground-processed values (header row of column names)."""
    report = IngestReport(source=source, octets=len(data))
    starts = _line_starts(data)
    lines = data.decode("utf-8", errors="replace").split("\n")[: len(starts)]  # one row per \n, as starts
    parsed = [_csv_row(line.removesuffix("\r")) for line in lines]
    if not parsed:
        raise ValueError("data: empty CSV, expected a header row with t_utc or t_utc_ns")
    if parsed[0][1]:
        raise ValueError(f"data: line 1 (header): {parsed[0][1]}")
    header, body = parsed[0][0], [fields for fields, _ in parsed[1:]]
    ends = np.append(starts[1:], len(data))
    row_offset, row_length = starts[1 : 1 + len(body)], (ends - starts)[1 : 1 + len(body)]
    short = [i for i, (fields, problem) in enumerate(parsed[1:]) if problem or len(fields) != len(header)]
    for i in short:
        detail = parsed[i + 1][1] or f"{len(body[i])} fields, header has {len(header)}"
        report.quarantined.append(
            QuarantineRecord(int(row_offset[i]), int(row_length[i]), "bad_row", line=i + 2, detail=detail)
        )
    keep = np.setdiff1d(np.arange(len(body)), short)
    kept_rows = [body[i] for i in keep] if short else body
    columns = dict(zip(header, (list(c) for c in zip(*kept_rows)))) if kept_rows else {name: [] for name in header}
    batches = _validate_rows(columns, row_offset[keep], row_length[keep], keep + 2, 1, dictionary, report, now_utc_ns)
    return _finish(report, batches)


def read_ground_jsonl(
    data: bytes, dictionary: Dictionary, source: str = "", now_utc_ns: int | None = None
) -> DecodeResult:
    """Validated batches of JSON Lines (one object of column → value per line) of ground-processed values."""
    report = IngestReport(source=source, octets=len(data))
    starts = _line_starts(data)
    ends = np.append(starts[1:], len(data))
    objects, offsets, lengths = [], [], []
    for line_no, (s, e) in enumerate(zip(starts.tolist(), ends.tolist()), start=1):
        line = data[s:e].strip()
        if not line:
            continue
        try:
            obj = json.loads(line)
            if not isinstance(obj, dict):
                raise ValueError("not an object")
        except (ValueError, RecursionError) as exc:  # RecursionError: nested deeper than the parser's stack
            report.quarantined.append(QuarantineRecord(s, e - s, "bad_row", line=line_no, detail=str(exc)[:80]))
            continue
        objects.append((line_no, obj))
        offsets.append(s)
        lengths.append(e - s)
    names = list(dict.fromkeys(k for _, obj in objects for k in obj))
    columns = {name: [obj.get(name) for _, obj in objects] for name in names}
    line_numbers = np.array([n for n, _ in objects], dtype=np.int64)
    batches = _validate_rows(
        columns,
        np.array(offsets, dtype=np.int64),
        np.array(lengths, dtype=np.int64),
        line_numbers,
        None,
        dictionary,
        report,
        now_utc_ns,
    )
    return _finish(report, batches)


def read_ground_file(path: str | Path, dictionary: Dictionary, now_utc_ns: int | None = None) -> DecodeResult:
    """Validated batches of a ``.csv`` or ``.jsonl`` ground file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return read_ground_csv(path.read_bytes(), dictionary, str(path), now_utc_ns)
    if suffix in (".jsonl", ".ndjson"):
        return read_ground_jsonl(path.read_bytes(), dictionary, str(path), now_utc_ns)
    raise ValueError(f"path: expected a .csv or .jsonl ground file, got {path.name}")
