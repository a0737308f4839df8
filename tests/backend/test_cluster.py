"""The Dask engine on a cluster started apart from the tests (a scheduler and two worker processes, as an operator
would): split batches fly bit for bit as one batch, cases keep their order, a what-if sweep and a server job equal
their local runs. The LocalCluster that dask_client starts by itself is the one the other tests fly on
(tests/conftest.py shared_dask; the shutdown, grace-restart and diagnose-command tests start their own)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from backend.jobs import cluster
from sim_core import engine, faults, scenario_library
from sim_core.scenario import Scenario, VariantSpec
from sim_core.trajectory import Trajectory

pytestmark = pytest.mark.slow  # a separately started cluster: scheduled first (tests/conftest.py)


def _batch() -> Scenario:
    s = scenario_library.get("somov-ge4-scan")  # MEKF with gyro and star-tracker noise: every variant draws
    variants = [VariantSpec(name="nominal")] + faults.random_wheel_failures(4, (5.0, 50.0), seed=3)
    return Scenario.model_validate(
        {**s.model_dump(), "duration_s": 60.0, "variants": [v.model_dump() for v in variants]}
    )


@pytest.fixture(scope="module")
def here() -> Trajectory:
    """The batch flown as one on this process: what the cluster's split flight must equal bit for bit."""
    return engine.simulate(_batch())


def test_scheduler_address_is_checked() -> None:
    with pytest.raises(ValueError, match="tcp://"):
        cluster.dask_client("localhost:8786")


@pytest.fixture(scope="module")
def scheduler_address():
    """A cluster started apart from the tests, as an operator would: ``dask scheduler`` + ``dask worker`` processes."""
    import subprocess
    import sys

    from backend.core.processes import stop_owned
    from tests.ports import free_port

    address = f"tcp://127.0.0.1:{free_port()}"
    host, port = address.removeprefix("tcp://").split(":")
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", host, "--port", port, "--no-dashboard"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    worker = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2", "--nthreads", "1"]
        + ["--host", host, "--no-dashboard"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        from distributed import Client

        with Client(address, timeout="120s") as probe:
            probe.wait_for_workers(2, timeout=300)
        yield address
    finally:
        stop_owned(worker)
        stop_owned(scheduler)  # each process group: SIGTERM, then SIGKILL of what is left


@pytest.fixture(scope="module")
def client(scheduler_address):
    c = cluster.dask_client(scheduler_address)
    yield c
    cluster.close_client(c)


def test_split_batch_on_two_workers_equals_one_batch(client, here: Trajectory) -> None:
    assert len(client.scheduler_info(n_workers=-1)["workers"]) == 2
    there = cluster.fly(client, _batch())
    assert there.variant_names == here.variant_names
    for name, series in here.series.items():
        np.testing.assert_array_equal(there.series[name], series, err_msg=name)
    assert there.events == here.events


def test_each_worker_s_pools_get_one_thread_and_a_local_cluster_s_their_share_of_the_cores(client, shared_dask) -> None:
    """A scheduler's workers (2 processes × 1 thread, started as an operator would) give a task's thread pools one
    thread each; the shared LocalCluster's workers the cores over its workers (the engine flew the same above)."""
    from sim_core.threads import thread_budget

    assert set(client.run(thread_budget).values()) == {1}
    workers = len(shared_dask.scheduler_info(n_workers=-1)["workers"])
    assert set(shared_dask.run(thread_budget).values()) == {cluster.local_thread_budget(workers)}


def test_a_local_cluster_serves_http_on_a_free_loopback_port_and_no_dashboard(shared_dask) -> None:
    """A server's LocalCluster must not take distributed's well-known dashboard port 8787 (it did, with
    dashboard_address=None, whenever 8787 was free): its scheduler's HTTP routes listen on a loopback port the kernel
    chose (in its ephemeral range)."""
    low, high = map(int, Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split())
    sockets = [sock.getsockname() for sock in shared_dask.cluster.scheduler.http_server._sockets.values()]
    assert sockets and all(host == "127.0.0.1" and low <= port <= high for host, port, *_ in sockets), sockets


def test_map_cases_keeps_order(client) -> None:
    assert cluster.map_cases(client, abs, [-3, 2, -1]) == [3, 2, 1]


def test_whatif_sweep_on_the_cluster_equals_the_local_sweep(client) -> None:
    from sim_core import whatif

    s = _batch()
    variants = s.variants
    base = Scenario.model_validate({**s.model_dump(), "variants": [variants[0].model_dump()]})
    assert whatif.sweep(base, variants, flyer=cluster.flyer(client)) == whatif.sweep(base, variants)


def test_a_server_job_on_a_separately_started_cluster_equals_the_engine(scheduler_address, tmp_path) -> None:
    import time

    from fastapi.testclient import TestClient

    from backend.app import create_app
    from backend.core.auth import Role
    from sim_core.scenario import apply_overrides
    from tests.backend.conftest import bearer, make_settings

    settings = make_settings(tmp_path, f"sqlite:///{tmp_path / 'jobs.sqlite'}", dask_scheduler=scheduler_address)
    body = {"library": "somov-ge4-scan", "set": ["duration_s=20"]}
    with TestClient(create_app(settings)) as api:
        operator = bearer(api.app.state.services.auth.issue("op", Role.operator)[1])
        job_id = api.post("/api/v1/simulations", json=body, headers=operator).json()["id"]
        deadline = time.monotonic() + 400.0
        while (job := api.get(f"/api/v1/simulations/{job_id}", headers=operator).json())["status"] in (
            "queued",
            "running",
        ):
            assert time.monotonic() < deadline, job
            time.sleep(0.1)
    assert job["status"] == "succeeded", job["error"]
    direct = engine.simulate(apply_overrides(scenario_library.get("somov-ge4-scan"), ["duration_s=20"]))
    expected = {k: v for k, v in direct.summary(0).items() if k != "wall_time_s"}
    assert {k: v for k, v in job["summary"]["variants"][0].items() if k != "wall_time_s"} == expected
