"""The plots' downsampler: min/max buckets of a time series, every bucket keeps its extreme samples.

The one downsampler of the project: the API's telemetry samples, simulation series and twin
residuals all pass through :func:`minmax_indices` (it keeps actual samples, so a plot shows real
points and every spike survives any zoom level). ``telemetry.queries.bucket_statistics`` is not a
second one: it reports per-time-bucket count/min/max/mean statistics, not samples.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["minmax_indices"]


def minmax_indices(values: npt.ArrayLike, max_points: int) -> npt.NDArray[np.intp]:
    """Sorted indices (≤ max_points) keeping each bucket's min and max of every column of (n, c)."""
    if max_points < 2:
        raise ValueError(f"max_points: must be ≥ 2, got {max_points}")
    y = np.asarray(values, dtype=float)
    y = y.reshape(len(y), -1)
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
