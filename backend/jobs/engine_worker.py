"""What each Dask worker of the server's cluster does as it joins: the engine's kernels loaded, the worker owned.

A module of its own so that the server imports ``distributed`` only when it first connects a cluster
(:func:`backend.jobs.cluster.dask_client`), not at start-up.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING

from distributed import WorkerPlugin

from sim_core.scenario import Scenario

if TYPE_CHECKING:
    from distributed import Worker

__all__ = ["ClosingHeartbeat", "EngineWorker", "warm_engine"]

HEARTBEAT_FAILURE = "Failed to communicate with scheduler during heartbeat"  # distributed.worker's report


def warm_engine() -> float:
    """Fly a 2-second nominal case so the engine's kernels are compiled or loaded from the cache; wall time (s)."""
    import time

    from sim_core import scenario_library
    from sim_core.engine import simulate

    start = time.perf_counter()
    s = scenario_library.get("peer-basilisk-rw4").model_copy(update={"duration_s": 2.0})
    simulate(Scenario.model_validate(s.model_dump()))
    return time.perf_counter() - start


class ClosingHeartbeat(logging.Filter):
    """Drops distributed's heartbeat-failure report (with its traceback) of a worker that is itself closing.

    An orderly stop closes the worker's connection pool under a heartbeat in flight, which distributed reports
    at ERROR level; the same report from a running worker (a scheduler that vanished) passes.
    """

    def __init__(self, worker: Worker) -> None:
        super().__init__()
        self._worker = worker

    def filter(self, record: logging.LogRecord) -> bool:
        from distributed.core import Status

        closing = self._worker.status in (Status.closing, Status.closing_gracefully, Status.closed)
        return not (closing and record.getMessage().startswith(HEARTBEAT_FAILURE))


class EngineWorker(WorkerPlugin):
    """Set up each worker as it joins: owned by this process (a LocalCluster's), its thread budget, the engine warm."""

    name = "acs-twin-engine"

    def __init__(self, owned: bool, warm: bool, threads: int | None = None) -> None:
        self.owned, self.warm, self.threads = owned, warm, threads

    def setup(self, worker: Worker) -> None:
        """Own process group and death with the parent (owned workers); the thread budget of a task's thread pools
        (:func:`sim_core.threads.thread_budget`): ``threads`` if given (a LocalCluster's share of the cores per
        worker), else the worker's own environment's, else one (a scheduler's workers are sized to their hosts by
        whoever started them, ``--nworkers`` × ``--nthreads`` tasks at once: Dask's own convention, its nanny's
        OMP_NUM_THREADS=1);
        the kernels compiled in a thread of their own, so the worker takes tasks at once (an engine task meanwhile
        waits on numba's compile lock; a cold compile takes minutes on a loaded machine, and a rigid-spin job needs
        none)."""
        import os

        from sim_core.threads import THREADS_ENV

        if self.threads is not None:
            os.environ[THREADS_ENV] = str(self.threads)
        elif not os.environ.get(THREADS_ENV):
            os.environ[THREADS_ENV] = "1"
        if self.owned:
            from backend.core.processes import become_owned_child

            become_owned_child()
            logging.getLogger("distributed.worker").addFilter(ClosingHeartbeat(worker))
        if self.warm:
            threading.Thread(target=warm_engine, name="engine-warm", daemon=True).start()
