"""Queries: bucket statistics vs a brute-force loop, pass summary, CSV/Parquet exports read back."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from telemetry.archive import Archive, PacketBatch
from telemetry.limits import LimitSet
from telemetry.queries import (
    bucket_statistics,
    downsample,
    export_csv,
    export_parquet,
    gaps,
    latest_values,
    pass_summary,
)
from tests.telemetry.archive_databases import archive, archive_url  # noqa: F401  (fixtures)

SAT = "REF-SAT"
T0_NS = 1_700_000_000 * 10**9
QUARTER_SECOND_NS = 250_000_000
PASS_SAMPLES = 2 * 3_600 * 4  # a 2-hour pass at 4 Hz
N_POINTS = 1_000


def series_batch(apid: int, name: str, values: np.ndarray, period_ns: int, t0_ns: int = T0_NS) -> PacketBatch:
    """Packets of one parameter at a fixed period."""
    n = values.size
    t = t0_ns + np.arange(n, dtype=np.int64) * period_ns
    return PacketBatch.from_packets(apid, t, np.arange(n) % 16_384, [b"\x01\x02"] * n, {name: values})


def brute_force_buckets(t: np.ndarray, v: np.ndarray, t0: int, t1: int, n: int) -> tuple[np.ndarray, ...]:
    """Per-bucket count/min/max/mean by masking each bucket in a Python loop (the obvious way)."""
    edges = np.linspace(t0, t1, n + 1)
    out = []
    for k in range(n):
        upper = t <= edges[k + 1] if k == n - 1 else t < edges[k + 1]
        sel = v[(t >= edges[k]) & upper]
        out.append((sel.size, sel.min(), sel.max(), sel.mean()) if sel.size else (0, np.nan, np.nan, np.nan))
    return tuple(np.array(col) for col in zip(*out))


def test_bucket_statistics_match_a_brute_force_loop() -> None:
    rng = np.random.default_rng(3)
    t = np.sort(rng.integers(T0_NS, T0_NS + 10**12, 20_000))
    v = rng.normal(size=t.size)
    v[rng.integers(0, t.size, 20)] = 50.0  # spikes must survive downsampling
    t1 = T0_NS + 10**12
    ours = bucket_statistics(t, v, T0_NS, t1, 250)
    count, lo, hi, mean = brute_force_buckets(t, v, T0_NS, t1, 250)
    np.testing.assert_array_equal(ours.count, count)
    np.testing.assert_array_equal(ours.minimum, lo)
    np.testing.assert_array_equal(ours.maximum, hi)
    np.testing.assert_allclose(ours.mean, mean, rtol=1e-12)


def test_empty_buckets_are_nan_and_bad_arguments_name_the_field() -> None:
    stats = bucket_statistics(np.array([T0_NS]), np.array([1.0]), T0_NS, T0_NS + 100, 4)
    np.testing.assert_array_equal(stats.count, [1, 0, 0, 0])
    assert np.isnan(stats.maximum[1:]).all()
    with pytest.raises(ValueError, match="n_points"):
        bucket_statistics(np.array([T0_NS]), np.array([1.0]), T0_NS, T0_NS + 100, 0)
    with pytest.raises(ValueError, match="t1_ns"):
        bucket_statistics(np.array([T0_NS]), np.array([1.0]), T0_NS, T0_NS, 3)


def test_two_hour_pass_at_4_hz_downsampled_to_1000_points_keeps_every_sample(archive: Archive) -> None:
    values = np.sin(np.arange(PASS_SAMPLES) / 500.0) + (np.arange(PASS_SAMPLES) == 12_345) * 9.0
    archive.ingest(SAT, [series_batch(10, "rate", values, QUARTER_SECOND_NS)], source="pass", uploaded_by="tester")
    t1 = T0_NS + (PASS_SAMPLES - 1) * QUARTER_SECOND_NS
    stats = downsample(archive, SAT, "rate", T0_NS, t1, N_POINTS)
    t = T0_NS + np.arange(PASS_SAMPLES) * QUARTER_SECOND_NS
    count, lo, hi, mean = brute_force_buckets(t, values, T0_NS, t1, N_POINTS)
    assert stats.count.sum() == PASS_SAMPLES
    np.testing.assert_array_equal(stats.count, count)
    np.testing.assert_array_equal(stats.maximum, hi)
    np.testing.assert_array_equal(stats.minimum, lo)
    assert np.nanmax(stats.maximum) == values.max()


def test_gaps_over_several_uploads_are_counted_from_sequence_counts(archive: Archive) -> None:
    n = 40
    whole = series_batch(10, "x", np.zeros(n), 10**9)
    archive.ingest(SAT, [whole.take(np.arange(0, 10))], source="a", uploaded_by="tester")
    archive.ingest(SAT, [whole.take(np.r_[np.arange(13, 20), np.arange(25, n)])], source="b", uploaded_by="tester")
    found = gaps(archive, SAT, T0_NS, T0_NS + n * 10**9)
    t = whole.t_utc_ns
    assert [(g.apid, g.after_t_ns, g.before_t_ns, g.missing) for g in found] == [
        (10, int(t[9]), int(t[13]), 3),
        (10, int(t[19]), int(t[25]), 5),
    ]


def test_latest_values_and_pass_summary(archive: Archive) -> None:
    temps = np.array([20.0, 21.0, 45.0, 22.0, 23.0])
    archive.ingest(
        SAT,
        [series_batch(10, "temp_c", temps, 10**9)],
        source="hk",
        uploaded_by="tester",
        limits={"temp_c": LimitSet(yellow_high=40.0, red_high=50.0)},
    )
    assert latest_values(archive, SAT) == {"temp_c": (T0_NS + 4 * 10**9, 23.0)}
    archive.add_ground_station("Kiruna", 67.857, 20.964, 400.0, 5.0)
    (pass_id,) = archive.save_passes(SAT, "Kiruna", [(T0_NS + 10**9, T0_NS + 3 * 10**9, T0_NS + 2 * 10**9, 42.0)])
    summary = pass_summary(archive, SAT, pass_id)
    assert summary["parameters"]["temp_c"] == {"count": 3, "min": 21.0, "max": 45.0, "mean": pytest.approx(88.0 / 3)}
    assert [a.parameter for a in summary["alarms"]] == ["temp_c"]
    with pytest.raises(ValueError, match="pass_id"):
        pass_summary(archive, SAT, pass_id + 1)


def test_csv_and_parquet_exports_read_back_to_the_archived_values(archive: Archive, tmp_path: Path) -> None:
    fast = np.arange(8, dtype=np.float64)
    slow = np.array([100, 200], dtype=np.int32)
    archive.ingest(
        SAT,
        [series_batch(10, "fast", fast, QUARTER_SECOND_NS), series_batch(11, "slow", slow, 10**9)],
        source="two-rates",
        uploaded_by="tester",
    )
    t1 = T0_NS + 2 * 10**9
    assert export_csv(archive, SAT, ["fast", "slow"], T0_NS, t1, tmp_path / "x.csv") == 8
    with open(tmp_path / "x.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["fast"]) for r in rows] == fast.tolist()
    assert [r["slow"] for r in rows] == ["100", "", "", "", "200", "", "", ""]
    assert rows[4]["time_utc"].startswith("2023-11-14 22:13:21")
    assert export_parquet(archive, SAT, ["fast", "slow"], T0_NS, t1, tmp_path / "x.parquet") == 8
    table = pq.read_table(tmp_path / "x.parquet")
    assert table.column("slow").to_pylist() == [100, None, None, None, 200, None, None, None]
    np.testing.assert_array_equal(table.column("t_utc_ns").to_numpy(), T0_NS + np.arange(8) * QUARTER_SECOND_NS)
