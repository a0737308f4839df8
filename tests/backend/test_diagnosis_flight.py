"""A diagnosed hypothesis flown on the simulated monitor (POST /monitors/simulated/flight): the emulated satellite's
RW2 fails at 350 s (its own truth parameters, onboard FDIR); the diagnosis' replay flies "failure RW2" from before
the onset and the telemetry's coasting RW2 follows it, while the nominal twin and a wrong wheel leave residuals
far beyond the tachometer's quantum. The running monitors switch to it, every viewer's panel naming it, and go
back to the nominal twin; bad requests are refused saying what is wrong."""

from __future__ import annotations

import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.twin.diagnosis_repository import DiagnosisRepository
from tests.backend.conftest import bearer, make_settings

pytestmark = pytest.mark.slow  # an emulated flight and two twin replays on the shared LocalCluster

FAILED_WHEEL, ONSET_S, DURATION_S = 1, 350.0, 1000.0  # 0-based: the dictionary's RW2
SCENARIO = "somov-ge4-scan"
QUANTUM_RPM = 0.25  # the reference dictionary's wheel-speed resolution
FIT_RMS_RPM = 2.0  # the true hypothesis: residuals of the quantum's order (twin vs truth parameters, estimate noise)
MISFIT_FACTOR = 10.0
CONTROL_DT_S = 2.0  # the scenario's control period: the twin's output rate (twin_replay.twin_at)
SETTLE_S = 30.0  # the failed wheel's last commanded torque dies out  # the nominal twin / the wrong wheel: at least this much worse than the true hypothesis


def _iso(t_ns: float) -> str:
    return np.datetime_as_string(np.datetime64(int(t_ns), "ns"), unit="ms") + "Z"


def _hypothesis(fault: str, wheel: int | None, onset_ns: float | None, score: float) -> dict:
    return {
        "fault": fault,
        "wheel": wheel,
        "onset_utc": None if onset_ns is None else _iso(onset_ns),
        "onset_sigma_s": None if onset_ns is None else 5.0,
        "magnitude": 0.1 if fault == "gyro_bias" else None,
        "score": score,
        "log_evidence": 0.0,
    }


@pytest.fixture(scope="module")
def flown(tmp_path_factory, shared_dask):
    """An app with REFSAT's emulated telemetry archived, monitors attached (a browserless viewer on the simulated
    one) and a succeeded diagnosis naming the emulator's truth first (the flight is under test, not the ranking)."""
    from frontend.feed import TrajectoryFeed
    from frontend.monitors import serve_monitors
    from telemetry import emulator
    from tests.frontend.viser_clients import viser_client, wait_for_viewers
    from tests.ports import free_port

    tmp = tmp_path_factory.mktemp("flight")
    fault = emulator.parse_fault(f"wheel:{FAILED_WHEEL}:failure@{ONSET_S}")
    truth, _, stream = emulator.emulate(faults=[fault], duration_s=DURATION_S)
    t0 = int(stream.t_utc_ns[0])
    settings = make_settings(tmp, f"sqlite:///{tmp / 'flight.sqlite'}", dask_scheduler=shared_dask.scheduler.address)
    with TestClient(create_app(settings)) as client:
        services = client.app.state.services
        operator = bearer(services.auth.issue("op", Role.operator)[1])
        viewer = bearer(services.auth.issue("eye", Role.viewer)[1])
        client.post(
            "/api/v1/telemetry/uploads?satellite=REFSAT&dictionary=reference_satellite.yaml",
            content=stream.data,
            headers=operator,
        ).raise_for_status()
        repo = DiagnosisRepository(services.sessions)
        record = {
            "satellite": "REFSAT",
            "dictionary": "reference_satellite.yaml",
            "scenario": SCENARIO,
            "created_by": "op",
            "trigger": "operator",
            "start_utc": _iso(t0),
            "end_utc": _iso(stream.t_utc_ns[-1]),
        }
        onset_ns = t0 + ONSET_S * 1e9
        result = {
            "hypotheses": [
                _hypothesis("failure", FAILED_WHEEL + 1, onset_ns, 0.9),
                _hypothesis("failure", FAILED_WHEEL + 2, onset_ns, 0.05),
                _hypothesis("gyro_bias", None, None, 0.03),  # every fault type flies, but not without an onset
                _hypothesis("none", None, None, 0.02),
            ]
        }
        ids = {}
        for name, status in (("done", "succeeded"), ("running", "running"), ("failed", "failed")):
            ids[name] = repo.add({**record, "id": f"flight-test-{name}"})["id"]
            if status == "succeeded":
                repo.finish(ids[name], status, result=result)
            elif status == "failed":
                repo.finish(ids[name], status, error="no cluster")
        nominal = TrajectoryFeed(truth)
        ports = {r: free_port() for r in ("actual", "simulated", "overlay")}
        handles = serve_monitors(nominal, ports=ports, live=True)
        services.monitors.attach(handles, nominal, "REFSAT")
        try:
            with viser_client(handles.ports["simulated"]):
                wait_for_viewers(handles, "simulated", 1)
                yield {
                    "client": client,
                    "operator": operator,
                    "viewer": viewer,
                    "ids": ids,
                    "t0": t0,
                    "handles": handles,
                }
        finally:
            handles.stop()


def _fly(flown, rank: int, headers=None, diagnosis: str = "done"):
    body = {"diagnosis_id": flown["ids"].get(diagnosis, diagnosis), "rank": rank}
    return flown["client"].post("/api/v1/monitors/simulated/flight", json=body, headers=headers or flown["operator"])


def _state(flown) -> dict:
    return flown["client"].get("/api/v1/monitors/simulated", headers=flown["viewer"]).json()


def test_the_true_hypothesis_flies_the_coasting_wheel_the_telemetry_shows(flown):
    answer = _fly(flown, 1)
    assert answer.status_code == 200, answer.json()
    flight = answer.json()
    hyp, nom = flight["summaries"]["hypothesis"], flight["summaries"]["nominal"]
    assert hyp["samples"] >= 660.0 / CONTROL_DT_S  # onset − 60 s to onset + 600 s, at the twin's rate
    assert hyp["wheel_speed_rms_rpm"] < FIT_RMS_RPM, hyp
    assert nom["wheel_speed_rms_rpm"] > MISFIT_FACTOR * hyp["wheel_speed_rms_rpm"], (hyp, nom)
    t = np.asarray(flight["t_s"])
    start_s = (np.datetime64(flight["start_utc"].rstrip("Z"), "ns").astype(np.int64) - flown["t0"]) / 1e9
    assert ONSET_S - 62.0 < start_s < ONSET_S - 59.99  # the replay starts REPLAY_LEAD_S before the onset
    w = {k: np.asarray(v)[:, FAILED_WHEEL] for k, v in flight["wheel_speed_rpm"].items()}
    before = t < ONSET_S - start_s  # one twin until the onset (each variant with its own sensor noise)
    assert np.abs(w["hypothesis"][before] - w["nominal"][before]).max() < QUANTUM_RPM
    # after it the failed wheel coasts (no motor torque, friction far below a count over minutes) in the telemetry
    # and in the hypothesis; the nominal twin keeps driving it
    after = t > ONSET_S - start_s + SETTLE_S
    assert np.ptp(w["telemetry"][after]) <= QUANTUM_RPM and np.ptp(w["hypothesis"][after]) < QUANTUM_RPM
    assert np.abs(w["hypothesis"][after] - w["telemetry"][after]).max() < 2 * QUANTUM_RPM
    assert np.ptp(w["nominal"][after]) > 4 * QUANTUM_RPM
    # the monitors fly it: the label on the monitors and on the connected viewer's panel
    state = _state(flown)
    assert state["running"] and state["showing"] == "hypothesis"
    assert state["label"].startswith(f"hypothesis #1: failure RW{FAILED_WHEEL + 1} from ")
    assert state["monitor_label"] == state["label"] == flight["label"] and flight["on_monitor"]
    assert [v["label"] for v in state["viewers"]] == [state["label"]]
    assert state["flight"]["summaries"] == flight["summaries"]
    # and that viewer's wheel plot is the twin's: at the flight's end the failed wheel coasts there too
    (monitor,) = flown["handles"].viewers["simulated"].values()
    end_s = np.datetime64(flight["end_utc"].rstrip("Z"), "ns").astype(np.int64) / 1e9
    monitor.clock.seek(end_s)
    deadline = time.monotonic() + 10.0
    while not monitor.panels.wheel_source.content.startswith(f"simulated: {flight['label']}"):
        assert time.monotonic() < deadline, monitor.panels.wheel_source.content
        time.sleep(0.1)
    x, *plotted = monitor.panels.wheel_plot.data
    rw2 = np.asarray(plotted[FAILED_WHEEL])[np.asarray(x) > -SETTLE_S]
    assert rw2.size and np.ptp(rw2) < QUANTUM_RPM
    assert abs(rw2[-1] - w["hypothesis"][-1]) < QUANTUM_RPM


def test_a_wrong_wheel_flies_worse_and_the_nominal_twin_comes_back(flown):
    right = _fly(flown, 1).json()["summaries"]["hypothesis"]["wheel_speed_rms_rpm"]
    wrong = _fly(flown, 2)
    assert wrong.status_code == 200, wrong.json()
    assert wrong.json()["summaries"]["hypothesis"]["wheel_speed_rms_rpm"] > MISFIT_FACTOR * right
    assert _state(flown)["label"].startswith(f"hypothesis #2: failure RW{FAILED_WHEEL + 2}")
    back = flown["client"].delete("/api/v1/monitors/simulated/flight", headers=flown["operator"])
    assert back.status_code == 200, back.json()
    state = back.json()
    assert state["showing"] == "nominal" and state["label"] == "nominal twin" and state["flight"] is None
    deadline = time.monotonic() + 10.0
    while [v["label"] for v in _state(flown)["viewers"]] != ["nominal twin"]:
        assert time.monotonic() < deadline
        time.sleep(0.1)


@pytest.mark.parametrize(
    ("diagnosis", "rank", "status", "words"),
    [
        ("no-such-diagnosis", 1, 404, "no diagnosis 'no-such-diagnosis'"),
        ("running", 1, 409, "running; only a succeeded one"),
        ("failed", 1, 409, "failed (no cluster)"),
        ("done", 5, 422, "rank: 5 outside 1..4"),
        ("done", 4, 422, "'none' (no fault)"),
        ("done", 3, 422, "gyro_bias has no onset inside the telemetry"),
    ],
)
def test_bad_flights_are_refused_saying_what_is_wrong(flown, diagnosis, rank, status, words):
    answer = _fly(flown, rank, diagnosis=diagnosis)
    assert answer.status_code == status, answer.json()
    assert words in answer.json()["message"], answer.json()


def test_flying_takes_an_operator(flown):
    assert _fly(flown, 1, headers=flown["viewer"]).status_code == 403
    assert flown["client"].delete("/api/v1/monitors/simulated/flight", headers=flown["viewer"]).status_code == 403
    assert _fly(flown, 0).status_code == 422  # ranks start at 1
