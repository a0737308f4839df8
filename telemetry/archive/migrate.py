"""``upgrade(url)`` creates or migrates an archive database to the head revision.

A database without the archive's tables and without a revision gets the head schema directly (the models'
``create_all``, stamped at head in the same transaction: ~10 statements instead of the alembic chain, and no
alembic import); a database at head is left as it is; any other runs the alembic migrations. The migrations are
the truth for existing databases: ``tests/telemetry/test_archive_schema.py`` checks that the created schema is
the migrated one, catalog by catalog, on SQLite and PostgreSQL, and that ``HEAD_REVISION`` is alembic's head.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Column, Connection, Engine, MetaData, PrimaryKeyConstraint, String, Table, inspect, text

from telemetry.archive.engine import create_archive_engine
from telemetry.archive.models import Base

if TYPE_CHECKING:
    from alembic.config import Config

__all__ = ["alembic_config", "upgrade", "HEAD_REVISION"]

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
HEAD_REVISION = "0003"  # the newest revision in migrations/versions (a test checks it against alembic's head)
# alembic's own version table (alembic.ddl.impl.DefaultImpl.version_table_impl), made here without importing alembic
VERSION_TABLE = Table(
    "alembic_version",
    MetaData(),
    Column("version_num", String(32), nullable=False),
    PrimaryKeyConstraint("version_num", name="alembic_version_pkc"),
)
# PostgreSQL: one upgrade at a time per schema (SQLite: the writer engine's BEGIN IMMEDIATE takes the write lock)
_PG_LOCK = text("SELECT pg_advisory_xact_lock(hashtext('acs_twin.archive.upgrade:' || current_schema()))")


def alembic_config(url: str) -> Config:
    """Alembic configuration pointing at the packaged migrations and the given database URL."""
    from alembic.config import Config  # imported on use: alembic costs ~0.2 s at start-up

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def upgrade(url: str, engine: Engine | None = None) -> None:
    """Create or migrate the archive at ``url`` to the head revision, in one transaction that holds the database's
    write lock (SQLite) or the schema's upgrade lock (PostgreSQL): processes opening a new database at once
    create it once, the others find it at head."""
    engine_used = engine if engine is not None else create_archive_engine(url)
    try:
        with engine_used.begin() as connection:
            if connection.dialect.name == "postgresql":
                connection.execute(_PG_LOCK)
            tables = set(inspect(connection).get_table_names())
            revision = _revision(connection) if VERSION_TABLE.name in tables else None
            if revision == HEAD_REVISION:
                return
            if revision is None and not tables & set(Base.metadata.tables):
                Base.metadata.create_all(connection, checkfirst=False)
                VERSION_TABLE.create(connection, checkfirst=True)
                connection.execute(VERSION_TABLE.insert().values(version_num=HEAD_REVISION))
                return
            _migrate(url, connection)
    finally:
        if engine is None:
            engine_used.dispose()


def _revision(connection: Connection) -> str | None:
    """The database's alembic revision (None: none stamped)."""
    rows = connection.execute(VERSION_TABLE.select()).scalars().all()
    return str(rows[0]) if len(rows) == 1 else None


def _migrate(url: str, connection: Connection) -> None:
    """Run the alembic migrations from the database's revision to the head on ``connection`` (its transaction)."""
    from alembic import command

    config = alembic_config(url)
    config.attributes["connection"] = connection
    command.upgrade(config, "head")
