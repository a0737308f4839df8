"""Time at the API edge: ISO 8601 / datetime ↔ int64 UTC nanoseconds since the Unix epoch."""

from __future__ import annotations

from datetime import UTC, datetime

__all__ = ["utc_ns", "EARLIEST_NS", "LATEST_NS"]

EARLIEST_NS = 0  # 1970-01-01: an open start of a query window
LATEST_NS = 2**62  # ~2116: an open end of a query window, far from int64 overflow
BOUND_NS = 2**62  # windows are clamped to ±BOUND_NS so every time fits the int64 columns


def utc_ns(moment: datetime | None, default: int) -> int:
    """UTC ns of ``moment`` (naive = UTC) clamped to ±BOUND_NS, or ``default`` when None (int64 ns)."""
    if moment is None:
        return default
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    delta = moment - datetime(1970, 1, 1, tzinfo=UTC)
    ns = (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000
    return min(max(ns, -BOUND_NS), BOUND_NS)
