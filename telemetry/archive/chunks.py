"""Column codecs of the archive: numpy arrays <-> compressed bytes (zstd level 1).

Integer columns (times, sequence counts, lengths) are delta-encoded before compression (a 1 Hz
stream compresses ~10,000:1); values are stored in the narrowest dtype that holds them exactly
and read back in the dtype they were given in.  zstd level 1 compresses float64 at ~80 M
samples/s here, zlib level 1 at ~5 M samples/s, which is why the archive depends on
``zstandard``.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import zstandard

__all__ = [
    "narrowest_exact",
    "encode_int64",
    "decode_int64",
    "encode_values",
    "encode_values_range",
    "encode_value_rows",
    "decode_values",
    "encode_raw",
    "decode_raw",
]

ZSTD_LEVEL = 1  # the faster negative levels saved <= 3 % of ingest CPU for up to 2x the disk (docs/archive.md)
STORABLE_KINDS = "biuf"  # bool, signed, unsigned, float: what min/max and limits make sense on


_NARROW_INTS = (np.int8, np.uint8, np.int16, np.uint16, np.int32, np.uint32)  # by size, signed first
_INT_RANGES = [(np.dtype(t), int(np.iinfo(t).min), int(np.iinfo(t).max)) for t in _NARROW_INTS]
_INT_MINIMA = np.array([lo for _, lo, _ in _INT_RANGES], dtype=np.int64)
_INT_MAXIMA = np.array([hi for _, _, hi in _INT_RANGES], dtype=np.int64)  # growing along _INT_RANGES
_NARROWER = {size: sum(t.itemsize < size for t, _, _ in _INT_RANGES) for size in (1, 2, 4, 8)}  # candidates
_codec = threading.local()  # zstd (de)compressors are not thread-safe; making one per call costs as much as the call


def _compressor() -> zstandard.ZstdCompressor:
    compressor = getattr(_codec, "compressor", None)
    if compressor is None:
        compressor = _codec.compressor = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
    return compressor


def _compress(data: bytes | memoryview) -> bytes:
    return _compressor().compress(data)


def _decompressor() -> zstandard.ZstdDecompressor:
    decompressor = getattr(_codec, "decompressor", None)
    if decompressor is None:
        decompressor = _codec.decompressor = zstandard.ZstdDecompressor()
    return decompressor


def _decompress(blob: bytes) -> bytes:
    return _decompressor().decompress(blob)


def encode_int64(values: np.ndarray) -> bytes:
    """Delta-encoded, compressed int64 column (times in UTC ns, sequence counts, packet lengths)."""
    a = np.ascontiguousarray(values, dtype=np.int64)
    delta = np.empty_like(a)
    delta[:1] = a[:1]
    np.subtract(a[1:], a[:-1], out=delta[1:])
    return _compress(delta.data)


def decode_int64(blob: bytes) -> np.ndarray:
    """Inverse of :func:`encode_int64`."""
    return np.cumsum(np.frombuffer(_decompress(blob), dtype=np.int64))


def narrowest_exact(values: np.ndarray) -> np.ndarray:
    """The values in the smallest dtype that holds every one of them exactly (float32, small ints).

    Decoders hand out float64 for 32-bit telemetry fields; storing them as float32 is lossless
    and makes zstd ~4x faster on them (measured: 11 -> 52 M samples/s).
    """
    array = np.ascontiguousarray(values)
    if array.dtype == np.float64 and array.size:
        return _as_float32_if_exact(array)
    if array.dtype.kind in "iu" and array.size:
        return _narrowest_int(array, int(array.min()), int(array.max()))
    return array


def _as_float32_if_exact(array: np.ndarray) -> np.ndarray:
    """A float64 column as float32 when that holds every value exactly (NaN as NaN), else itself."""
    with np.errstate(over="ignore"):  # beyond float32's range: inf, which fails the comparison below
        narrow = array.astype(np.float32)
    same = narrow == array  # compared in float64: exact
    if same.all() or (same | np.isnan(array)).all():  # NaN stays NaN in float32
        return narrow
    return array


def _narrowest_int(array: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """An integer column in the smallest integer dtype holding lo..hi (its own when none is smaller)."""
    bounds = np.array([lo, hi], dtype=array.dtype)  # the column's own least and greatest values: they fit
    choice = int(_narrowest_int_rows(array.dtype, bounds[:1], bounds[1:])[0])
    return array if choice < 0 else array.astype(_INT_RANGES[choice][0])


def encode_values(values: np.ndarray) -> tuple[str, bytes]:
    """Compressed values and a dtype spec ``stored/presented`` to read them back losslessly."""
    spec, blob, _, _ = encode_values_range(values)
    return spec, blob


def encode_values_range(
    values: np.ndarray, presented: np.dtype | None = None
) -> tuple[str, bytes, float | None, float | None]:
    """:func:`encode_values` and the least and greatest finite value (None when there is none); ``presented``:
    the dtype to read them back in, if not their own (one that holds every value exactly).

    One pass finds both the range and the narrowest dtype (integers: the range is the test).
    """
    array = np.ascontiguousarray(values)
    shown = array.dtype if presented is None else np.dtype(presented)
    if array.dtype.kind not in STORABLE_KINDS:
        raise ValueError(f"values: dtype {array.dtype} is not numeric (bool, int, uint or float)")
    if array.size == 0:
        return f"{array.dtype.str}/{shown.str}", _compress(b""), None, None
    v_min, v_max = array.min(), array.max()
    low: float | None
    high: float | None
    if array.dtype.kind in "iu":
        stored = _narrowest_int(array, int(v_min), int(v_max))
        low, high = float(v_min), float(v_max)
    else:
        stored = _as_float32_if_exact(array) if array.dtype == np.float64 else array
        low, high = _finite_range(array, v_min, v_max)
    spec = f"{stored.dtype.str}/{shown.str}"
    return spec, _compress(stored.data.cast("B")), low, high


def _finite_range(array: np.ndarray, v_min: Any, v_max: Any) -> tuple[float | None, float | None]:
    """The least and greatest finite value of a float (or bool) column whose min and max are ``v_min, v_max``."""
    if np.isnan(v_min) or np.isnan(v_max):  # NaN (no such element): the range of the others, no masked copy
        v_min, v_max = np.fmin.reduce(array), np.fmax.reduce(array)
    if not (np.isfinite(v_min) and np.isfinite(v_max)):  # infinities, or nothing but NaN
        finite = array[np.isfinite(array)]
        if not finite.size:
            return None, None
        v_min, v_max = finite.min(), finite.max()
    return float(v_min), float(v_max)


def encode_value_rows(
    matrix: np.ndarray, presented: np.dtype | None = None
) -> list[tuple[str, bytes, float | None, float | None]]:
    """:func:`encode_values_range` of each row of a 2-D array (one column of values per row), the same specs,
    blobs and ranges, in a few calls over the whole matrix: ranges by one min and one max along the rows, the
    narrowest dtype chosen for all rows at once, rows stored in one dtype converted and compressed together
    (zstd's multi_compress_to_buffer: one call, not one per row). An archive chunk holds ~100 columns of a few
    thousand samples each, where the per-call costs of one row at a time outweighed the work on the values.
    """
    m = np.asarray(matrix)
    if m.ndim != 2:
        raise ValueError(f"matrix: expected a 2-D array of value columns, got shape {m.shape}")
    kind = m.dtype.kind
    if m.shape[0] == 0 or m.shape[1] == 0 or kind not in "iuf":  # bool, empty, non-numeric: one row at a time
        return [encode_values_range(row, presented) for row in m]
    shown = (m.dtype if presented is None else np.dtype(presented)).str
    low, high = m.min(axis=1), m.max(axis=1)
    parts: list[tuple[np.ndarray, np.ndarray | None, np.dtype | None]]  # (values, their rows or all, stored dtype)
    if kind in "iu":
        choice = _narrowest_int_rows(m.dtype, low, high)
        parts = [(m, rows, None if c < 0 else _INT_RANGES[c][0]) for c, rows in _rows_by_choice(choice)]
        lows: list[Any] = low.astype(np.float64).tolist()
        highs: list[Any] = high.astype(np.float64).tolist()
    else:
        lows, highs = low.astype(np.float64).tolist(), high.astype(np.float64).tolist()
        for i in np.flatnonzero(~(np.isfinite(low) & np.isfinite(high))).tolist():  # NaN or infinities
            lows[i], highs[i] = _finite_range(m[i], low[i], high[i])
        parts = [(m, None, None)]
        if m.dtype == np.float64:
            with np.errstate(over="ignore"):  # beyond float32's range: inf, which fails the comparison below
                narrow = m.astype(np.float32)
            exact = (narrow == m).all(axis=1)  # compared in float64: exact
            nan_rows = np.flatnonzero(np.isnan(low) & ~exact)  # a row's min is NaN when it holds any
            if nan_rows.size:  # NaN stays NaN in float32
                exact[nan_rows] = ((narrow[nan_rows] == m[nan_rows]) | np.isnan(m[nan_rows])).all(axis=1)
            parts = [(narrow if c == 0 else m, rows, None) for c, rows in _rows_by_choice(np.where(exact, 0, -1))]
    out: list[Any] = [None] * m.shape[0]
    for values, rows, dtype in parts:
        block = values if rows is None else values[rows]
        block = np.ascontiguousarray(block) if dtype is None else block.astype(dtype)
        spec = f"{block.dtype.str}/{shown}"
        for i, blob in zip(range(m.shape[0]) if rows is None else rows.tolist(), _compress_rows(block)):
            out[i] = (spec, blob, lows[i], highs[i])
    return out


def _narrowest_int_rows(dtype: np.dtype, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Per row (its least and greatest value ``low``, ``high``, of integer ``dtype``), the index in _INT_RANGES of
    the narrowest integer dtype holding low..high, -1 when none is narrower than ``dtype``: the first that fits,
    _INT_RANGES being ordered by size. The one choice of the archive's integer narrowing (rows and columns)."""
    k = _NARROWER[dtype.itemsize]
    if k == 0:  # 8-bit: nothing narrower
        return np.full(low.shape, -1, dtype=np.int64)
    if dtype.kind == "u":  # low >= 0: the first whose maximum holds high (compared as float64 beside uint64 values:
        choice = np.searchsorted(_INT_MAXIMA[:k], high)  # exact below 2**53, far above every candidate's maximum)
    else:
        fits = np.ones((k + 1, low.shape[0]), dtype=bool)  # row k: the dtype itself, which always fits
        np.greater_equal(low, _INT_MINIMA[:k, None], out=fits[:k])
        fits[:k] &= high <= _INT_MAXIMA[:k, None]
        choice = fits.argmax(axis=0)  # the first that fits
    return np.where(choice < k, choice, -1)


def _rows_by_choice(choice: np.ndarray) -> list[tuple[int, np.ndarray | None]]:
    """(choice, rows having it, in order) for each distinct choice, in increasing order; rows None when every row
    has the same."""
    first = int(choice[0])
    if (choice == first).all():
        return [(first, None)]
    return [(c, np.flatnonzero(choice == c)) for c in sorted(set(choice.tolist()))]  # a handful: not np.unique


def _compress_rows(block: np.ndarray) -> list[bytes]:
    """Each row of a C-contiguous 2-D array compressed on its own (as :func:`_compress` would), in one call."""
    row_octets = block.shape[1] * block.dtype.itemsize
    segments = np.empty((block.shape[0], 2), dtype=np.uint64)
    segments[:, 0] = np.arange(block.shape[0], dtype=np.uint64) * np.uint64(row_octets)
    segments[:, 1] = row_octets
    buffers = zstandard.BufferWithSegments(block.data.cast("B"), segments.tobytes())
    blobs = _compressor().multi_compress_to_buffer(buffers)
    return [blobs[i].tobytes() for i in range(len(blobs))]


def decode_values(dtype_spec: str, blob: bytes) -> np.ndarray:
    """Inverse of :func:`encode_values` (in the dtype the values were given in)."""
    stored, _, presented = dtype_spec.partition("/")
    array = np.frombuffer(_decompress(blob), dtype=np.dtype(stored))
    return array.astype(np.dtype(presented or stored), copy=False)


def encode_raw(raw: bytes | memoryview | np.ndarray) -> bytes:
    """Compressed concatenation of raw packets (byte-exact on decode); octets of any contiguous buffer, not copied."""
    return _compress(np.ascontiguousarray(raw, dtype=np.uint8).data if isinstance(raw, np.ndarray) else raw)


def decode_raw(blob: bytes) -> bytes:
    """Inverse of :func:`encode_raw`."""
    return _decompress(blob)
