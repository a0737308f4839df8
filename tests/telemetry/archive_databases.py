"""Archive fixtures shared by the archive tests: every test runs on SQLite and on PostgreSQL.

PostgreSQL tests get a fresh schema (unique name, dropped afterwards) so parallel runs and
repeated runs never see each other's rows.
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

from telemetry.archive import Archive


def postgres_schema_url(base_url: str, schema: str) -> str:
    """``base_url`` with every connection's search_path set to ``schema``."""
    url = make_url(base_url).update_query_dict({"options": f"-csearch_path={schema}"})
    return url.render_as_string(hide_password=False)


@contextmanager
def new_postgres_schema(base_url: str) -> Iterator[str]:
    """URL of a new, empty PostgreSQL schema on ``base_url``'s database (dropped afterwards)."""
    schema = f"acs_twin_test_{uuid.uuid4().hex[:12]}"
    admin = create_engine(base_url)
    with admin.begin() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    try:
        yield postgres_schema_url(base_url, schema)
    finally:
        with admin.begin() as conn:
            conn.execute(text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def archive_url(request: pytest.FixtureRequest, tmp_path) -> Iterator[str]:
    """URL of an empty archive database: a SQLite file, or a fresh PostgreSQL schema."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'archive.sqlite'}"
        return
    with new_postgres_schema(request.getfixturevalue("postgres_url")) as url:
        yield url


@pytest.fixture
def archive(archive_url: str) -> Iterator[Archive]:
    """An archive migrated to the newest schema on the database under test."""
    store = Archive(archive_url)
    try:
        yield store
    finally:
        store.close()
