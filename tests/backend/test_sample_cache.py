"""Sample caches: an answer survives ingests elsewhere in time, never outlives overlapping data."""

from __future__ import annotations

import numpy as np

from backend.ingest.sample_cache import SampleCache

KEY = ("SAT", "q", 100, 200, 1000)


def test_overlapping_ingest_drops_the_answer_and_other_windows_keep_theirs() -> None:
    cache = SampleCache()
    cache.store_answer(KEY, cache.generation("SAT"), b"a")
    cache.invalidate("SAT", 300, 400)  # later data: the [100, 200] answer is still exact
    assert cache.answer(KEY) == b"a"
    cache.invalidate("SAT", 150, 150)
    assert cache.answer(KEY) is None


def test_answer_computed_across_an_ingest_is_not_stored() -> None:
    cache = SampleCache()
    generation = cache.generation("SAT")
    cache.invalidate("SAT", 0, 1)  # an upload commits while the answer is being computed
    cache.store_answer(KEY, generation, b"stale?")
    assert cache.answer(KEY) is None


def test_windows_reaching_unarchived_live_data_are_not_stored_and_series_are_dropped_on_ingest() -> None:
    cache = SampleCache()
    cache.mark_live("SAT", 150)
    cache.store_answer(KEY, cache.generation("SAT"), b"a")
    assert cache.answer(KEY) is None and cache.hot_start_ns("SAT") == 150
    t, v = np.arange(10, dtype=np.int64), np.arange(10.0)
    cache.store_series("OTHER", "q", cache.generation("OTHER"), t, v)
    assert cache.series("OTHER", "q")[1] is v
    cache.invalidate("OTHER", 5, 5)
    assert cache.series("OTHER", "q") is None
