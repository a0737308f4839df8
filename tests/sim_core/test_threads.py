"""The thread budget of the engine's and the diagnosis' pools: every core in a plain process, what a Dask worker
(or anyone) sets in ACS_TWIN_THREADS otherwise; and a batch flown on one thread equals the batch flown on many."""

from __future__ import annotations

import os

import numpy as np
import pytest

from sim_core.threads import THREADS_ENV, single_threaded_kernel_blas, thread_budget


def test_a_plain_process_uses_every_core(monkeypatch) -> None:
    monkeypatch.delenv(THREADS_ENV, raising=False)
    assert thread_budget() == (os.cpu_count() or 1)


def test_the_environment_sets_the_budget_and_a_bad_one_is_refused(monkeypatch) -> None:
    monkeypatch.setenv(THREADS_ENV, "1")
    assert thread_budget() == 1
    for bad in ("0", "-2", "two"):
        monkeypatch.setenv(THREADS_ENV, bad)
        with pytest.raises(ValueError, match=f"{THREADS_ENV}: expected a positive number of threads, got '{bad}'"):
            thread_budget()


def test_the_tachometer_likelihood_is_the_same_on_one_thread_as_on_many(monkeypatch) -> None:
    from sim_core import fault_detection as fd

    rng = np.random.default_rng(7)
    n, rows, quantum = 120, 3 * fd.THREAD_ROWS + 5, 0.026
    speed = 10.0 + np.cumsum(rng.normal(0.0, 0.01, n))
    y = np.round(speed / quantum) * quantum
    drift = np.ascontiguousarray(np.diff(speed)[None, :] + rng.normal(0.0, 0.002, (rows, n - 1)))
    q_var = np.full(n - 1, 1e-5)
    offset, reset = np.zeros((rows, n)), np.zeros((rows, n), dtype=np.bool_)
    monkeypatch.setenv(THREADS_ENV, "1")
    one = fd.count_loglik(y, drift, q_var, quantum, 1e-8, offset, reset)
    monkeypatch.setenv(THREADS_ENV, "4")
    many = fd.count_loglik(y, drift, q_var, quantum, 1e-8, offset, reset)
    np.testing.assert_array_equal(one, many)


def test_the_kernels_blas_runs_one_thread_and_numpy_s_keeps_its_own() -> None:
    """numba's kernels call scipy's bundled OpenBLAS: the engine gives it one thread (its worker thread spun beside
    every flight, doubling a flight's CPU); numpy's own BLAS is not touched."""
    from pathlib import Path

    import scipy
    from threadpoolctl import threadpool_info

    import sim_core.closed_loop  # noqa: F401  (sets the kernels' BLAS as it is imported)

    bundled = Path(scipy.__file__).resolve().parent.parent / "scipy.libs"
    blas = {
        Path(i["filepath"]).resolve().parent: i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"
    }
    if bundled not in blas:
        pytest.skip(f"scipy here does not bundle its OpenBLAS in {bundled} (found: {sorted(map(str, blas))})")
    assert blas[bundled] == 1
    assert {Path(p).resolve().parent for p in single_threaded_kernel_blas()} == {bundled}  # numpy's BLAS untouched
