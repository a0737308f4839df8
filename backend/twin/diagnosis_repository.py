"""Diagnosis repository: the persisted diagnoses (they survive a restart), on SQLite or PostgreSQL."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, cast

from sqlalchemy import CursorResult, select, update
from sqlalchemy.orm import Session, sessionmaker

from backend.core.models import DiagnosisRow

__all__ = ["DiagnosisRepository"]

FIELDS = (
    "id",
    "satellite",
    "dictionary",
    "scenario",
    "start_utc",
    "end_utc",
    "status",
    "error",
    "result",
    "trigger",
    "alarm_id",
    "alarm_utc",
    "created_by",
)
RESTARTED = "the server restarted while the diagnosis ran; start it again"


def _record(row: DiagnosisRow) -> dict[str, Any]:
    return {name: getattr(row, name) for name in FIELDS}


class DiagnosisRepository:
    """Create, finish, read and list diagnoses (records as dicts of FIELDS)."""

    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def add(self, record: dict[str, Any]) -> dict[str, Any]:
        """Insert a running diagnosis; the stored record."""
        row = DiagnosisRow(status="running", created_at=datetime.now(UTC), **record)
        with self._sessions.begin() as session:
            session.add(row)
            return _record(row)

    def finish(self, run_id: str, status: str, result: dict[str, Any] | None = None, error: str | None = None) -> None:
        """running → succeeded (with the result) or failed (with the reason)."""
        with self._sessions.begin() as session:
            session.execute(
                update(DiagnosisRow)
                .where(DiagnosisRow.id == run_id, DiagnosisRow.status == "running")
                .values(status=status, result=result, error=error, finished_at=datetime.now(UTC))
            )

    def link_alarm(self, run_id: str, alarm_id: int) -> None:
        """Record the archive alarm that started the diagnosis."""
        with self._sessions.begin() as session:
            session.execute(update(DiagnosisRow).where(DiagnosisRow.id == run_id).values(alarm_id=alarm_id))

    def get(self, run_id: str) -> dict[str, Any] | None:
        """The diagnosis, None if unknown."""
        with self._sessions() as session:
            row = session.get(DiagnosisRow, run_id)
            return None if row is None else _record(row)

    def list(self, limit: int = 200, alarm_id: int | None = None, satellite: str | None = None) -> list[dict[str, Any]]:
        """Newest first, optionally only those of one alarm or one satellite."""
        stmt = select(DiagnosisRow).order_by(DiagnosisRow.created_at.desc()).limit(limit)
        if alarm_id is not None:
            stmt = stmt.where(DiagnosisRow.alarm_id == alarm_id)
        if satellite is not None:
            stmt = stmt.where(DiagnosisRow.satellite == satellite)
        with self._sessions() as session:
            return [_record(row) for row in session.scalars(stmt)]

    def fail_running(self) -> int:
        """On start-up: diagnoses a previous server left running failed, saying so; their count."""
        with self._sessions.begin() as session:
            stmt = (
                update(DiagnosisRow)
                .where(DiagnosisRow.status == "running")
                .values(status="failed", error=RESTARTED, finished_at=datetime.now(UTC))
            )
            return cast("CursorResult[Any]", session.execute(stmt)).rowcount
