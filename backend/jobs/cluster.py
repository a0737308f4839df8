"""The distributed engine: a Dask client for simulation jobs, hypothesis sweeps, what-if sweeps and campaigns.

:func:`dask_client` returns a client of a ``LocalCluster`` on this machine (worker processes, one
thread each, bound to 127.0.0.1, no dashboard port; as many as the machine has cores, at most 4)
unless a scheduler address is given (``scheduler=`` / ``--scheduler tcp://host:port`` /
``ACS_TWIN_DASK_SCHEDULER``). Every worker loads the engine's compiled kernels when it joins, a
restarted one too (:mod:`backend.jobs.engine_worker`), so the first task does not pay
numba's start-up, and is given its thread budget (``ACS_TWIN_THREADS``, :mod:`sim_core.threads`): the
engine's and the diagnosis' thread pools of a task use the worker's share of the host's cores, not every
core (a LocalCluster's worker: cores / workers; a scheduler's: one, unless its environment sets it). The
workers of a LocalCluster are children of this process that it owns
(:func:`backend.core.processes.become_owned_child`: own process group, gone with this process even
after ``kill -9``); a scheduler's workers belong to whoever started them.

:class:`ServerCluster` is the server's one client (and ``acs-twin diagnose``'s), connected on first use and
closed at shutdown.

:func:`fly` splits a batch scenario's variants into one chunk per worker and merges the trajectories.
Each variant keeps the random stream it has in the whole batch (the engine seeds variant i with
``seed·1000 + 7919 i + seed_offset``; a chunk's offsets are shifted so that i is the batch index), so
the result is identical to :func:`sim_core.engine.simulate` on one machine, bit for bit.
:func:`map_cases` maps any picklable function over independent cases (campaigns) in order.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from sim_core.scenario import Scenario
from sim_core.trajectory import Trajectory

if TYPE_CHECKING:  # distributed ships its types (py.typed): the seam is typed by the library itself
    from distributed import Client

__all__ = [
    "SCHEDULER_ENV",
    "ServerCluster",
    "close_client",
    "dask_client",
    "local_thread_budget",
    "local_workers",
    "fly",
    "flyer",
    "map_cases",
    "split_variants",
    "merge_trajectories",
]

SCHEDULER_ENV = "ACS_TWIN_DASK_SCHEDULER"
SEED_STRIDE = 7919  # sim_core.engine.simulate: variant i draws from seed·1000 + 7919 i + seed_offset
T = TypeVar("T")
Case = TypeVar("Case")


def local_workers() -> int:
    """Worker processes of a default LocalCluster: one per core, at most 4 (2 on this project's machines)."""
    return max(1, min(os.cpu_count() or 1, 4))


def local_thread_budget(n_workers: int) -> int:
    """Threads each worker of a LocalCluster of ``n_workers`` single-thread processes may give one task's thread
    pools (:func:`sim_core.threads.thread_budget`): its share of this machine's cores, at least one."""
    return max(1, (os.cpu_count() or 1) // max(n_workers, 1))


def dask_client(scheduler: str | None = None, n_workers: int | None = None, warm: bool = True) -> Client:
    """A ``distributed.Client``: to ``scheduler`` (or $ACS_TWIN_DASK_SCHEDULER), else a new LocalCluster."""
    from distributed import Client, LocalCluster

    from backend.jobs.engine_worker import EngineWorker

    address = scheduler or os.environ.get(SCHEDULER_ENV) or None
    if address:
        if not address.startswith(("tcp://", "tls://", "inproc://", "ws://", "wss://")):
            raise ValueError(f"scheduler: expected an address like tcp://host:8786, got {address!r}")
        client = Client(address, timeout="10s")
    else:
        cluster = LocalCluster(
            n_workers=n_workers or local_workers(),
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",  # its HTTP routes on a free loopback port, never 8787
            scheduler_kwargs={"dashboard": False},
            silence_logs=40,
        )
        client = Client(cluster)
    threads = None if address else local_thread_budget(n_workers or local_workers())
    client.register_plugin(EngineWorker(owned=not address, warm=warm, threads=threads))
    return client


def close_client(client: Client) -> None:
    """Close the client and, when it made its own LocalCluster, the cluster's worker processes."""
    cluster = getattr(client, "cluster", None)
    client.close()
    if cluster is not None:
        cluster.close()


class ServerCluster:
    """The server's Dask client: connected on first use (a LocalCluster it owns, or a scheduler), closed on stop."""

    def __init__(self, scheduler: str | None, n_workers: int) -> None:
        self._scheduler, self._n_workers = scheduler, n_workers
        self._client: Client | None = None
        self._error: str | None = None
        self._closed = False
        self._lock = threading.Lock()

    def client(self) -> Client:
        """The connected client (connects on the first call); RuntimeError naming the cause when it cannot."""
        with self._lock:
            if self._closed:
                raise RuntimeError("the server is stopping: no Dask client")
            if self._client is None and self._error is None:
                try:
                    self._client = dask_client(self._scheduler, self._n_workers)
                except (OSError, ValueError, TimeoutError) as exc:
                    where = self._scheduler or "a LocalCluster"
                    self._error = f"Dask cluster ({where}) unavailable: {type(exc).__name__}: {exc}"
            if self._client is None:
                raise RuntimeError(self._error)
            return self._client

    @property
    def connected(self) -> Client | None:
        """The client if connected, else None (never connects)."""
        return self._client

    def close(self) -> None:
        """Close the client and stop the owned LocalCluster's worker processes; later calls of ``client`` fail."""
        with self._lock:
            self._closed = True
            client, self._client = self._client, None
        if client is not None:
            close_client(client)


def split_variants(s: Scenario, n_chunks: int) -> list[Scenario]:
    """The batch as ``n_chunks`` batches of consecutive variants, each variant's random stream unchanged."""
    n = len(s.variants)
    bounds = np.linspace(0, n, min(n_chunks, n) + 1).round().astype(int)
    data = s.model_dump()
    chunks = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        variants = []
        for v in data["variants"][a:b]:
            variants.append({**v, "seed_offset": v["seed_offset"] + SEED_STRIDE * int(a)})
        chunks.append(Scenario.model_validate({**data, "variants": variants}))
    return chunks


def merge_trajectories(parts: Sequence[Trajectory]) -> Trajectory:
    """One trajectory of the parts' variants in order (same scenario, same time axis)."""
    first = parts[0]
    return Trajectory(
        scenario_name=first.scenario_name,
        variant_names=[n for p in parts for n in p.variant_names],
        t_s=first.t_s,
        series={k: np.concatenate([p.series[k] for p in parts], axis=0) for k in first.series},
        events=[e for p in parts for e in p.events],
        wheel_inertia_kg_m2=first.wheel_inertia_kg_m2,
        wall_time_s=max(p.wall_time_s for p in parts),
        simulated_time_s=first.simulated_time_s,
        extra=dict(first.extra),
    )


def _simulate(s: Scenario) -> Trajectory:
    from sim_core.engine import simulate  # numba kernels: imported where a case is flown, not with the server

    return simulate(s)


def fly(client: Client, s: Scenario) -> Trajectory:
    """:func:`sim_core.engine.simulate` of the batch with its variants spread over the cluster's workers."""
    n_workers = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
    chunks = split_variants(s, n_workers)
    if len(chunks) == 1:
        return client.submit(_simulate, chunks[0], pure=False).result()
    return merge_trajectories(client.gather(client.map(_simulate, chunks, pure=False)))


def flyer(client: Client) -> Callable[[Scenario], Trajectory]:
    """``fly`` bound to a client, for hooks that take how a batch is flown (diagnosis replay, what-if)."""
    return lambda s: fly(client, s)


def map_cases(client: Client, fn: Callable[[Case], T], cases: Sequence[Case]) -> list[T]:
    """``[fn(c) for c in cases]`` computed on the cluster, results in the order of ``cases``."""
    return list(client.gather(client.map(fn, list(cases), pure=False)))
