"""The app factory, settings and the JSON error format."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from tests.backend.conftest import bearer


def test_health_answers_without_token_and_names_the_database(client: TestClient, database_url: str) -> None:
    body = client.get("/api/v1/health").json()
    assert body["status"] == "ok"
    assert body["database"] == ("sqlite" if database_url.startswith("sqlite") else "postgresql")
    assert body["auth_enabled"] is True


def test_openapi_served_at_fixed_path_with_v1_routes(client: TestClient) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    for path in ("/api/v1/health", "/api/v1/simulations", "/api/v1/simulations/{job_id}"):
        assert path in paths


def test_validation_error_is_json_naming_the_field(client: TestClient, tokens: dict[str, str]) -> None:
    answer = client.post("/api/v1/tokens", json={"name": "x", "role": "pilot"}, headers=bearer(tokens["admin"]))
    assert answer.status_code == 422
    assert answer.json()["field"] == "role"
    assert answer.json()["status"] == 422


def test_unknown_route_is_json_404(client: TestClient) -> None:
    answer = client.get("/api/v1/nowhere")
    assert answer.status_code == 404 and answer.json()["message"] == "Not Found"


def test_settings_read_from_acs_twin_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("ACS_TWIN_PORT", "9123")
    monkeypatch.setenv("ACS_TWIN_AUTH_ENABLED", "false")
    monkeypatch.setenv("ACS_TWIN_DATA_DIR", str(tmp_path))
    settings = Settings()
    assert (settings.port, settings.auth_enabled, settings.host) == (9123, False, "127.0.0.1")
    assert settings.resolved_database_url() == f"sqlite:///{(tmp_path / 'acs-twin.sqlite').resolve()}"


def test_bad_setting_names_the_field(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="port"):
        Settings(port=70_000, data_dir=tmp_path)


def test_factory_creates_nothing_until_called_and_auth_off_acts_as_admin(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path / "d", auth_enabled=False, telemetry_port=0, live_enabled=False)
    assert not settings.data_dir.exists()
    with TestClient(create_app(settings)) as client:
        assert (tmp_path / "d" / "acs-twin.sqlite").exists()
        assert client.get("/api/v1/tokens").status_code == 200


def test_dashboard_is_served_with_the_api_prefix_and_monitor_urls(client: TestClient) -> None:
    page = client.get("/dashboard/")
    assert page.status_code == 200 and "<html" in page.text.lower()
    config = client.get("/dashboard/config.json").json()
    assert config["api_base"] == "/api/v1"
    assert set(config["monitors"]) == {"actual", "simulated", "overlay"}
