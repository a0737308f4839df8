"""Audit repository: append and list audited actions."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from backend.core.models import AuditRow

__all__ = ["AuditRepository"]


class AuditRepository:
    """Append-only log of uploads, simulations, acknowledgements and token changes."""

    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def record(self, actor: str, action: str, target: str, detail: dict[str, Any] | None = None) -> None:
        """Append one entry stamped now (UTC)."""
        row = AuditRow(at=datetime.now(UTC), actor=actor, action=action, target=target, detail=detail or {})
        with self._sessions.begin() as session:
            session.add(row)

    def list(self, limit: int = 100, action: str | None = None) -> list[AuditRow]:
        """Most recent entries first, optionally only one action."""
        with self._sessions() as session:
            stmt = select(AuditRow).order_by(AuditRow.id.desc()).limit(limit)
            if action:
                stmt = stmt.where(AuditRow.action == action)
            return list(session.scalars(stmt))
