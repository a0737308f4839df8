"""Programmatic alembic: ``upgrade(url)`` creates or migrates an archive database to the head."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Engine

from telemetry.archive.engine import create_archive_engine

if TYPE_CHECKING:
    from alembic.config import Config

__all__ = ["alembic_config", "upgrade"]

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"


def alembic_config(url: str) -> Config:
    """Alembic configuration pointing at the packaged migrations and the given database URL."""
    from alembic.config import Config  # imported on use: alembic costs ~0.2 s at start-up

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def upgrade(url: str, engine: Engine | None = None) -> None:
    """Create or migrate the archive at ``url`` to the newest schema revision."""
    from alembic import command

    engine_used = engine if engine is not None else create_archive_engine(url)
    config = alembic_config(url)
    with engine_used.begin() as connection:
        config.attributes["connection"] = connection
        command.upgrade(config, "head")
    if engine is None:
        engine_used.dispose()
