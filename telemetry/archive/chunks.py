"""Column codecs of the archive: numpy arrays <-> compressed bytes (zstd level 1).

Integer columns (times, sequence counts, lengths) are delta-encoded before compression (a 1 Hz
stream compresses ~10,000:1); values are stored in the narrowest dtype that holds them exactly
and read back in the dtype they were given in.  zstd level 1 compresses float64 at ~80 M
samples/s here, zlib level 1 at ~5 M samples/s, which is why the archive depends on
``zstandard``.
"""

from __future__ import annotations

import threading

import numpy as np
import zstandard

__all__ = [
    "narrowest_exact",
    "encode_int64",
    "decode_int64",
    "encode_values",
    "encode_values_range",
    "decode_values",
    "encode_raw",
    "decode_raw",
]

ZSTD_LEVEL = 1  # fastest level: ingest throughput matters more than a few % of disk
STORABLE_KINDS = "biuf"  # bool, signed, unsigned, float: what min/max and limits make sense on


_NARROW_INTS = (np.int8, np.uint8, np.int16, np.uint16, np.int32, np.uint32)
_INT_RANGES = [(np.dtype(t), int(np.iinfo(t).min), int(np.iinfo(t).max)) for t in _NARROW_INTS]
_codec = threading.local()  # a ZstdCompressor is not thread-safe; making one per call costs as much as compressing


def _compress(data: bytes | memoryview) -> bytes:
    compressor = getattr(_codec, "compressor", None)
    if compressor is None:
        compressor = _codec.compressor = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
    return compressor.compress(data)


def _decompress(blob: bytes) -> bytes:
    return zstandard.ZstdDecompressor().decompress(blob)


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
    size = array.dtype.itemsize
    for candidate, t_min, t_max in _INT_RANGES:
        if candidate.itemsize >= size:
            return array
        if t_min <= lo and hi <= t_max:
            return array.astype(candidate)
    return array


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
    if array.dtype.kind in "iu":
        stored = _narrowest_int(array, int(v_min), int(v_max))
    else:
        stored = _as_float32_if_exact(array) if array.dtype == np.float64 else array
        if np.isnan(v_min) or np.isnan(v_max):  # NaN (no such element): the range of the others, no masked copy
            v_min, v_max = np.fmin.reduce(array), np.fmax.reduce(array)
        if not (np.isfinite(v_min) and np.isfinite(v_max)):  # infinities, or nothing but NaN
            finite = array[np.isfinite(array)]
            v_min, v_max = (finite.min(), finite.max()) if finite.size else (None, None)
    spec = f"{stored.dtype.str}/{shown.str}"
    blob = _compress(stored.data.cast("B"))
    return spec, blob, (None if v_min is None else float(v_min)), (None if v_max is None else float(v_max))


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
