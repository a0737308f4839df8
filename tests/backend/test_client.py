"""The Python client against a real uvicorn server on loopback (HTTP and WebSocket)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import uvicorn
from fastapi import FastAPI

from backend.app import create_app
from backend.client import Client, ClientError
from backend.core.auth import Role
from backend.core.settings import Settings
from tests.backend.conftest import make_settings
from tests.ports import free_port

STARTUP_TIMEOUT_S = 20.0
DIARY = "real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
ENERGY_DRIFT_TOLERANCE = 1e-9  # RK4 at 0.01 s over 2 s on a slow spin: round-off level


@pytest.fixture
def settings(tmp_path: Path, database_url: str, dask_scheduler: str) -> Settings:
    """The default test settings, jobs and twin sessions flown on the shared Dask cluster (tests/conftest.py)."""
    return make_settings(tmp_path, database_url, dask_scheduler=dask_scheduler)


@pytest.fixture
def app(settings: Settings) -> FastAPI:
    """The app under test (its services reachable for waits on their state)."""
    return create_app(settings)


@pytest.fixture
def server(app: FastAPI) -> Iterator[tuple[str, dict[str, str]]]:
    """The app served by uvicorn in a thread; (base URL, token per role)."""
    port = free_port()
    uv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=uv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while not uv.started:
        assert time.monotonic() < deadline and thread.is_alive(), "uvicorn did not start"
        time.sleep(0.05)
    tokens = {role.name: app.state.services.auth.issue(role.name, role)[1] for role in Role}
    yield f"http://127.0.0.1:{port}", tokens
    uv.should_exit = True
    thread.join(15)


def test_client_uploads_queries_and_gets_live_samples(
    app: FastAPI, server: tuple[str, dict[str, str]], shared_data: Path
) -> None:
    url, tokens = server
    received: list[dict] = []

    def listen() -> None:
        with Client(url, tokens["viewer"]) as viewer:
            for item in viewer.subscribe(["parameters/q_ib_1"], timeout_s=30):
                received.append(item)
                return

    listener = threading.Thread(target=listen, daemon=True)
    listener.start()
    hub, deadline = app.state.services.hub, time.monotonic() + STARTUP_TIMEOUT_S
    while not hub.wants_any("parameters/q_ib_1"):  # the subscription registered: the upload's samples reach it
        assert time.monotonic() < deadline and listener.is_alive(), "the subscription never registered"
        time.sleep(0.01)
    with Client(url, tokens["operator"]) as api:
        report = api.upload(shared_data / DIARY)
        t_ns, q1 = api.samples("q_ib_1", max_points=50)
    listener.join(30)
    assert report["archive"]["packets_accepted"] == 7200
    assert len(q1) <= 50 and np.all(np.diff(t_ns) > 0)
    assert received and received[0]["topic"] == "parameters/q_ib_1"
    assert len(received[0]["data"]["values"]) == 7200


def test_client_runs_a_simulation_with_progress_and_fetches_numpy_results(server: tuple[str, dict[str, str]]) -> None:
    url, tokens = server
    seen: list[float] = []
    scenario = {
        "kind": "rigid-spin",
        "duration_s": 2.0,
        "dt_s": 0.01,
        "inertia_kg_m2": [[35.0, 30.0, 25.0]],
        "omega0_rad_s": [[0.01, -0.02, 0.03]],
    }
    with Client(url, tokens["operator"]) as api:
        job = api.simulate(scenario, progress=seen.append, poll_s=0.1, timeout_s=60)
        arrays = api.results(job["id"])
    assert job["status"] == "succeeded" and seen[-1] == 1.0
    assert arrays["q_ib"].shape == (1, 201, 4) and arrays["t_s"][-1] == pytest.approx(2.0)
    assert job["summary"]["energy_rel_drift"][0] < ENERGY_DRIFT_TOLERANCE


def test_client_raises_with_status_and_field(server: tuple[str, dict[str, str]]) -> None:
    url, tokens = server
    with Client(url, tokens["viewer"]) as viewer, pytest.raises(ClientError) as denied:
        viewer.start_simulation({"kind": "rigid-spin"})
    assert denied.value.status == 403
    with Client(url) as anonymous, pytest.raises(ClientError) as missing:
        anonymous.job("nope")
    assert missing.value.status == 401 and missing.value.field == "Authorization"


EMULATED_S, ALIGN_S, TWIN_S = 130.0, 65.0, 60.0  # a short flight: GPS fixes before the alignment, then a minute
TWIN_ATTITUDE_TOL_DEG = 30.0 / 3600.0  # 10 × the 3″ star-tracker σ, as in test_twin.py


def test_client_runs_a_twin_session_and_gets_residual_arrays(server: tuple[str, dict[str, str]]) -> None:
    from telemetry import emulator

    url, tokens = server
    _, _, stream = emulator.emulate(duration_s=EMULATED_S)
    align = np.datetime_as_string(np.datetime64(int(stream.t_utc_ns[0]) + int(ALIGN_S * 1e9), "ns"), unit="ms")
    with Client(url, tokens["operator"]) as api:
        api.upload(stream.data, satellite="REFSAT", dictionary="reference_satellite.yaml")
        session = api.start_twin(align + "Z", TWIN_S, satellite="REFSAT", alternatives={"spare": []})
        residuals = api.twin_residuals(session["id"], max_points=100_000, poll_s=0.2, timeout_s=300)
    assert set(residuals["summaries"]) == {"twin", "spare"}
    assert residuals["t_s"].size >= TWIN_S / 0.25 - 1 and residuals["wheel_speed_rpm"].shape[1] == 4
    assert residuals["attitude_deg"].max() < TWIN_ATTITUDE_TOL_DEG
