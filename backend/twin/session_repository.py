"""Twin-session repository."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from backend.core.models import TwinSessionRow

__all__ = ["TwinSessionRepository"]


class TwinSessionRepository:
    """Create and read twin sessions."""

    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def add(self, **fields: Any) -> TwinSessionRow:
        """Insert a session row stamped now."""
        row = TwinSessionRow(created_at=datetime.now(UTC), **fields)
        with self._sessions.begin() as session:
            session.add(row)
        return row

    def get(self, session_id: str) -> TwinSessionRow | None:
        """The session or None."""
        with self._sessions() as session:
            return session.get(TwinSessionRow, session_id)

    def list(self, limit: int = 100) -> list[TwinSessionRow]:
        """Newest first."""
        with self._sessions() as session:
            stmt = select(TwinSessionRow).order_by(TwinSessionRow.created_at.desc()).limit(limit)
            return list(session.scalars(stmt))
