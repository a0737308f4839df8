"""Token repository: create, find by hash, list and revoke API tokens."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from backend.core.models import TokenRow

__all__ = ["TokenRepository"]


class TokenRepository:
    """Stores tokens by their sha256 hash; never sees a plain token."""

    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def add(self, name: str, role: str, token_sha256: str) -> TokenRow:
        """Insert a token row and return it."""
        row = TokenRow(name=name, role=role, token_sha256=token_sha256, created_at=datetime.now(UTC))
        with self._sessions.begin() as session:
            session.add(row)
        return row

    def find_active(self, token_sha256: str) -> TokenRow | None:
        """The unrevoked token with this hash, or None."""
        with self._sessions() as session:
            stmt = select(TokenRow).where(TokenRow.token_sha256 == token_sha256, TokenRow.revoked_at.is_(None))
            return session.scalars(stmt).first()

    def list(self) -> list[TokenRow]:
        """All tokens, newest first (hashes included; callers must not expose them)."""
        with self._sessions() as session:
            return list(session.scalars(select(TokenRow).order_by(TokenRow.id.desc())))

    def revoke(self, token_id: int) -> TokenRow | None:
        """Mark a token revoked; None if it does not exist."""
        with self._sessions.begin() as session:
            row = session.get(TokenRow, token_id)
            if row is not None and row.revoked_at is None:
                row.revoked_at = datetime.now(UTC)
            return row

    def revoked_among(self, token_ids: Iterable[int]) -> set[int]:
        """Which of these token ids are revoked (by this process or any other sharing the database)."""
        ids = sorted(set(token_ids))
        if not ids:
            return set()
        with self._sessions() as session:
            stmt = select(TokenRow.id).where(TokenRow.id.in_(ids), TokenRow.revoked_at.is_not(None))
            return set(session.scalars(stmt))

    def count_active_admins(self) -> int:
        """How many unrevoked admin tokens exist (first start creates one when zero)."""
        with self._sessions() as session:
            stmt = select(TokenRow).where(TokenRow.role == "admin", TokenRow.revoked_at.is_(None))
            return len(list(session.scalars(stmt)))
