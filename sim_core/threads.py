"""The thread budget of the engine's and the diagnosis' thread pools: this process' share of the machine's cores.

The batch engine flies variants on a thread each (:func:`sim_core.closed_loop.fly_batch`) and the tachometer
likelihood filters rows in blocks on threads (:func:`sim_core.fault_detection.count_loglik`); both kernels release
the GIL and neither result depends on the thread count. A plain process may use every core. A Dask worker shares
its host with the other workers, each running its own tasks at once: there, threads per core would be
oversubscribed (a 2-worker cluster on 2 cores ran 4 engine threads). The worker is given its share as it joins
(``backend.jobs.engine_worker.EngineWorker`` sets :data:`THREADS_ENV`); anyone may set it for a process.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["THREADS_ENV", "single_threaded_kernel_blas", "thread_budget"]

THREADS_ENV = "ACS_TWIN_THREADS"


def thread_budget() -> int:
    """Threads a pool of this process may run at once: $ACS_TWIN_THREADS if set (a positive integer), else the
    machine's cores."""
    value = os.environ.get(THREADS_ENV, "").strip()
    if not value:
        return os.cpu_count() or 1
    try:
        threads = int(value)
    except ValueError:
        threads = 0
    if threads < 1:
        raise ValueError(f"{THREADS_ENV}: expected a positive number of threads, got {value!r}")
    return threads


def single_threaded_kernel_blas() -> list[str]:
    """Give the BLAS that numba's kernels call (scipy's bundled OpenBLAS, reached through
    ``scipy.linalg.cython_blas``) one thread; the libraries set, by path (none when scipy uses another BLAS).

    The kernels' products are of 3–6-element vectors and matrices, which gain nothing from threads, yet OpenBLAS's
    worker thread spun beside every flight: one orbit of peer-basilisk-rw4 took 0.146 s CPU for 0.074 s wall on 2
    cores, 0.074 s CPU with one thread, the same wall and the same bits. numpy's own BLAS (another library) is
    left as it is."""
    import scipy
    import scipy.linalg.cython_blas  # noqa: F401  (loads the library numba's kernels call)
    from threadpoolctl import ThreadpoolController

    bundled = Path(scipy.__file__).resolve().parent.parent / "scipy.libs"
    done = []
    for lib in ThreadpoolController().lib_controllers:
        if lib.user_api == "blas" and Path(lib.filepath).resolve().parent == bundled:
            lib.set_num_threads(1)
            done.append(lib.filepath)
    return done
