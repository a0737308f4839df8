"""Min/max downsampling keeps every extreme and respects max_points."""

from __future__ import annotations

import numpy as np
import pytest

from telemetry.downsampling import minmax_indices


def test_global_extremes_of_every_column_survive() -> None:
    rng = np.random.default_rng(7)
    y = rng.normal(size=(100_003, 2))
    keep = minmax_indices(y, 1000)
    assert len(keep) <= 1000 and np.all(np.diff(keep) > 0)
    for c in range(2):
        assert np.argmax(y[:, c]) in keep and np.argmin(y[:, c]) in keep


def test_short_series_is_returned_whole_and_bad_max_points_named() -> None:
    assert np.array_equal(minmax_indices(np.arange(5.0), 10), np.arange(5))
    with pytest.raises(ValueError, match="max_points"):
        minmax_indices(np.arange(5.0), 1)


def test_matches_the_set_of_bucket_extremes_computed_one_bucket_at_a_time() -> None:
    y = np.random.default_rng(11).normal(size=(1003, 2))
    y[17, 0] = np.nan  # an all-NaN-safe path: nan-aware arg-extremes
    keep = minmax_indices(y, 40)
    buckets, size = 40 // 4, -(-1003 // (40 // 4))
    expected = set()
    for b in range(buckets):
        block = y[b * size : (b + 1) * size]
        for c in range(2):
            expected |= {b * size + int(np.nanargmin(block[:, c])), b * size + int(np.nanargmax(block[:, c]))}
    assert list(keep) == sorted(expected)
