"""Programmatic alembic: ``upgrade(url)`` creates or migrates an archive database to the head."""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import Engine

from telemetry.archive.engine import create_archive_engine

__all__ = ["alembic_config", "upgrade"]

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"


def alembic_config(url: str) -> Config:
    """Alembic configuration pointing at the packaged migrations and the given database URL."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def upgrade(url: str, engine: Engine | None = None) -> None:
    """Create or migrate the archive at ``url`` to the newest schema revision."""
    engine_used = engine if engine is not None else create_archive_engine(url)
    config = alembic_config(url)
    with engine_used.begin() as connection:
        config.attributes["connection"] = connection
        command.upgrade(config, "head")
    if engine is None:
        engine_used.dispose()
