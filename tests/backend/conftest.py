"""Fixtures of the API tests: an app over real SQLite or real PostgreSQL, and one token per role."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.core.settings import Settings


def postgres_schema_url(base_url: str) -> Iterator[str]:
    """A fresh PostgreSQL schema for one test (parallel test files never share tables)."""
    schema = f"bk_{uuid.uuid4().hex[:12]}"
    engine = sa.create_engine(base_url)
    with engine.begin() as connection:
        connection.execute(sa.text(f"CREATE SCHEMA {schema}"))
    sep = "&" if "?" in base_url else "?"
    try:
        yield f"{base_url}{sep}options=-csearch_path%3D{schema}"
    finally:
        with engine.begin() as connection:
            connection.execute(sa.text(f"DROP SCHEMA {schema} CASCADE"))
        engine.dispose()


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """Real SQLite file under tmp_path, or a throw-away schema in the real PostgreSQL server."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'api.sqlite'}"
        return
    yield from postgres_schema_url(request.getfixturevalue("postgres_url"))


def make_settings(tmp_path: Path, database_url: str, **overrides: object) -> Settings:
    """Settings for a test app: data under tmp_path, auth on, small limits."""
    values: dict[str, object] = {
        "data_dir": tmp_path / "data",
        "database_url": database_url,
        "job_workers": 1,
        "job_queue_size": 2,
        "telemetry_port": 0,
        "live_enabled": False,
    }
    values.update(overrides)
    return Settings(**values)


@pytest.fixture
def settings(tmp_path: Path, database_url: str) -> Settings:
    """Default test settings over the parametrised database."""
    return make_settings(tmp_path, database_url)


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    """A started app (lifespan run) behind a test client."""
    with TestClient(create_app(settings)) as test_client:
        yield test_client


@pytest.fixture
def tokens(client: TestClient) -> dict[str, str]:
    """One plain token per role, issued through the app's authenticator."""
    auth = client.app.state.services.auth
    return {role.name: auth.issue(f"test-{role.name}", role)[1] for role in Role}


def bearer(token: str) -> dict[str, str]:
    """Authorization header for a token."""
    return {"Authorization": f"Bearer {token}"}
