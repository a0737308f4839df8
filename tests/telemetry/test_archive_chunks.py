"""Column codecs: every dtype round-trips bit-exactly, narrowed only when lossless."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from telemetry.archive.batch import ColumnMatrices
from telemetry.archive.chunks import (
    decode_int64,
    decode_raw,
    decode_values,
    encode_int64,
    encode_raw,
    encode_value_rows,
    encode_values,
    encode_values_range,
    narrowest_exact,
)

COLUMNS = {
    "float32-valued float64": np.array([0.1, -2.5, np.nan, np.inf], dtype=np.float32).astype(np.float64),
    "true float64": np.array([0.1, 1e-300, np.nan, -0.0]),
    "small int64": np.array([0, 1, 2, 255], dtype=np.int64),
    "negative int64": np.array([-40_000, 3], dtype=np.int64),
    "huge int64": np.array([0, 2**62], dtype=np.int64),
    "uint16": np.array([0, 65_535], dtype=np.uint16),
    "bool": np.array([True, False, True]),
    "empty": np.array([], dtype=np.float64),
}


@pytest.mark.parametrize("name", sorted(COLUMNS))
def test_values_round_trip_bit_exact_in_their_own_dtype(name: str) -> None:
    original = COLUMNS[name]
    dtype_spec, blob = encode_values(original)
    back = decode_values(dtype_spec, blob)
    assert back.dtype == original.dtype
    assert back.tobytes() == original.tobytes()


def test_narrowing_is_taken_only_when_lossless() -> None:
    assert narrowest_exact(COLUMNS["float32-valued float64"]).dtype == np.float32
    assert narrowest_exact(COLUMNS["true float64"]).dtype == np.float64
    assert narrowest_exact(COLUMNS["small int64"]).dtype == np.uint8
    assert narrowest_exact(COLUMNS["negative int64"]).dtype == np.int32
    assert narrowest_exact(COLUMNS["huge int64"]).dtype == np.int64


def test_int64_columns_and_raw_bytes_round_trip() -> None:
    t = 1_750_000_000 * 10**9 + np.cumsum(np.random.default_rng(1).integers(1, 10**9, 1_000))
    np.testing.assert_array_equal(decode_int64(encode_int64(t)), t)
    raw = bytes(range(256)) * 7
    assert decode_raw(encode_raw(raw)) == raw


INT_DTYPES = ["u1", "i1", "u2", "i2", "u4", "i4", "u8", "i8"]
NARROW_INTS = [np.dtype(t) for t in ("i1", "u1", "i2", "u2", "i4", "u4")]  # by size, signed first


@pytest.mark.parametrize("dtype", INT_DTYPES)
def test_integers_stored_in_the_first_smaller_dtype_holding_their_range(dtype: str) -> None:
    """Every edge of every smaller integer range, as a column's least or greatest value: stored in the first of
    int8, uint8, int16, uint16, int32, uint32 narrower than the column holding both (np.iinfo), else as given."""
    own = np.dtype(dtype)
    info = np.iinfo(own)
    edges = sorted({e for t in NARROW_INTS for b in (np.iinfo(t).min, np.iinfo(t).max) for e in (b - 1, b, b + 1)})
    edges = [e for e in edges if info.min <= e <= info.max]
    pairs = [(lo, hi) for lo in edges for hi in edges if lo <= hi]
    matrix = np.array(pairs, dtype=own)  # each row: its least and greatest value
    for (lo, hi), row, (spec, _, _, _) in zip(pairs, matrix, encode_value_rows(matrix)):
        fits = [t for t in NARROW_INTS if t.itemsize < own.itemsize and np.iinfo(t).min <= lo and hi <= np.iinfo(t).max]
        expected = fits[0] if fits else own
        assert narrowest_exact(row).dtype == expected and spec.split("/")[0] == expected.str, (lo, hi)


def test_non_numeric_values_name_the_field() -> None:
    with pytest.raises(ValueError, match="values"):
        encode_values(np.array(["a", "b"]))


MATRIX_DTYPES = ["u1", "i1", "<u2", ">u2", "<i2", "<u4", "<i4", "<i8", "<u8", "<f8", "<f4", "?"]


@pytest.mark.parametrize("dtype", MATRIX_DTYPES)
def test_matrix_rows_encode_as_each_row_alone(dtype: str) -> None:
    """encode_value_rows gives each row of a matrix the spec, blob and range that encode_values_range gives it
    alone: rows narrowing to different dtypes, rows with NaN, infinities or nothing finite, strided slices."""
    rng = np.random.default_rng(12)
    kind, size = np.dtype(dtype).kind, np.dtype(dtype).itemsize
    rows = []
    for scale in (1, 100, 200, 40_000, 70_000, 2**31, 2**40):
        if kind == "b":
            rows.append(rng.integers(0, 2, 50).astype(bool))
            continue
        info = np.finfo(dtype) if kind == "f" else np.iinfo(dtype)
        high = min(scale, info.max)
        low = 0 if kind == "u" else max(-scale, info.min)
        rows.append(rng.integers(int(low), int(high), 50, endpoint=True).astype(dtype))
    if kind == "f":
        rows.append(rng.normal(size=50).astype(dtype))  # not float32-exact (as float64)
        for special in ([np.nan], [np.inf, -np.inf], [np.nan, np.inf]):
            row = rng.normal(size=50).astype(np.float32).astype(dtype)
            row[: len(special)] = special
            rows.append(row)
        rows.append(np.full(50, np.nan, dtype=dtype))
        rows.append(np.full(50, np.inf, dtype=dtype))
    matrix = np.stack(rows, dtype=dtype)  # byte order kept
    assert size and matrix.dtype == np.dtype(dtype)
    wide = np.dtype(np.int64) if kind in "iu" and np.dtype(dtype) != np.uint64 else None
    for view in (matrix, matrix[:, 7:40], matrix[::-1]):
        expected = [encode_values_range(row, wide) for row in view]
        assert encode_value_rows(view, wide) == expected
        for (spec, blob, _, _), row in zip(expected, view):
            assert np.array_equal(decode_values(spec, blob), row.astype(wide or row.dtype), equal_nan=kind == "f")


def test_matrix_rows_of_no_samples_or_no_rows() -> None:
    assert encode_value_rows(np.empty((0, 5))) == []
    assert encode_value_rows(np.empty((2, 0), dtype=np.uint8)) == [encode_values_range(np.empty(0, np.uint8))] * 2
    with pytest.raises(ValueError, match="2-D"):
        encode_value_rows(np.zeros(3))
    with pytest.raises(ValueError, match="not numeric"):
        encode_value_rows(np.array([["a", "b"]]))


def test_pending_parts_join_into_one_matrix_per_dtype() -> None:
    """Columns joined end to end equal np.concatenate's (in its dtype: native byte order); rows of one matrix per dtype; a column
    whose dtype differs between parts is joined alone, promoted as np.concatenate promotes it."""
    parts = [
        {"a": np.arange(3).astype(">u2"), "b": np.full(3, 0.5), "c": np.arange(3, 6).astype(">u2")},
        {"a": np.arange(2).astype(">u2"), "b": np.full(2, np.nan), "c": np.arange(7, 9).astype(">u2")},
    ]
    joined = ColumnMatrices.concatenated(parts, [3, 2])
    assert isinstance(joined, ColumnMatrices) and list(joined) == ["a", "b", "c"]
    for name, column in joined.items():
        expected = np.concatenate([p[name] for p in parts])
        assert column.dtype == expected.dtype and np.array_equal(column, expected, equal_nan=True)
    assert [(d.str, members, m.shape) for d, members, m in joined.groups] == [
        ("<u2", [0, 2], (2, 5)),
        ("<f8", [1], (1, 5)),
    ]
    mixed = ColumnMatrices.concatenated([parts[0], {**parts[1], "a": np.arange(2, dtype=np.uint32)}], [3, 2])
    assert not isinstance(mixed, ColumnMatrices) and mixed["a"].dtype == np.uint32


def test_column_matrices_refuse_a_change_the_matrices_would_not_see_and_pickle_whole() -> None:
    """A column set or removed on the mapping would be missing from the matrices the archive reads: refused. A
    pickled copy (a decoder process hands its batches on) has the same columns and groups."""
    matrices = ColumnMatrices(["a", "b"], [(np.dtype(np.float64), [0, 1], np.arange(6.0).reshape(2, 3))])
    for change in (
        lambda m: m.__setitem__("c", np.zeros(3)),
        lambda m: m.update(a=np.zeros(3)),
        lambda m: m.pop("a"),
        lambda m: m.__delitem__("b"),
    ):
        with pytest.raises(TypeError, match="read-only"):
            change(matrices)
    again = pickle.loads(pickle.dumps(matrices))
    assert isinstance(again, ColumnMatrices) and list(again) == ["a", "b"]
    assert [(d, p, m.tolist()) for d, p, m in again.groups] == [(np.dtype(np.float64), [0, 1], [[0, 1, 2], [3, 4, 5]])]
    assert np.array_equal(again["b"], [3.0, 4.0, 5.0])
