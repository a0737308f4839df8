"""The Dask engine on a real LocalCluster (two worker processes): split batches fly bit for bit as one batch."""

from __future__ import annotations

import numpy as np
import pytest

from backend.jobs import cluster
from sim_core import engine, faults, scenario_library
from sim_core.scenario import Scenario, VariantSpec


@pytest.fixture(scope="module")
def client():
    c = cluster.dask_client(n_workers=2)
    yield c
    c.close()
    c.cluster.close()


def _batch() -> Scenario:
    s = scenario_library.get("somov-ge4-scan")  # MEKF with gyro and star-tracker noise: every variant draws
    variants = [VariantSpec(name="nominal")] + faults.random_wheel_failures(4, (5.0, 50.0), seed=3)
    return Scenario.model_validate(
        {**s.model_dump(), "duration_s": 60.0, "variants": [v.model_dump() for v in variants]}
    )


def test_split_batch_on_two_workers_equals_one_batch(client) -> None:
    s = _batch()
    here = engine.simulate(s)
    there = cluster.fly(client, s)
    assert there.variant_names == here.variant_names
    for name, series in here.series.items():
        np.testing.assert_array_equal(there.series[name], series, err_msg=name)
    assert there.events == here.events


def test_map_cases_keeps_order(client) -> None:
    assert cluster.map_cases(client, abs, [-3, 2, -1]) == [3, 2, 1]


def test_scheduler_address_is_checked() -> None:
    with pytest.raises(ValueError, match="tcp://"):
        cluster.dask_client("localhost:8786")


def test_whatif_sweep_on_the_cluster_equals_the_local_sweep(client) -> None:
    from sim_core import whatif

    s = _batch()
    variants = s.variants
    base = Scenario.model_validate({**s.model_dump(), "variants": [variants[0].model_dump()]})
    assert whatif.sweep(base, variants, flyer=cluster.flyer(client)) == whatif.sweep(base, variants)
