"""The backend's own tables (tokens, audit, jobs): engine, session factory and schema creation.

These tables live in their own SQLAlchemy metadata, created with ``create_all``; they carry a
``backend_`` prefix and never touch telemetry's alembic version table, so both can share one
database (SQLite or PostgreSQL).
"""

from __future__ import annotations

import logging
import threading
import time

from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.orm import Session, sessionmaker
from sqlalchemy.pool import StaticPool

from backend.core.models import Base

__all__ = ["DatabaseWatch", "make_engine", "make_session_factory", "create_schema"]

log = logging.getLogger(__name__)

WATCH_PERIOD_S = 1.0  # the database watch makes a round trip this often


def _sqlite_pragmas(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.execute("PRAGMA busy_timeout=5000")
    cursor.close()


def make_engine(url: str) -> Engine:
    """SQLAlchemy engine for ``url``; SQLite gets WAL and a busy timeout for concurrent readers."""
    if url.startswith("sqlite"):
        kwargs: dict = {"connect_args": {"check_same_thread": False}}
        if url in ("sqlite://", "sqlite:///:memory:"):
            kwargs["poolclass"] = StaticPool
        engine = create_engine(url, **kwargs)
        event.listen(engine, "connect", _sqlite_pragmas)
        return engine
    return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)


def make_session_factory(engine: Engine) -> sessionmaker[Session]:
    """Session factory bound to ``engine`` (objects stay readable after commit)."""
    return sessionmaker(engine, expire_on_commit=False)


def create_schema(engine: Engine) -> None:
    """Create the backend's tables if missing (idempotent); importing models registered them on Base."""
    Base.metadata.create_all(engine)


class DatabaseWatch:
    """A round trip to the database (``SELECT 1``) every WATCH_PERIOD_S from a daemon thread; ``last_answer``
    says how long ago the last one succeeded. GET /health reads it instead of asking the database itself, so that
    health is answered on the event loop alone: no worker thread, no connection pool, no database to wait for."""

    def __init__(self, engine: Engine, period_s: float = WATCH_PERIOD_S) -> None:
        self._engine, self._period_s = engine, period_s
        self._answered: float | None = None  # time.monotonic() of the last successful round trip
        self._error, self._failing = "no round trip yet", False  # the last failure's message, failing now?
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """One round trip now (health is right from the start), then the watch thread."""
        self._round_trip()
        self._stop.clear()
        self._thread = threading.Thread(target=self._watch, name="database-watch", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the watch thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None

    def last_answer(self) -> tuple[float | None, str]:
        """(seconds since the last successful round trip or None if none yet, the last failure's message)."""
        answered = self._answered
        return (None if answered is None else time.monotonic() - answered), self._error

    def _watch(self) -> None:
        while not self._stop.wait(self._period_s):
            self._round_trip()

    def _round_trip(self) -> None:
        try:
            with self._engine.connect() as connection:
                connection.execute(text("SELECT 1"))
        except Exception as exc:  # a database hiccup must not end the watch: health shows the age growing
            if not self._failing:  # logged once per outage, not every period
                log.warning("database watch: round trip failed", exc_info=True)
            self._error, self._failing = f"{type(exc).__name__}: {exc}"[:300], True
            return
        self._answered, self._failing = time.monotonic(), False
