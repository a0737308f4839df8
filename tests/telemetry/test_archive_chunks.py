"""Column codecs: every dtype round-trips bit-exactly, narrowed only when lossless."""

from __future__ import annotations

import numpy as np
import pytest

from telemetry.archive.chunks import (
    decode_int64,
    decode_raw,
    decode_values,
    encode_int64,
    encode_raw,
    encode_values,
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


def test_non_numeric_values_name_the_field() -> None:
    with pytest.raises(ValueError, match="values"):
        encode_values(np.array(["a", "b"]))
