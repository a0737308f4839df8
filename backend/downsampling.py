"""Min/max bucket downsampling of time series for plotting: every bucket keeps its extremes."""

from __future__ import annotations

import numpy as np

__all__ = ["minmax_indices"]


def minmax_indices(values: np.ndarray, max_points: int) -> np.ndarray:
    """Sorted indices (≤ max_points) keeping each bucket's min and max of every column of (n, c)."""
    if max_points < 2:
        raise ValueError(f"max_points: must be ≥ 2, got {max_points}")
    y = np.asarray(values, dtype=float).reshape(len(values), -1)
    n, columns = y.shape
    if n <= max_points:
        return np.arange(n)
    buckets = max(1, max_points // (2 * columns))
    size = -(-n // buckets)
    padded = np.concatenate([y, np.repeat(y[-1:], buckets * size - n, axis=0)])
    blocks = padded.reshape(buckets, size, columns)
    offsets = (np.arange(buckets) * size)[:, None]
    argmin, argmax = (np.nanargmin, np.nanargmax) if np.isnan(y).any() else (np.argmin, np.argmax)
    picks = np.sort(np.concatenate([argmin(blocks, axis=1), argmax(blocks, axis=1)], axis=1) + offsets, axis=1)
    flat = np.minimum(picks.ravel(), n - 1)  # rows are sorted and bucket b precedes b + 1: flat is monotone
    return flat[np.concatenate(([True], np.diff(flat) != 0))]
