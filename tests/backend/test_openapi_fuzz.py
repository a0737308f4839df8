"""Schemathesis against the OpenAPI document: no 5xx, statuses, content types and bodies as declared.

Auth is off here (the auth matrix in test_auth.py covers tokens), so every operation is reachable.
A 503 is accepted only with its documented meaning: a telemetry component not in this build.
Three passes over every operation: schema-valid requests (positive), schema-violating requests
(negative: only "no 5xx" is checked, the answer to nonsense is a 4xx of our choosing), and positive
requests on real state: the archive holds the NOAA-20 diary, a TLE, a station, predicted passes and a
finished simulation, and path parameters name those rows, so handlers run past their 404s.
On SQLite and on PostgreSQL: out-of-range ids, NUL characters and over-long names were 500s on PostgreSQL only.
"""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from backend.app import create_app
from backend.core.settings import Settings

pytestmark = pytest.mark.slow  # hundreds of generated requests: scheduled first (tests/conftest.py)

EXAMPLES_PER_OPERATION = 5  # x 3 passes: the whole run stays well under 2 minutes on 2 cores
CALL_TIMEOUT_S = 120.0  # schemathesis' default 10 s read timeout failed POST /simulations at load 18 on 2 cores
CHECKS = [status_code_conformance, content_type_conformance, response_schema_conformance]
NOT_BUILT = "is not available in this build"
DIARY = "real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
TLE_FILE = "tle/real_sso_smallsats.tle"
STATION = {"name": "Fairbanks", "lat_deg": 64.86, "lon_deg": -147.85, "alt_m": 200.0, "min_elevation_deg": 5.0}
DAY = {"start": "2021-04-09T00:00:00Z", "end": "2021-04-10T00:00:00Z"}


def _seed(client: TestClient, shared_data: Path) -> dict[str, dict[str, Any]]:
    """Real rows to aim at: path template -> path parameters naming existing things."""
    api = "/api/v1"
    lines = (shared_data / TLE_FILE).read_text().splitlines()
    at = lines.index("NOAA 20 (JPSS-1)")
    client.post(f"{api}/telemetry/uploads", content=(shared_data / DIARY).read_bytes())
    client.post(f"{api}/ground-stations", json=STATION)
    client.post(f"{api}/satellites/NOAA-20/tles", content=f"{lines[at + 1]}\n{lines[at + 2]}\n")
    passes = client.post(f"{api}/satellites/NOAA-20/passes/predict", params={"station": "Fairbanks", **DAY}).json()
    job = client.post(f"{api}/simulations", json={"kind": "rigid-spin", "duration_s": 2.0}).json()["id"]
    deadline = time.monotonic() + 120
    while client.get(f"{api}/simulations/{job}").json()["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, "the seed simulation did not finish"
        time.sleep(0.2)
    series = client.get(f"{api}/simulations/{job}/files").json()
    satellite, pass_id = {"name": "NOAA-20"}, {"pass_id": passes[0]["id"]}
    return {
        f"{api}/parameters/{{name}}/samples": {"name": "ADCFAQ4"},
        f"{api}/satellites/{{name}}/tles": satellite,
        f"{api}/satellites/{{name}}/tle": satellite,
        f"{api}/satellites/{{name}}/passes/reception": satellite,
        f"{api}/satellites/{{name}}/passes/predict": satellite,
        f"{api}/satellites/{{name}}/twin": satellite,
        f"{api}/ground-stations/{{name}}": {"name": "Fairbanks"},
        f"{api}/passes/{{pass_id}}": pass_id,
        f"{api}/passes/{{pass_id}}/summary": pass_id,
        f"{api}/simulations/{{job_id}}": {"job_id": job},
        f"{api}/simulations/{{job_id}}/files": {"job_id": job},
        f"{api}/simulations/{{job_id}}/files/{{name}}": {"job_id": job, "name": series[0]["name"]},
        f"{api}/simulations/{{job_id}}/series/{{name}}": {"job_id": job, "name": "omega_b_rad_s"},
        f"{api}/simulations/{{job_id}}/export": {"job_id": job},
    }


def test_api_matches_its_openapi_document(
    tmp_path: Path, shared_data: Path, dask_scheduler: str, database_url: str
) -> None:
    app = create_app(
        Settings(
            data_dir=tmp_path,
            database_url=database_url,  # SQLite and PostgreSQL: some inputs were a 500 on one of them only
            dask_scheduler=dask_scheduler,  # the generated jobs fly on the shared cluster (tests/conftest.py)
            auth_enabled=False,
            job_queue_size=2,
            max_upload_mb=1.0,
            telemetry_port=0,
            live_enabled=False,
        )
    )
    tally: Counter[str] = Counter()
    server_errors: list[str] = []

    def check(case: schemathesis.Case, conformance: bool) -> None:
        response = case.call(timeout=CALL_TIMEOUT_S)
        tally["requests"] += 1
        if response.status_code == 503:
            assert NOT_BUILT in response.json()["message"], response.text
            return
        if response.status_code >= 500:
            server_errors.append(f"{case.method} {case.formatted_path} {case.query}: {response.text[:300]}")
            return
        if conformance:
            case.validate_response(response, checks=CHECKS)

    def checker(conformance: bool) -> Any:
        def check_case(case: schemathesis.Case) -> None:
            check(case, conformance)

        return check_case

    # One lifespan: schemathesis starts the app's on loading the schema and ends it with the test (its pytest
    # plugin); the seed's client only sends requests. A second one (``with TestClient(app)``) ran every service
    # twice on one set of objects: the first shutdown waited out the live twins' 30 s join on a writer thread
    # that the other start had orphaned.
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    client = TestClient(app)
    app.state.services.settings.max_upload_mb = 100.0  # the diary (1.4 MB) for the seed only
    known = _seed(client, shared_data)
    app.state.services.settings.max_upload_mb = 1.0
    operations = [result.ok() for result in schema.get_all_operations()]
    assert len(operations) >= 30
    started = time.monotonic()
    passes = [(GenerationMode.POSITIVE, False), (GenerationMode.NEGATIVE, False), (GenerationMode.POSITIVE, True)]
    for mode, on_state in passes:
        for operation in operations:
            fixed = known.get(operation.path) if on_state else None
            if on_state and fixed is None:
                continue
            strategy = operation.as_strategy(generation_mode=mode, path_parameters=fixed)
            run = settings(
                max_examples=EXAMPLES_PER_OPERATION,
                deadline=None,
                database=None,
                suppress_health_check=list(HealthCheck),
            )(given(case=strategy)(checker(conformance=mode is GenerationMode.POSITIVE)))
            try:
                run()
            except Unsatisfiable:  # nothing in this operation's schema to violate (e.g. GET /health)
                assert mode is GenerationMode.NEGATIVE, operation.path
    print(
        f"schemathesis: {tally['requests']} requests over {len(operations)} operations in "
        f"{time.monotonic() - started:.0f} s, {len(server_errors)} server errors"
    )
    assert server_errors == []
