"""Job repository: the persisted state of simulation jobs."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, cast

from sqlalchemy import CursorResult, select, update
from sqlalchemy.orm import Session, sessionmaker

from backend.core.models import JobRow

__all__ = ["JobRepository", "ACTIVE_STATES", "FINAL_STATES"]

ACTIVE_STATES = ("queued", "running")
FINAL_STATES = ("succeeded", "failed", "cancelled", "interrupted")


def _now() -> datetime:
    return datetime.now(UTC)


class JobRepository:
    """Create, read and move jobs through queued → running → a final state."""

    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def add(self, job_id: str, scenario: dict[str, Any], created_by: str) -> JobRow:
        """Insert a queued job."""
        row = JobRow(
            id=job_id, status="queued", progress=0.0, scenario=scenario, created_by=created_by, created_at=_now()
        )
        with self._sessions.begin() as session:
            session.add(row)
        return row

    def get(self, job_id: str) -> JobRow | None:
        """The job or None."""
        with self._sessions() as session:
            return session.get(JobRow, job_id)

    def list(self, limit: int = 100) -> list[JobRow]:
        """Most recent jobs first."""
        with self._sessions() as session:
            stmt = select(JobRow).order_by(JobRow.created_at.desc()).limit(limit)
            return list(session.scalars(stmt))

    def mark_running(self, job_id: str, result_dir: str) -> bool:
        """queued → running; False if the job left the queue meanwhile (cancelled)."""
        with self._sessions.begin() as session:
            stmt = (
                update(JobRow)
                .where(JobRow.id == job_id, JobRow.status == "queued")
                .values(status="running", started_at=_now(), result_dir=result_dir)
            )
            return cast("CursorResult[Any]", session.execute(stmt)).rowcount == 1

    def set_progress(self, job_id: str, progress: float) -> None:
        """Store the progress fraction of a running job."""
        with self._sessions.begin() as session:
            session.execute(
                update(JobRow).where(JobRow.id == job_id, JobRow.status == "running").values(progress=progress)
            )

    def finish(self, job_id: str, status: str, summary: dict[str, Any] | None = None, error: str | None = None) -> None:
        """Move an active job to a final state (a job already final is left alone)."""
        if status not in FINAL_STATES:
            raise ValueError(f"status: must be one of {FINAL_STATES}, got {status!r}")
        values: dict[str, Any] = {"status": status, "finished_at": _now(), "error": error}
        if summary is not None:
            values["summary"], values["progress"] = summary, 1.0
        with self._sessions.begin() as session:
            session.execute(
                update(JobRow).where(JobRow.id == job_id, JobRow.status.in_(ACTIVE_STATES)).values(**values)
            )

    def interrupt_active(self) -> int:
        """On start-up: jobs left queued or running by a previous server become interrupted."""
        with self._sessions.begin() as session:
            stmt = (
                update(JobRow)
                .where(JobRow.status.in_(ACTIVE_STATES))
                .values(status="interrupted", finished_at=_now(), error="server restarted while the job was active")
            )
            return cast("CursorResult[Any]", session.execute(stmt)).rowcount
