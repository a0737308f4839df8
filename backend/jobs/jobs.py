"""Simulation jobs: a bounded queue drained by dispatcher threads, each job one task on the Dask engine.

Simulations never run in the event loop nor in the server process: a dispatcher submits the job to
the server's Dask cluster (:class:`backend.jobs.cluster.ServerCluster`: a LocalCluster of worker
processes the server owns, or an existing cluster's scheduler) and waits on it; as many jobs run at
once as there are dispatchers (``job_workers``). The task (:func:`backend.jobs.simulators.run_job`)
reports progress as Dask events and stops once its job's cancel ``distributed.Event`` is set; one
that has not stopped ``CANCEL_GRACE_S`` later has its worker restarted. The server writes the result
files and persists the outcome.
"""

from __future__ import annotations

import contextlib
import json
import queue
import shutil
import threading
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from backend.core.errors import ApiError
from backend.core.settings import Settings
from backend.jobs.cluster import ServerCluster
from backend.jobs.job_repository import JobRepository
from backend.jobs.simulators import (
    PROGRESS_TOPIC,
    JobCancelled,
    JobCost,
    JobOutput,
    cancel_event_name,
    run_job,
    validate_scenario,
)

if TYPE_CHECKING:
    from distributed import Client, Future

__all__ = ["JobManager"]

CANCEL_GRACE_S = 5.0  # time a task gets to stop by itself (it looks every 0.25 s) before its worker is restarted
PROGRESS_PERSIST_S = 1.0  # how often running progress is written to the database
WAIT_STEP_S = 0.1  # a dispatcher looks at its job's progress and cancellation this often
RESTART_TIMEOUT_S = 300.0  # a worker restart's stop and return; past it Dask removes the worker with its nanny


@dataclass
class _Handle:
    body: dict[str, Any]
    options: dict[str, Any] = field(default_factory=dict)
    progress: float = 0.0
    future: Future[JobOutput] | None = None
    cancel_at: float | None = field(default=None)

    @property
    def cancelled(self) -> bool:
        return self.cancel_at is not None


class JobManager:
    """Admits, runs, cancels and reports simulation jobs within the configured limits."""

    def __init__(self, settings: Settings, repo: JobRepository, cluster: ServerCluster) -> None:
        self._settings, self._repo, self._cluster = settings, repo, cluster
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._active: dict[str, _Handle] = {}
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._subscribed = False
        self._stopping = False  # at shutdown the cluster itself stops: no worker restarts

    def start(self) -> int:
        """Mark jobs left active by a previous server interrupted, start dispatchers; returns count."""
        interrupted = self._repo.interrupt_active()
        for i in range(self._settings.job_workers):
            thread = threading.Thread(target=self._dispatch, name=f"job-dispatch-{i}", daemon=True)
            thread.start()
            self._threads.append(thread)
        return interrupted

    def stop(self) -> None:
        """Stop every active job (recorded interrupted, as after a crash) and the dispatchers (shutdown)."""
        with self._lock:
            handles = dict(self._active)
            self._stopping = True
        for job_id, handle in handles.items():
            self._repo.finish(job_id, "interrupted", error="server stopped while the job was active")
            self._request_cancel(job_id, handle)
        for _ in self._threads:
            self._queue.put(None)
        for thread in self._threads:
            thread.join(timeout=10)
        self._threads.clear()

    def submit(self, body: dict[str, Any], created_by: str, options: dict[str, Any] | None = None) -> str:
        """Validate limits and queue a job; ApiError 422 over a limit, 429 when the queue is full.

        ``options`` go to the engine as keywords (``fdir``, ``wheel_available``), e.g. for twin sessions.
        """
        scenario, cost = validate_scenario(body)
        self._check_limits(cost)
        job_id = uuid.uuid4().hex
        with self._lock:
            if len(self._active) >= self._settings.job_queue_size:
                raise ApiError(
                    429,
                    f"job queue full ({self._settings.job_queue_size} active jobs)",
                    field="job_queue_size",
                    headers={"Retry-After": str(self._settings.job_retry_after_s)},
                )
            self._active[job_id] = _Handle(scenario, options or {})
            self._repo.add(job_id, scenario, created_by)
        self._queue.put(job_id)
        return job_id

    def _check_limits(self, cost: JobCost) -> None:
        s = self._settings
        if cost.duration_s > s.max_sim_duration_s:
            raise ApiError(
                422,
                f"duration_s {cost.duration_s:g} over the limit max_sim_duration_s = {s.max_sim_duration_s:g}",
                "max_sim_duration_s",
            )
        if cost.batch_size > s.max_batch_size:
            raise ApiError(
                422,
                f"batch size {cost.batch_size} over the limit max_batch_size = {s.max_batch_size}",
                "max_batch_size",
            )
        if cost.output_bytes > s.max_output_mb * 1e6:
            raise ApiError(
                422,
                f"output {cost.output_bytes / 1e6:.1f} MB over the limit max_output_mb = {s.max_output_mb:g}",
                "max_output_mb",
            )

    def progress(self, job_id: str) -> float | None:
        """Live progress fraction of an active job, None when not active here."""
        with self._lock:
            handle = self._active.get(job_id)
        return None if handle is None else handle.progress

    def cancel(self, job_id: str) -> bool:
        """Request cancellation; the job is recorded cancelled at once. False if not active or already cancelled."""
        with self._lock:
            handle = self._active.get(job_id)
            if handle is None or handle.cancelled:
                return False
            handle.cancel_at = time.monotonic()
        self._repo.finish(job_id, "cancelled", error="cancelled on request")
        self._request_cancel(job_id, handle)
        return True

    def result_dir(self, job_id: str) -> Path:
        """Directory of a job's result files."""
        return self._settings.jobs_dir() / job_id

    def _request_cancel(self, job_id: str, handle: _Handle) -> None:
        """Set the job's cancel Event on the cluster (a queued job never reaches it)."""
        if handle.cancel_at is None:
            handle.cancel_at = time.monotonic()
        client = self._cluster.connected
        if client is not None and handle.future is not None:
            from distributed import Event

            Event(cancel_event_name(job_id), client=client).set()

    def _on_progress(self, event: tuple[float, tuple[str, float]]) -> None:
        job_id, fraction = event[1]
        with self._lock:
            handle = self._active.get(job_id)
        if handle is not None:
            handle.progress = float(fraction)

    def _client(self) -> Client:
        client = self._cluster.client()
        with self._lock:
            if not self._subscribed:
                client.subscribe_topic(PROGRESS_TOPIC, self._on_progress)
                self._subscribed = True
        return client

    def _dispatch(self) -> None:
        while (job_id := self._queue.get()) is not None:
            with self._lock:
                handle = self._active.get(job_id)
            try:
                if handle is not None and not handle.cancelled:
                    self._run(job_id, handle)
            finally:
                with self._lock:
                    self._active.pop(job_id, None)

    def _run(self, job_id: str, handle: _Handle) -> None:
        out = self.result_dir(job_id)
        if not self._repo.mark_running(job_id, str(out)):
            return
        out.mkdir(parents=True, exist_ok=True)
        (out / "scenario.json").write_text(json.dumps(handle.body))
        try:
            client = self._client()
        except RuntimeError as exc:
            self._repo.finish(job_id, "failed", error=str(exc))
            return
        future = client.submit(run_job, job_id, handle.body, handle.options, key=f"job-{job_id}", pure=False)
        handle.future = future
        if handle.cancelled:  # cancelled while the cluster was being connected
            self._request_cancel(job_id, handle)
        self._supervise(job_id, handle, client, future)
        if self._stopping:  # recorded interrupted; the cluster is going away with the task
            return
        self._record_outcome(job_id, future, out)
        from distributed import Event

        with contextlib.suppress(OSError):  # the scheduler forgets a cleared Event (unless it went away meanwhile)
            Event(cancel_event_name(job_id), client=client).clear()

    def _supervise(self, job_id: str, handle: _Handle, client: Client, future: Future[JobOutput]) -> None:
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        last_persist = time.monotonic()
        restarted = False
        while not done.wait(WAIT_STEP_S) and not self._stopping:
            now = time.monotonic()
            overdue = handle.cancel_at is not None and now - handle.cancel_at > CANCEL_GRACE_S
            if overdue and not restarted and not self._stopping:
                self._restart_worker_of(client, future)
                restarted = True
            if now - last_persist > PROGRESS_PERSIST_S:
                self._repo.set_progress(job_id, handle.progress)
                last_persist = now

    @staticmethod
    def _restart_worker_of(client: Client, future: Future[JobOutput]) -> None:
        """Stop a task that ignores its cancel Event: release it, then restart the worker that runs it."""
        workers = [w for w, keys in client.processing().items() if future.key in keys]
        future.cancel()
        if workers:
            with contextlib.suppress(OSError):  # the cluster went away meanwhile: nothing left to stop
                client.restart_workers(workers, timeout=RESTART_TIMEOUT_S, raise_for_error=False)

    def _record_outcome(self, job_id: str, future: Future[JobOutput], out: Path) -> None:
        if future.cancelled():
            self._repo.finish(job_id, "cancelled", error="cancelled on request")
            return
        exc = future.exception()
        if isinstance(exc, JobCancelled):
            self._repo.finish(job_id, "cancelled", error="cancelled on request")
        elif exc is not None:
            text = "".join(traceback.format_exception(type(exc), exc, future.traceback()))
            self._repo.finish(job_id, "failed", error=text[-4000:])
        else:
            npz, summary = future.result()
            if len(npz) > self._settings.max_output_mb * 1e6:
                shutil.rmtree(out, ignore_errors=True)
                self._repo.finish(job_id, "failed", error="output over max_output_mb; files removed")
                return
            (out / "trajectory.npz").write_bytes(npz)
            (out / "summary.json").write_text(json.dumps(summary))
            self._repo.finish(job_id, "succeeded", summary=summary)
