"""The app factory, settings and the JSON error format."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, get_args, get_origin

import pytest
from fastapi import FastAPI
from fastapi.responses import FileResponse, StreamingResponse
from fastapi.routing import APIRoute, iter_route_contexts
from fastapi.testclient import TestClient
from pydantic import BaseModel

from backend.app import create_app
from backend.core.database import DatabaseWatch, make_engine
from backend.core.settings import Settings
from tests.backend.conftest import bearer


def test_health_answers_without_token_and_names_the_database(client: TestClient, database_url: str) -> None:
    body = client.get("/api/v1/health").json()
    assert body["status"] == "ok"
    assert body["database"] == ("sqlite" if database_url.startswith("sqlite") else "postgresql")
    assert body["auth_enabled"] is True


def test_health_is_503_naming_the_database_when_it_does_not_answer(client: TestClient, tmp_path: Path) -> None:
    unreachable = DatabaseWatch(make_engine(f"sqlite:///{tmp_path / 'no such directory' / 'db.sqlite'}"))
    unreachable.start()  # its first round trip fails: the directory does not exist
    unreachable.stop()
    services = client.app.state.services  # type: ignore[attr-defined]
    services.database_watch, watch = unreachable, services.database_watch
    try:
        answer = client.get("/api/v1/health")
    finally:
        services.database_watch = watch
    assert answer.status_code == 503
    assert answer.json()["field"] == "database"
    assert "unable to open database file" in answer.json()["message"]
    assert client.get("/api/v1/health").status_code == 200  # the server's own watch answers


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


def _api_routes(app: FastAPI) -> list[tuple[str, APIRoute]]:
    """(full path, route) of every documented HTTP route, routers included with their prefix."""
    found = [(c.path or "", c.original_route) for c in iter_route_contexts(app.routes)]
    return [(path, r) for path, r in found if isinstance(r, APIRoute) and r.include_in_schema]


def _named(model: Any) -> bool:
    """A schema with a name in the OpenAPI components: a pydantic model or dataclass, or a list of one."""
    if get_origin(model) is list:
        (model,) = get_args(model)
    return isinstance(model, type) and (issubclass(model, BaseModel) or dataclasses.is_dataclass(model))


def test_every_api_route_declares_a_named_response_model_or_its_file_media_types(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path, telemetry_port=0, live_enabled=False))
    routes = _api_routes(app)
    assert {"/api/v1/satellites/{name}/twin", "/api/v1/simulations/{job_id}/files/{name}"} <= {p for p, _ in routes}
    document = app.openapi()["paths"]
    unnamed = []
    for path, route in routes:
        if route.response_model is None:  # a file download: its media types documented instead
            media = route.responses.get(200, {}).get("content", {})
            if not (issubclass(route.response_class, (FileResponse, StreamingResponse)) and media):
                unnamed.append(f"{sorted(route.methods)} {path}: no response_model, no documented file media types")
            continue
        if not _named(route.response_model):
            unnamed.append(f"{sorted(route.methods)} {path}: response_model {route.response_model} has no name")
        for method in route.methods:
            success = document[path][method.lower()]["responses"][str(route.status_code or 200)]
            schema = success["content"]["application/json"]["schema"]
            if "$ref" not in schema.get("items", schema):
                unnamed.append(f"{method} {path}: OpenAPI answer schema {schema} is not a named component")
    assert unnamed == []
