"""Auth: the matrix of every route × no token / viewer / operator / admin, hashing at rest, audit."""

from __future__ import annotations

import hashlib

import sqlalchemy as sa
from fastapi.testclient import TestClient

from tests.backend.conftest import bearer

PUBLIC_PATHS = {"/api/v1/health"}
ADMIN_PREFIXES = ("/api/v1/tokens", "/api/v1/audit")


def _routes(client: TestClient) -> list[tuple[str, str]]:
    """Every (method, path) the OpenAPI document declares, except the public ones."""
    paths = client.get("/openapi.json").json()["paths"]
    return [(method.upper(), path) for path, item in paths.items() if path not in PUBLIC_PATHS for method in item]


def _concrete(path: str) -> str:
    return path.replace("{token_id}", "999999").replace("{", "").replace("}", "")


def _expected_denial(method: str, path: str, role: str) -> int | None:
    needed = "admin" if path.startswith(ADMIN_PREFIXES) else ("viewer" if method == "GET" else "operator")
    order = ["viewer", "operator", "admin"]
    return 403 if order.index(role) < order.index(needed) else None


def test_every_route_by_every_role(client: TestClient, tokens: dict[str, str]) -> None:
    routes = _routes(client)
    assert len(routes) >= 8, "the matrix must cover the API"
    for method, path in routes:
        url = _concrete(path)
        assert client.request(method, url).status_code == 401, (method, path, "no token")
        assert client.request(method, url, headers=bearer("acs_forged")).status_code == 401
        for role, token in tokens.items():
            status = client.request(method, url, headers=bearer(token)).status_code
            expected = _expected_denial(method, path, role)
            if expected is None:
                assert status not in (401, 403), (method, path, role, status)
            else:
                assert status == expected, (method, path, role, status)


def test_tokens_are_stored_only_as_sha256(client: TestClient, tokens: dict[str, str]) -> None:
    with client.app.state.services.engine.connect() as connection:
        rows = connection.execute(sa.text("SELECT token_sha256 FROM backend_tokens")).scalars().all()
    digests = {hashlib.sha256(t.encode()).hexdigest() for t in tokens.values()}
    assert digests <= set(rows)
    assert not any(t in rows for t in tokens.values())


def test_admin_issues_and_revokes_a_token_and_both_are_audited(client: TestClient, tokens: dict[str, str]) -> None:
    admin = bearer(tokens["admin"])
    issued = client.post("/api/v1/tokens", json={"name": "console", "role": "viewer"}, headers=admin)
    assert issued.status_code == 201
    new = issued.json()
    assert client.get("/api/v1/simulations", headers=bearer(new["token"])).status_code == 200
    listed = client.get("/api/v1/tokens", headers=admin).json()
    assert all("token" not in row and "token_sha256" not in row for row in listed)
    assert client.delete(f"/api/v1/tokens/{new['id']}", headers=admin).status_code == 200
    assert client.get("/api/v1/simulations", headers=bearer(new["token"])).status_code == 401
    actions = [e["action"] for e in client.get("/api/v1/audit", headers=admin).json()]
    assert actions[:2] == ["token.revoke", "token.create"]


def test_revoking_unknown_token_is_404_naming_it(client: TestClient, tokens: dict[str, str]) -> None:
    answer = client.delete("/api/v1/tokens/424242", headers=bearer(tokens["admin"]))
    assert answer.status_code == 404 and answer.json()["field"] == "token_id"
