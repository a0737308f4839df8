"""A job's trajectory.npz as export rows (backend.jobs.trajectory_files.npz_rows), against numpy's own reader of the
same file: every series' values member after member, in batches, with memory bounded by a batch, not the file."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from backend.jobs import trajectory_files
from backend.jobs.trajectory_files import npz_rows

MEMBERS, SAMPLES = 3, 7


def _expected(path: Path) -> dict[str, np.ndarray]:
    """Columns built from np.load: member-major rows, one column per component."""
    with np.load(path) as npz:
        t = npz["t_s"]
        arrays = {k: npz[k] for k in npz.files}
    out = {"member": np.repeat(np.arange(MEMBERS), t.size), "t_s": np.tile(t, MEMBERS)}
    for k, a in arrays.items():
        if k == "t_s" or a.ndim < 2 or a.shape[1] != t.size:
            continue
        if a.ndim == 2:
            out[k] = a.reshape(-1)
        else:
            flat = a.reshape(a.shape[0] * a.shape[1], -1)
            out.update({f"{k}_{i}": flat[:, i] for i in range(flat.shape[1])})
    return out


def test_rows_equal_numpys_reading_of_every_series_across_batch_and_member_boundaries(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(trajectory_files, "EXPORT_BATCH_ROWS", 3)  # 7 samples: batches of 3, 3, 1 per member
    rng = np.random.default_rng(17)
    path = tmp_path / "trajectory.npz"
    np.savez_compressed(
        path,
        t_s=np.linspace(0.0, 0.6, SAMPLES),
        wheel_inertia_kg_m2=np.full(4, 0.01),  # not a time series: no column
        meta=np.array('{"scenario": "x"}'),
        q_ib=rng.normal(size=(MEMBERS, SAMPLES, 4)),
        mode=rng.integers(0, 6, size=(MEMBERS, SAMPLES)).astype(np.int8),
        torque=np.asfortranarray(rng.normal(size=(MEMBERS, SAMPLES, 2)).astype(np.float32)),  # Fortran-ordered
        grid=rng.normal(size=(MEMBERS, SAMPLES, 2, 3)),  # two trailing axes: 6 components
    )
    schema, batches = npz_rows(path)
    table = pa.Table.from_batches(list(batches), schema=schema)
    expected = _expected(path)
    assert table.column_names == list(expected)
    for name, column in expected.items():
        assert np.array_equal(table[name].to_numpy(), column), name
        assert table[name].type == pa.from_numpy_dtype(column.dtype) or name == "member", name


def test_memory_held_is_a_batch_not_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(trajectory_files, "EXPORT_BATCH_ROWS", 10_000)
    samples = 100_000
    path = tmp_path / "trajectory.npz"
    series = {f"s{k}": np.arange(2 * samples * 4, dtype=np.float64).reshape(2, samples, 4) + k for k in range(3)}
    np.savez_compressed(path, t_s=np.arange(samples, dtype=np.float64), **series)
    series_bytes = sum(a.nbytes for a in series.values())  # 19.2 MB: what reading the arrays at once would hold
    del series
    tracemalloc.start()
    try:
        _, batches = npz_rows(path)
        rows = sum(batch.num_rows for batch in batches)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert rows == 2 * samples
    assert peak < series_bytes / 4, peak
