"""Every integer and text parameter of the OpenAPI document, called with values past what the databases hold:
a 422 naming the parameter (or a 404 for an id in range that names nothing), never a 5xx, on SQLite and PostgreSQL.

Truths: PostgreSQL's INTEGER is 32 bits (our id columns; SQLite's hold 64), Python's sqlite3 refuses ints past
64 bits (OverflowError), and PostgreSQL's text holds no NUL (U+0000). Before the bounds, ids from 2**31 were a 500 on
PostgreSQL, 2**63 a 500 on SQLite, and a NUL in a name, id, query value or JSON string a 500 on PostgreSQL.
Names the archive stores (satellites, stations, the actors that token names become) are varchar(NAME_MAX) there:
a longer one was a 500 on PostgreSQL, so the API declares NAME_MAX. The parameters are read from the document, not
listed by hand, so a new one is covered when it is declared.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.schemas import DB_ID_MAX, NAME_MAX
from tests.backend.conftest import make_settings

OUT_OF_RANGE = [DB_ID_MAX + 1, 2**63, 10**30, -1, 0]  # past INTEGER on PostgreSQL, past int64, past any int, <= 0
IN_RANGE = [DB_ID_MAX]  # the largest id both databases hold: a lookup that finds nothing (404), not an error
NUL_TEXT = "a\x00b"
PLACEHOLDER = {"integer": "1", "string": "REFSAT"}  # the other parameters: well-formed, naming nothing
SOME_UTC = "2021-04-09T00:00:00Z"


@pytest.fixture
def client(tmp_path: Path, database_url: str) -> Iterator[TestClient]:
    """The app over the database under test, auth off (roles are test_auth's), no live stream."""
    settings = make_settings(tmp_path, database_url, auth_enabled=False)
    with TestClient(create_app(settings), raise_server_exceptions=False) as test_client:
        yield test_client


def _types(schema: dict[str, Any]) -> set[str]:
    """JSON types a parameter takes (through anyOf and array items)."""
    found = {schema["type"]} if "type" in schema else set()
    for option in schema.get("anyOf", []):
        found |= _types(option)
    if schema.get("type") == "array":
        found |= _types(schema["items"])
    return found - {"null", "array"}


def _bounds(schema: dict[str, Any]) -> tuple[int | None, int | None]:
    """(minimum, maximum) an integer parameter declares (through anyOf and array items)."""
    for option in [schema, *schema.get("anyOf", []), schema.get("items", {})]:
        if option.get("type") == "integer":
            return option.get("minimum"), option.get("maximum")
    return None, None


def _operations(client: TestClient, kind: str) -> Iterator[tuple[str, str, dict[str, Any], list[dict[str, Any]]]]:
    """(method, path, parameter, the operation's parameters) for every path or query parameter of type ``kind``."""
    for path, operations in client.get("/openapi.json").json()["paths"].items():
        for method, operation in operations.items():
            parameters = operation.get("parameters", [])
            for parameter in parameters:
                if parameter["in"] in ("path", "query") and _types(parameter["schema"]) == {kind}:
                    yield method.upper(), path, parameter, parameters


def _placeholder(parameter: dict[str, Any]) -> str:
    """A well-formed value of a parameter: its example, else one of its type."""
    schema = parameter["schema"]
    examples = parameter.get("examples") or schema.get("examples")
    if examples:
        return str(next(iter(examples.values()))["value"] if isinstance(examples, dict) else examples[0])
    if any(option.get("format") == "date-time" for option in [schema, *schema.get("anyOf", [])]):
        return SOME_UTC
    return PLACEHOLDER[min(_types(schema))]


def _call(client: TestClient, method: str, path: str, parameter: dict[str, Any], others: list, value: object) -> Any:
    """``method path`` with ``parameter`` set to ``value`` (percent-encoded), the other path and required query
    parameters set to well-formed values."""
    name = parameter["name"]
    fill = {p["name"]: _placeholder(p) for p in others if p["in"] == "path"}
    query: dict[str, object] = {p["name"]: _placeholder(p) for p in others if p["in"] == "query" and p["required"]}
    if parameter["in"] == "path":
        fill[name] = str(value).replace("\x00", "%00")
    else:
        query[name] = value
    url = re.sub(r"\{(\w+)\}", lambda m: fill[m.group(1)], path)
    return client.request(method, url, params=query, json={"duration_s": 60.0})  # shelve's body; others ignore it


def test_integer_parameters_past_their_bounds_are_422_naming_them(client: TestClient) -> None:
    seen = 0
    for method, path, parameter, others in _operations(client, "integer"):
        low, high = _bounds(parameter["schema"])
        assert low is not None, f"{method} {path} {parameter['name']}: no minimum in the document"
        for value in OUT_OF_RANGE + IN_RANGE:
            answer = _call(client, method, path, parameter, others, value)
            where = f"{method} {path} {parameter['name']}={value}"
            assert answer.status_code < 500, f"{where}: {answer.text}"
            if value < low or (high is not None and value > high):
                assert answer.status_code == 422, f"{where}: {answer.text}"
                assert answer.json()["field"] == parameter["name"], f"{where}: {answer.text}"
        seen += 1
    assert seen >= 15  # the ids (tokens, passes, alarms, diagnoses' alarm_id), limits, APIDs, members, points


def test_every_id_in_the_document_fits_a_32_bit_integer_column(client: TestClient) -> None:
    ids = [
        (method, path, parameter["name"], _bounds(parameter["schema"]))
        for method, path, parameter, _ in _operations(client, "integer")
        if parameter["name"].endswith("_id")
    ]
    assert len(ids) >= 7
    assert all(bounds == (1, DB_ID_MAX) for *_, bounds in ids), ids


def test_text_parameters_with_a_nul_are_422_naming_them(client: TestClient) -> None:
    seen = 0
    for method, path, parameter, others in _operations(client, "string"):
        answer = _call(client, method, path, parameter, others, NUL_TEXT)
        where = f"{method} {path} {parameter['name']}"
        assert answer.status_code == 422, f"{where}: {answer.text}"
        assert answer.json()["field"] == ("path" if parameter["in"] == "path" else parameter["name"]), answer.text
        assert "NUL" in answer.json()["message"]
        seen += 1
    assert seen >= 30


@pytest.mark.parametrize(
    ("url", "body", "field"),
    [
        ("/api/v1/tokens", {"name": NUL_TEXT, "role": "viewer"}, "name"),
        ("/api/v1/ground-stations", {"name": NUL_TEXT, "lat_deg": 64.86, "lon_deg": -147.85}, "name"),
        ("/api/v1/simulations", {"kind": "rigid-spin", "duration_s": 1.0, "tags": ["ok", NUL_TEXT]}, "tags.1"),
        ("/api/v1/simulations", {"library": "somov-ge4-scan", "set": [], NUL_TEXT: 1}, "body"),
    ],
)
def test_json_strings_with_a_nul_are_422_naming_their_place(
    client: TestClient, url: str, body: dict[str, Any], field: str
) -> None:
    answer = client.post(url, json=body)
    assert answer.status_code == 422 and answer.json()["field"] == field, answer.text


def test_every_satellite_and_station_name_in_the_document_fits_the_archive_s_name_column(client: TestClient) -> None:
    names = [
        (method, path, parameter)
        for method, path, parameter, _ in _operations(client, "string")
        if parameter["name"] in ("satellite", "station")
        or (parameter["name"] == "name" and path.startswith(("/api/v1/satellites", "/api/v1/ground-stations")))
    ]
    assert len(names) >= 20
    for method, path, parameter in names:
        schema = parameter["schema"]
        declared = next(
            (option["maxLength"] for option in [schema, *schema.get("anyOf", [])] if "maxLength" in option), None
        )
        assert declared == NAME_MAX, (method, path, parameter)


def test_names_up_to_the_column_width_are_stored_and_longer_ones_are_422(tmp_path: Path, database_url: str) -> None:
    """Names of NAME_MAX + 1 to 100 characters were a 500 on PostgreSQL (varchar(64)), and so was every upload by a
    token named so (its name is the upload's actor); the API declared 100."""
    with TestClient(create_app(make_settings(tmp_path, database_url))) as app_client:
        admin = {"Authorization": f"Bearer {app_client.app.state.services.auth.issue('admin', Role.admin)[1]}"}
        for width, status in ((NAME_MAX, 201), (NAME_MAX + 1, 422)):
            station = {"name": "S" * width, "lat_deg": 64.86, "lon_deg": -147.85}
            for url, body in (("/api/v1/satellites", {"name": "N" * width}), ("/api/v1/ground-stations", station)):
                answer = app_client.post(url, json=body, headers=admin)
                assert answer.status_code == status and (status == 201 or answer.json()["field"] == "name"), answer.text
            token = app_client.post("/api/v1/tokens", json={"name": "T" * width, "role": "operator"}, headers=admin)
            assert token.status_code == status, token.text
            if status == 201:
                operator = {"Authorization": f"Bearer {token.json()['token']}"}
        csv = f"t_utc_ns,ADCFAQ4\n{(int(time.time()) - 3600) * 10**9},0.5\n".encode()
        upload = app_client.post("/api/v1/telemetry/uploads?format=csv", content=csv, headers=operator)
        assert upload.status_code == 200 and upload.json()["archive"]["samples_accepted"] == 1, upload.text


def test_a_dictionary_parameter_name_with_a_nul_is_422_before_anything_is_archived(client: TestClient) -> None:
    """It was stored (dictionaries are files), then every upload decoded with it was a 500 on PostgreSQL."""
    yaml = (
        b'packets:\n  - {name: P, apid: 5, time_code: CUC-4-2, parameters: [{name: "a\\0b", type: uint, bits: 16}]}\n'
    )
    answer = client.post("/api/v1/dictionaries/nul.yaml", content=yaml)
    assert answer.status_code == 422 and answer.json()["field"] == "a\\x00b.name", answer.text
