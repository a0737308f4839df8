"""Alembic environment of the telemetry archive, driven programmatically by ``migrate.upgrade``."""

from __future__ import annotations

from alembic import context

from telemetry.archive.engine import create_archive_engine
from telemetry.archive.models import Base

config = context.config
target_metadata = Base.metadata


def run_migrations_online() -> None:
    """Run migrations on the connection handed in by ``migrate.upgrade`` (or the configured URL)."""
    connection = config.attributes.get("connection")
    if connection is not None:
        context.configure(connection=connection, target_metadata=target_metadata, render_as_batch=True)
        with context.begin_transaction():
            context.run_migrations()
        return
    engine = create_archive_engine(config.get_main_option("sqlalchemy.url") or "")
    with engine.connect() as connection:
        context.configure(connection=connection, target_metadata=target_metadata, render_as_batch=True)
        with context.begin_transaction():
            context.run_migrations()
    engine.dispose()


if context.is_offline_mode():
    raise RuntimeError("the archive migrations run online only: call telemetry.archive.upgrade(url)")
run_migrations_online()
