"""Shared test fixtures: where the real third-party data lives, the databases under test, one Dask cluster."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from distributed import Client, Worker

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The ../shared/data folder of real reference data (README there gives provenance)."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"reference data missing: expected {SHARED_DATA} beside the repository")
    return SHARED_DATA


@pytest.fixture(scope="session")
def postgres_url() -> str:
    """URL of the PostgreSQL server used as the production path (CI sets it; else skip)."""
    url = os.environ.get("ACS_TWIN_TEST_POSTGRES_URL")
    if not url:
        pytest.skip("ACS_TWIN_TEST_POSTGRES_URL not set")
    return url


SETTLE_S = 60.0  # a task the test left running gets this long to see its cancel Event before the worker restarts
WORKER_BACK_S = 300.0  # a restarted worker imports and loads the engine again; minutes on a loaded machine


@pytest.fixture(scope="session")
def shared_dask() -> Iterator[Client]:
    """This test process's one Dask LocalCluster (one worker process, the engine loaded as it joins), started on
    first use: the apps and commands whose jobs, twin sessions and diagnoses need no cluster of their own fly on it
    (one each cost a worker start and an engine load). Tests about a cluster's own processes keep their own."""
    from backend.jobs import cluster

    client = cluster.dask_client(n_workers=1)
    yield client
    cluster.close_client(client)


def _executing(dask_worker: Worker) -> int:
    return dask_worker.state.executing_count  # a released task still running in the worker's thread counts too


def settle(client: Client) -> None:
    """Leave the shared cluster as a fresh one: no task running (waited for, else its worker restarted), a worker
    up. An app that stops sets its jobs' cancel Events; their tasks stop at their next look."""
    deadline = time.monotonic() + SETTLE_S
    while any(client.run(_executing).values()) and time.monotonic() < deadline:
        time.sleep(0.1)
    if any(client.run(_executing).values()):
        client.restart(timeout=WORKER_BACK_S)
    client.wait_for_workers(1, timeout=WORKER_BACK_S)


@pytest.fixture
def dask_scheduler(shared_dask: Client) -> Iterator[str]:
    """Address of the shared cluster's scheduler for one test (Settings.dask_scheduler, $ACS_TWIN_DASK_SCHEDULER),
    the cluster settled after it."""
    yield shared_dask.scheduler.address
    settle(shared_dask)


def pytest_configure(config: pytest.Config) -> None:
    """Numba cache saves under a lock: the two workers (and warm before them) may save one function's signatures at
    once, and numba alone could then file both under one data-file name (backend.jobs.kernel_signatures)."""
    from backend.jobs.kernel_signatures import serialise_cache_saves

    serialise_cache_saves()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files holding a ``slow`` test first, each file's tests kept together and in order: scripts/test.sh hands
    whole files to its two workers in this order (``--dist loadfile --no-loadscope-reorder``), so they start on the
    long files and finish together on short ones (xdist's own reorder, by test count, left the long one-test
    files — live diagnosis, OpenAPI fuzzing, the warm command — for the end, one worker alone on them)."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_files)
