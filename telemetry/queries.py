"""Queries on the archive (issue 5): downsampled series, latest values, pass summary, exports.

Downsampling splits [t0, t1] into N equal time buckets and gives per bucket the sample count,
min, max and mean (empty buckets: count 0 and NaN), the min/max envelope a plot needs so that
spikes survive any zoom level.  Exports are wide tables: one row per distinct sample time, one
column per parameter (empty where a parameter has no sample at that time).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from telemetry.archive import Archive, Gap, sequence_gaps

__all__ = [
    "Downsampled",
    "bucket_statistics",
    "downsample",
    "latest_values",
    "gaps",
    "pass_summary",
    "export_table",
    "export_csv",
    "export_parquet",
]


@dataclass(frozen=True)
class Downsampled:
    """Per-bucket statistics of one parameter: bucket start/end (UTC ns), count, min, max, mean."""

    t_start_ns: np.ndarray
    t_end_ns: np.ndarray
    count: np.ndarray
    minimum: np.ndarray
    maximum: np.ndarray
    mean: np.ndarray


def bucket_statistics(t_ns: np.ndarray, values: np.ndarray, t0_ns: int, t1_ns: int, n_buckets: int) -> Downsampled:
    """Count/min/max/mean of time-sorted samples in n equal buckets spanning [t0_ns, t1_ns]."""
    if n_buckets < 1:
        raise ValueError(f"n_points: expected at least 1 bucket, got {n_buckets}")
    if t1_ns <= t0_ns:
        raise ValueError(f"t1_ns: {t1_ns} must be after t0_ns {t0_ns}")
    t = np.asarray(t_ns, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    edges = t0_ns + ((t1_ns - t0_ns) * np.arange(n_buckets + 1, dtype=np.float64) / n_buckets).astype(np.int64)
    edges[-1] = t1_ns + 1  # the last bucket is closed on the right
    inside = (t >= t0_ns) & (t <= t1_ns)
    t, v = t[inside], v[inside]
    bucket = np.searchsorted(edges, t, side="right") - 1
    count = np.bincount(bucket, minlength=n_buckets)
    total = np.bincount(bucket, weights=v, minlength=n_buckets)
    minimum = np.full(n_buckets, np.nan)
    maximum = np.full(n_buckets, np.nan)
    filled = np.flatnonzero(count)
    if filled.size:
        starts = np.searchsorted(bucket, filled, side="left")
        minimum[filled] = np.minimum.reduceat(v, starts)
        maximum[filled] = np.maximum.reduceat(v, starts)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.nan)
    return Downsampled(edges[:-1], np.minimum(edges[1:], t1_ns), count, minimum, maximum, mean)


def downsample(archive: Archive, satellite: str, name: str, t0_ns: int, t1_ns: int, n_points: int) -> Downsampled:
    """One parameter over [t0_ns, t1_ns] reduced to ``n_points`` min/max/mean buckets."""
    t, v = archive.read_parameter(satellite, name, t0_ns, t1_ns)
    return bucket_statistics(t, v, t0_ns, t1_ns, n_points)


def latest_values(archive: Archive, satellite: str, names: list[str] | None = None) -> dict[str, tuple[int, float]]:
    """Newest (t_utc_ns, value) of each parameter."""
    return archive.latest_values(satellite, names)


def gaps(archive: Archive, satellite: str, t0_ns: int, t1_ns: int) -> list[Gap]:
    """Sequence-count gaps (CCSDS 133.0-B-2 §4.1.3.4.2.2, modulo 2**14) of every APID in [t0_ns, t1_ns]."""
    found: list[Gap] = []
    for apid, (t, seq) in sorted(archive.packet_keys(satellite, t0_ns, t1_ns).items()):
        missing = sequence_gaps(seq)
        found.extend(Gap(apid, int(t[i - 1]), int(t[i]), int(missing[i])) for i in np.flatnonzero(missing).tolist())
    return found


def pass_summary(archive: Archive, satellite: str, pass_id: int) -> dict[str, Any]:
    """A pass with its reception, per-parameter count/min/max/mean and the alarms raised during it."""
    record = archive.pass_record(satellite, pass_id)
    parameters = {}
    for name in sorted(archive.parameters(satellite)):
        _, v = archive.read_parameter(satellite, name, record.aos_ns, record.los_ns)
        if v.size:
            vf = v.astype(np.float64)
            parameters[name] = {
                "count": int(v.size),
                "min": float(np.nanmin(vf)),
                "max": float(np.nanmax(vf)),
                "mean": float(np.nanmean(vf)),
            }
    alarms = [
        a
        for a in archive.alarms(satellite, include_cleared=True)
        if a.first_t_ns <= record.los_ns and a.last_t_ns >= record.aos_ns
    ]
    return {
        "pass": record,
        "completeness": record.completeness,
        "parameters": parameters,
        "alarms": alarms,
    }


def export_table(archive: Archive, satellite: str, names: list[str], t0_ns: int, t1_ns: int) -> pa.Table:
    """Wide table: t_utc_ns, time_utc and one column per parameter (null where not sampled)."""
    if not names:
        raise ValueError("names: at least one parameter to export")
    series = {name: archive.read_parameter(satellite, name, t0_ns, t1_ns) for name in names}
    t_all = np.unique(np.concatenate([t for t, _ in series.values()]))
    columns: dict[str, pa.Array] = {
        "t_utc_ns": pa.array(t_all, type=pa.int64()),
        "time_utc": pa.array(t_all.astype("datetime64[ns]"), type=pa.timestamp("ns", tz="UTC")),
    }
    for name, (t, v) in series.items():
        present = np.zeros(t_all.size, dtype=bool)
        values = np.zeros(t_all.size, dtype=v.dtype if v.size else np.float64)
        at = np.searchsorted(t_all, t)
        present[at], values[at] = True, v
        columns[name] = pa.array(values, mask=~present)
    return pa.table(columns)


def export_csv(archive: Archive, satellite: str, names: list[str], t0_ns: int, t1_ns: int, path: str | Path) -> int:
    """Write the export table as CSV (header row, ISO 8601 UTC times); returns rows written."""
    table = export_table(archive, satellite, names, t0_ns, t1_ns)
    pa_csv.write_csv(table, str(path))
    return int(table.num_rows)


def export_parquet(archive: Archive, satellite: str, names: list[str], t0_ns: int, t1_ns: int, path: str | Path) -> int:
    """Write the export table as Parquet (zstd); returns rows written."""
    table = export_table(archive, satellite, names, t0_ns, t1_ns)
    pq.write_table(table, str(path), compression="zstd")
    return int(table.num_rows)
