"""Routes the operator console reads: constants shared with the server (not copied into the page), the
caller's role, the dictionary entry of each archived parameter; / opens the dashboard, /docs needs no CDN;
a wheel isolated by FDIR raises a critical (red) alarm from the reference dictionary's limits."""

from __future__ import annotations

import time
from pathlib import Path

from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.twin.live import STALE_S
from backend.twin.twin_sessions import GPS_MARGIN_S
from telemetry.emulator import emulate
from tests.backend.conftest import bearer, make_settings

REFSAT = "REFSAT-CONSOLE"


def _upload_fault_flag(client: TestClient, token: str, values: list[float]) -> dict:
    t0_ns = time.time_ns() - 60 * 10**9
    rows = "\n".join(f"{t0_ns + i * 10**9},{v},3" for i, v in enumerate(values))
    answer = client.post(
        "/api/v1/telemetry/uploads",
        headers=bearer(token),
        content=f"t_utc_ns,fault_wheel_2,mode\n{rows}\n",
        params={"satellite": REFSAT, "dictionary": "reference_satellite.yaml", "format": "csv"},
    )
    assert answer.status_code == 200, answer.text
    return answer.json()


def test_constants_are_the_servers_own(client: TestClient, tokens: dict[str, str]) -> None:
    body = client.get("/api/v1/constants", headers=bearer(tokens["viewer"])).json()
    assert body["gps_margin_s"] == GPS_MARGIN_S and body["stale_after_s"] == STALE_S
    assert body["severities"] == {"yellow": "warning", "red": "critical"} and body["shelve_max_s"] == 30 * 86_400
    assert client.get("/api/v1/constants").status_code == 401


def test_the_stale_threshold_is_configured_once_for_the_console_and_the_twins(
    tmp_path: Path, database_url: str
) -> None:
    """ACS_TWIN_STALE_AFTER_S: the dashboard's constant and every twin state say the configured threshold, and a
    twin whose telemetry stopped longer ago than it is stale (a shorter gap is not)."""
    settings = make_settings(tmp_path, database_url, stale_after_s=2.5)
    with TestClient(create_app(settings)) as client:
        viewer = client.app.state.services.auth.issue("viewer", Role.viewer)[1]
        assert client.get("/api/v1/constants", headers=bearer(viewer)).json()["stale_after_s"] == 2.5
        operator = client.app.state.services.auth.issue("operator", Role.operator)[1]
        data = emulate("somov-ge4-scan", [], 20.0, "2026-03-20T00:00:00Z", truth_seed=None)[2].data
        answer = client.post(
            "/api/v1/telemetry/uploads?satellite=REFSAT-STALE&dictionary=reference_satellite.yaml",
            content=data,
            headers=bearer(operator),
        )
        assert answer.status_code == 200
        twins = client.app.state.services.twins
        twins.drain()
        fresh = twins.state("REFSAT-STALE")
        assert fresh is not None and fresh["stale_after_s"] == 2.5
        while (state := twins.state("REFSAT-STALE")) is not None and state["last_packet_age_s"] < 2.5:
            assert not state["stale"]
            time.sleep(0.1)
        assert state is not None and state["stale"]


def test_whoami_names_the_role(client: TestClient, tokens: dict[str, str]) -> None:
    for role in ("viewer", "operator", "admin"):
        assert client.get("/api/v1/whoami", headers=bearer(tokens[role])).json()["role"] == role


def test_parameter_info_comes_from_the_dictionary_and_a_wheel_failure_is_critical(
    client: TestClient, tokens: dict[str, str]
) -> None:
    report = _upload_fault_flag(client, tokens["operator"], [0.0, 1.0, 1.0])
    assert report["archive"]["alarm_events"] == 1
    info = client.get("/api/v1/parameters/info", params={"satellite": REFSAT}, headers=bearer(tokens["viewer"])).json()
    assert set(info) == {"fault_wheel_2", "mode"}
    assert info["mode"]["enumeration"]["3"] == "THREE_AXIS" and info["mode"]["description"].startswith(
        "onboard ACS mode"
    )
    assert info["fault_wheel_2"]["limits"] == {"yellow_low": None, "yellow_high": 0.5, "red_low": None, "red_high": 0.5}
    (alarm,) = client.get("/api/v1/alarms", params={"satellite": REFSAT}, headers=bearer(tokens["viewer"])).json()
    assert (alarm["parameter"], alarm["severity"], alarm["state"]) == ("fault_wheel_2", "red", "active")


def test_parameter_info_of_an_unknown_satellite_names_the_field(client: TestClient, tokens: dict[str, str]) -> None:
    answer = client.get("/api/v1/parameters/info", params={"satellite": "NOPE"}, headers=bearer(tokens["viewer"]))
    assert answer.status_code == 422 and answer.json()["field"] == "satellite"


def test_root_opens_the_dashboard_and_docs_use_the_vendored_swagger_ui(client: TestClient) -> None:
    root = client.get("/", follow_redirects=False)
    assert root.status_code in (302, 307) and root.headers["location"] == "/dashboard/"
    docs = client.get("/docs").text
    assert "/dashboard/vendor/swagger-ui/swagger-ui-bundle.js" in docs and "cdn" not in docs.lower()
    assert client.get("/dashboard/vendor/swagger-ui/swagger-ui-bundle.js").status_code == 200
