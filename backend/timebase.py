"""Time at the API edge: ISO 8601 / datetime ↔ int64 UTC nanoseconds since the Unix epoch."""

from __future__ import annotations

from datetime import datetime, timezone

__all__ = ["utc_ns", "EARLIEST_NS", "LATEST_NS"]

EARLIEST_NS = 0  # 1970-01-01: an open start of a query window
LATEST_NS = 2**62  # ~2116: an open end of a query window, far from int64 overflow


def utc_ns(moment: datetime | None, default: int) -> int:
    """UTC ns of ``moment`` (naive = UTC), or ``default`` when None (DESIGN.md: time as int64 ns)."""
    if moment is None:
        return default
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    delta = moment - datetime(1970, 1, 1, tzinfo=timezone.utc)
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000
