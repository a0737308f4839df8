"""Sample caches: an answer or a computed result survives ingests elsewhere in time, never outlives overlapping data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from backend.core.settings import Settings
from backend.ingest.live_hub import LiveHub
from backend.ingest.sample_cache import SampleCache
from backend.ingest.telemetry_gateway import TelemetryGateway
from telemetry.dictionary import SHIPPED

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


def test_window_result_is_computed_once_until_an_ingest_overlaps_its_window(tmp_path: Path) -> None:
    gateway = TelemetryGateway(Settings(data_dir=tmp_path), LiveHub(16))
    computed: list[int] = []

    def compute() -> list[int]:
        computed.append(len(computed))
        return computed.copy()

    first = gateway.window_result("SAT", "residuals of session s1", 100, 200, compute)
    assert gateway.window_result("SAT", "residuals of session s1", 100, 200, compute) is first
    gateway.invalidate("SAT", 300, 400)  # later telemetry: the window's result still holds
    gateway.invalidate("OTHER", 0, 1000)
    assert gateway.window_result("SAT", "residuals of session s1", 100, 200, compute) is first
    gateway.invalidate("SAT", 200, 250)  # a backfill touching the window
    assert gateway.window_result("SAT", "residuals of session s1", 100, 200, compute) == [0, 1]
    assert computed == [0, 1]


def test_a_result_computed_across_an_overlapping_ingest_is_not_kept_one_elsewhere_in_time_is() -> None:
    cache = SampleCache()
    key = ("SAT", "residuals of session s1", 100, 200)
    generation = cache.generation("SAT")
    cache.invalidate("SAT", 500, 600)  # a live batch after the window lands while the result is computed
    cache.store_computed(key, generation, "kept")
    assert cache.computed(key) == "kept"
    other = ("SAT", "residuals of session s2", 100, 200)
    generation = cache.generation("SAT")
    cache.invalidate("SAT", 150, 160)  # an upload into the window lands meanwhile
    cache.store_computed(other, generation, "stale")
    assert cache.computed(other) is None and cache.computed(key) is None


def test_a_result_decoded_with_a_dictionary_is_recomputed_once_the_dictionary_is_uploaded_again(
    tmp_path: Path,
) -> None:
    gateway = TelemetryGateway(Settings(data_dir=tmp_path), LiveHub(16))
    definition = (SHIPPED / "reference_satellite.yaml").read_bytes()
    gateway.dictionaries.add("ops.yaml", definition, apid=None, time_code=None)
    computed: list[int] = []

    def compute() -> list[int]:
        computed.append(len(computed))
        return computed.copy()

    first = gateway.window_result("SAT", "residuals of session s1", 100, 200, compute, dictionary="ops.yaml")
    assert gateway.window_result("SAT", "residuals of session s1", 100, 200, compute, dictionary="ops.yaml") is first
    gateway.dictionaries.add("ops.yaml", definition.replace(b"\n", b"\n\n", 1), apid=None, time_code=None)  # v2
    assert gateway.window_result("SAT", "residuals of session s1", 100, 200, compute, dictionary="ops.yaml") == [0, 1]
    assert computed == [0, 1]
