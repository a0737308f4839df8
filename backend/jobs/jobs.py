"""Simulation jobs: a bounded queue drained by dispatcher threads, one worker process per job.

Simulations never run in the event loop nor in the server process: each job gets a fresh
``spawn`` process (killable on cancel); dispatcher threads wait on them and persist the outcome.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import queue
import shutil
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from backend.core.errors import ApiError
from backend.core.settings import Settings
from backend.jobs.job_repository import JobRepository
from backend.jobs.simulators import run_in_worker, validate_scenario

__all__ = ["JobManager"]

CANCEL_GRACE_S = 1.0  # time a worker gets to stop by itself before it is terminated
PROGRESS_PERSIST_S = 1.0  # how often running progress is written to the database


@dataclass
class _Handle:
    body: dict[str, Any]
    progress: Any
    cancel: Any
    options: dict[str, Any] = field(default_factory=dict)
    process: Any = None
    cancel_at: float | None = field(default=None)


class JobManager:
    """Admits, runs, cancels and reports simulation jobs within the configured limits."""

    def __init__(self, settings: Settings, repo: JobRepository) -> None:
        self._settings, self._repo = settings, repo
        self._ctx = mp.get_context("spawn")
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._active: dict[str, _Handle] = {}
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []

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
        for job_id, handle in handles.items():
            self._repo.finish(job_id, "interrupted", error="server stopped while the job was active")
            handle.cancel.set()
            handle.cancel_at = time.monotonic()
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
            self._active[job_id] = _Handle(scenario, self._ctx.Value("d", 0.0), self._ctx.Event(), options or {})
            self._repo.add(job_id, scenario, created_by)
        self._queue.put(job_id)
        return job_id

    def _check_limits(self, cost: Any) -> None:
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
        return None if handle is None else float(handle.progress.value)

    def cancel(self, job_id: str) -> bool:
        """Request cancellation; the job is recorded cancelled at once. False if not active or already cancelled."""
        with self._lock:
            handle = self._active.get(job_id)
            if handle is None or handle.cancel.is_set():
                return False
            handle.cancel.set()
            handle.cancel_at = time.monotonic()
        self._repo.finish(job_id, "cancelled", error="cancelled on request")
        return True

    def result_dir(self, job_id: str) -> Path:
        """Directory of a job's result files."""
        return self._settings.jobs_dir() / job_id

    def _dispatch(self) -> None:
        while (job_id := self._queue.get()) is not None:
            with self._lock:
                handle = self._active.get(job_id)
            try:
                if handle is not None and not handle.cancel.is_set():
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
        handle.process = self._ctx.Process(
            target=run_in_worker,
            name=f"sim-{job_id[:8]}",
            args=(handle.body, str(out), handle.progress, handle.cancel, handle.options),
        )
        handle.process.start()
        self._supervise(job_id, handle)
        self._record_outcome(job_id, handle.process.exitcode, out)

    def _supervise(self, job_id: str, handle: _Handle) -> None:
        last_persist = time.monotonic()
        while handle.process.is_alive():
            handle.process.join(0.1)
            now = time.monotonic()
            if handle.cancel_at is not None and now - handle.cancel_at > CANCEL_GRACE_S:
                handle.process.terminate()
                handle.process.join(5)
            if now - last_persist > PROGRESS_PERSIST_S:
                self._repo.set_progress(job_id, float(handle.progress.value))
                last_persist = now

    def _record_outcome(self, job_id: str, exitcode: int | None, out: Path) -> None:
        summary_file = out / "summary.json"
        if exitcode == 0 and summary_file.exists():
            npz = out / "trajectory.npz"
            if npz.exists() and npz.stat().st_size > self._settings.max_output_mb * 1e6:
                shutil.rmtree(out, ignore_errors=True)
                self._repo.finish(job_id, "failed", error="output over max_output_mb; files removed")
                return
            self._repo.finish(job_id, "succeeded", summary=json.loads(summary_file.read_text()))
        elif (out / "error.txt").exists():
            self._repo.finish(job_id, "failed", error=(out / "error.txt").read_text()[-4000:])
        else:
            self._repo.finish(
                job_id, "cancelled" if exitcode in (3, -15) else "failed", error=f"worker exited with code {exitcode}"
            )
