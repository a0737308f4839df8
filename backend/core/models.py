"""ORM models of the backend's own tables; API schemas live apart in backend/schemas.py."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import JSON, BigInteger, DateTime, Float, Integer, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

__all__ = ["Base", "TokenRow", "AuditRow", "JobRow", "TwinSessionRow", "DiagnosisRow"]


class Base(DeclarativeBase):
    """Declarative base of the backend's ORM models (tables prefixed ``backend_``)."""


class TokenRow(Base):
    """An API token: only its sha256 hash is stored, with its role and owner name."""

    __tablename__ = "backend_tokens"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(100))
    role: Mapped[str] = mapped_column(String(16))
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True, index=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    revoked_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class AuditRow(Base):
    """One audited action: who (token name), what, on which target, when."""

    __tablename__ = "backend_audit"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    at: Mapped[datetime] = mapped_column(DateTime(timezone=True), index=True)
    actor: Mapped[str] = mapped_column(String(100))
    action: Mapped[str] = mapped_column(String(50), index=True)
    target: Mapped[str] = mapped_column(String(200))
    detail: Mapped[dict] = mapped_column(JSON, default=dict)


class JobRow(Base):
    """A simulation job: its scenario, state, progress, summary and result directory."""

    __tablename__ = "backend_jobs"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    status: Mapped[str] = mapped_column(String(16), index=True)
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    scenario: Mapped[dict] = mapped_column(JSON)
    summary: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    result_dir: Mapped[str | None] = mapped_column(String(500), nullable=True)
    created_by: Mapped[str] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    started_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class TwinSessionRow(Base):
    """A twin session: a simulation job aligned to a telemetry instant, with its fault hypothesis."""

    __tablename__ = "backend_twin_sessions"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    job_id: Mapped[str] = mapped_column(String(32), index=True)
    satellite: Mapped[str] = mapped_column(String(100))
    dictionary: Mapped[str] = mapped_column(String(130))
    scenario: Mapped[str] = mapped_column(String(100))
    align_utc_ns: Mapped[int] = mapped_column(BigInteger)
    duration_s: Mapped[float] = mapped_column(Float)
    faults: Mapped[list] = mapped_column(JSON)
    alternatives: Mapped[dict] = mapped_column(JSON, default=dict)
    created_by: Mapped[str] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))


class DiagnosisRow(Base):
    """A diagnosis of a satellite's telemetry window: who or what started it, its state and the ranked result.

    ``result`` is the JSON of backend.twin.diagnosis (hypotheses best first); ``alarm_id`` is the archive alarm
    whose detection started it (live twins), null for one an operator started."""

    __tablename__ = "backend_diagnoses"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    satellite: Mapped[str] = mapped_column(String(100), index=True)
    dictionary: Mapped[str] = mapped_column(String(130))
    scenario: Mapped[str] = mapped_column(String(100))
    start_utc: Mapped[str] = mapped_column(String(40))
    end_utc: Mapped[str] = mapped_column(String(40))
    status: Mapped[str] = mapped_column(String(16), index=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    result: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    trigger: Mapped[str] = mapped_column(String(16), default="operator")
    alarm_id: Mapped[int | None] = mapped_column(BigInteger, nullable=True, index=True)
    alarm_utc: Mapped[str | None] = mapped_column(String(40), nullable=True)
    created_by: Mapped[str] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), index=True)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
