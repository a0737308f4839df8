"""API time edge: ISO times to int64 UTC ns, against numpy's datetime64 and the int64 range."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta, timezone

import numpy as np

from backend.core.time import BOUND_NS, utc_ns


def test_utc_ns_matches_numpy_datetime64_and_treats_naive_as_utc() -> None:
    moment = datetime(2021, 4, 9, 0, 0, 0, 7137)
    truth = int(np.datetime64("2021-04-09T00:00:00.007137", "ns").astype(np.int64))
    assert utc_ns(moment, 0) == truth
    assert utc_ns(moment.replace(tzinfo=timezone(timedelta(hours=2))), 0) == truth - 7_200_000_000_000


def test_out_of_range_times_are_clamped_into_int64_and_none_gives_default() -> None:
    assert utc_ns(datetime(2263, 1, 1, tzinfo=UTC), 0) == BOUND_NS
    assert utc_ns(datetime(1, 1, 1), 0) == -BOUND_NS
    assert utc_ns(None, 42) == 42
