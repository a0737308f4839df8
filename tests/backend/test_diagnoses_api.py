"""Diagnosis over REST: upload the emulated satellite's packets (a hidden wheel failure), start a diagnosis on
the satellite and window, poll it, read the ranked hypotheses (the same JSON as ``acs-twin diagnose``); the
twin replays fly on the server's Dask LocalCluster; diagnoses are stored (SQLite, PostgreSQL) and outlive a restart."""

from __future__ import annotations

import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from tests.backend.conftest import bearer, make_settings

pytestmark = pytest.mark.slow  # replays on the server's LocalCluster: scheduled first (tests/conftest.py)

FAILED_WHEEL, FAILURE_ONSET_S = 1, 350.0  # sim_core's 0-based index: the dictionary's wheel 2
ONSET_TOLERANCE_S = 60.0
POLL_TIMEOUT_S = 300.0  # numba may compile the engine on a loaded machine


def _iso(t_ns: int) -> str:
    return np.datetime_as_string(np.datetime64(t_ns, "ns"), unit="ms") + "Z"


def test_diagnosis_started_over_rest_names_the_hidden_wheel_failure(tmp_path: Path, dask_scheduler: str) -> None:
    from telemetry import emulator

    _, _, stream = emulator.emulate(faults=[emulator.parse_fault(f"wheel:{FAILED_WHEEL}:failure@{FAILURE_ONSET_S}")])
    t0, t1 = int(stream.t_utc_ns[0]), int(stream.t_utc_ns[-1])
    settings = make_settings(tmp_path, f"sqlite:///{tmp_path / 'diagnosis.sqlite'}", dask_scheduler=dask_scheduler)
    with TestClient(create_app(settings)) as client:
        operator = bearer(client.app.state.services.auth.issue("op", Role.operator)[1])
        upload = client.post(
            "/api/v1/telemetry/uploads?satellite=REFSAT&dictionary=reference_satellite.yaml",
            content=stream.data,
            headers=operator,
        )
        assert upload.status_code == 200, upload.json()
        started = client.post(
            "/api/v1/diagnoses",
            headers=operator,
            json={"satellite": "REFSAT", "scenario": "somov-ge4-scan", "start_utc": _iso(t0), "end_utc": _iso(t1)},
        )
        assert started.status_code == 202, started.json()
        run_id = started.json()["id"]
        deadline = time.monotonic() + POLL_TIMEOUT_S
        while (run := client.get(f"/api/v1/diagnoses/{run_id}", headers=operator).json())["status"] == "running":
            assert time.monotonic() < deadline
            time.sleep(0.1)
        assert run["status"] == "succeeded", run["error"]
        top = run["result"]["hypotheses"][0]
        assert (top["fault"], top["wheel"]) == ("failure", FAILED_WHEEL + 1)
        onset = datetime.fromisoformat(top["onset_utc"]).timestamp() - t0 / 1e9
        assert abs(onset - FAILURE_ONSET_S) <= ONSET_TOLERANCE_S
        listed = client.get("/api/v1/diagnoses", headers=operator).json()
        # the live twin may have diagnosed the uploaded failure by itself too: only its trigger differs
        assert [r["id"] for r in listed if r["trigger"] == "operator"] == [run_id]
        assert {r["trigger"] for r in listed} <= {"operator", "live twin"}
        assert run["trigger"] == "operator" and run["alarm_id"] is None
    with TestClient(create_app(settings)) as client:  # a restart keeps the result
        operator = bearer(client.app.state.services.auth.issue("op", Role.operator)[1])
        assert client.get(f"/api/v1/diagnoses/{run_id}", headers=operator).json() == run


def test_diagnosis_requests_are_checked_and_their_outcome_outlives_a_restart(
    tmp_path: Path, database_url: str, dask_scheduler: str
) -> None:
    settings = make_settings(tmp_path, database_url, dask_scheduler=dask_scheduler)
    start = datetime(2026, 3, 20, tzinfo=UTC)
    with TestClient(create_app(settings)) as client:
        operator = bearer(client.app.state.services.auth.issue("op", Role.operator)[1])
        too_long = client.post(
            "/api/v1/diagnoses",
            headers=operator,
            json={"start_utc": start.isoformat(), "end_utc": start.replace(day=22).isoformat()},
        )
        assert too_long.status_code == 422 and too_long.json()["field"] == "end_utc"
        unknown = client.get("/api/v1/diagnoses/nope", headers=operator)
        past_int64 = client.get(f"/api/v1/diagnoses?alarm_id={2**63}", headers=operator)  # was a 500 (OverflowError)
        assert past_int64.status_code == 422 and past_int64.json()["field"] == "alarm_id"
        assert unknown.status_code == 404 and unknown.json()["field"] == "diagnosis_id"
        empty = client.post(
            "/api/v1/diagnoses",
            headers=operator,
            json={"start_utc": start.isoformat(), "end_utc": start.replace(hour=1).isoformat()},
        ).json()
        deadline = time.monotonic() + 30.0
        while (run := client.get(f"/api/v1/diagnoses/{empty['id']}", headers=operator).json())["status"] == "running":
            assert time.monotonic() < deadline
            time.sleep(0.2)
        assert run["status"] == "failed" and "REFSAT" in run["error"]  # the archive names what it lacks
    with TestClient(create_app(settings)) as client:
        operator = bearer(client.app.state.services.auth.issue("op", Role.operator)[1])
        assert client.get(f"/api/v1/diagnoses/{empty['id']}", headers=operator).json() == run


def test_a_diagnosis_left_running_by_a_dead_server_is_failed_saying_so(tmp_path: Path, database_url: str) -> None:
    from backend.services import build_services
    from backend.twin.diagnosis_repository import RESTARTED, DiagnosisRepository

    settings = make_settings(tmp_path, database_url)
    crashed = build_services(settings)
    record = {"id": "deadbeef", "satellite": "REFSAT", "dictionary": "reference_satellite.yaml"}
    record |= {"scenario": "somov-ge4-scan", "start_utc": "2026-03-20T00:00:00.000Z"}
    DiagnosisRepository(crashed.sessions).add(record | {"end_utc": "2026-03-20T00:20:00.000Z", "created_by": "op"})
    crashed.engine.dispose()
    with TestClient(create_app(settings)) as client:
        operator = bearer(client.app.state.services.auth.issue("op", Role.operator)[1])
        run = client.get("/api/v1/diagnoses/deadbeef", headers=operator).json()
    assert run["status"] == "failed" and run["error"] == RESTARTED
