"""Live fan-out: non-blocking publish, thinning of slow clients, ≤ rate_hz batches, WebSocket auth."""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketTestSession
from starlette.websockets import WebSocketDisconnect

from backend.app import create_app
from backend.core.auth import Role
from backend.ingest.live_hub import LiveHub
from backend.routes.live import CLOSE_TOO_SLOW, CLOSE_UNAUTHORIZED, _send_batches
from backend.twin.live import ATTITUDE_LIMIT_ARCSEC, RED_FACTOR
from telemetry import emulator
from telemetry.live import hello
from tests.backend.conftest import bearer, make_settings

QUATERNION_RESOLUTION = 1e-6  # the dictionary's float32 quaternion fields round the sent values
# The ingest process commits every ARCHIVE_INTERVAL_S = 0.5 s: a wait for it fails once none of its tallies has moved
# for this long (a stalled ingest), not after a fixed total (10 s before) that a loaded machine can overrun while the
# ingest still progresses
LIVE_STALL_S = 30.0
LIVE_TALLIES = ("packets_received", "packets_archived", "connections", "hellos_refused")
SUBSCRIBE_HANG_S = 60.0  # the app's receive task takes a subscribe within milliseconds: a hang bound, not a budget
NOAA20_DIARY = "real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
NOAA20_OCTETS = 71  # one APID 11 packet of the diary
NOAA20_LISTENER = {"live_enabled": True, "live_satellite": "NOAA-20", "live_dictionary": "noaa20_apid11_ccsdspy.yaml"}


def _subscribe(ws: WebSocketTestSession, hub: LiveHub, topic: str) -> None:
    """Subscribe the WebSocket to ``topic`` and wait until the hub fans it out (the subscribe is asynchronous)."""
    ws.send_json({"op": "subscribe", "topics": [topic]})
    deadline = time.monotonic() + SUBSCRIBE_HANG_S
    while not hub.wants_any(topic):
        assert time.monotonic() < deadline, f"the subscribe to {topic} never reached the hub"
        time.sleep(0.01)


def _wait_live(client: TestClient, done: Callable[[dict], bool], what: str) -> dict:
    """The health's live block once ``done`` holds for it; fails when the ingest process's tallies (packets received
    and archived, connections, refused hellos) have not moved for LIVE_STALL_S before that."""
    moved_at, last = time.monotonic(), ()
    while not done(live := client.get("/api/v1/health").json()["live"]):
        if (tallies := tuple(live.get(name) for name in LIVE_TALLIES)) != last:
            moved_at, last = time.monotonic(), tallies
        assert time.monotonic() - moved_at < LIVE_STALL_S, f"{what} never reached the archive: stalled at {live}"
        time.sleep(0.1)
    return live


def _wait_archived(client: TestClient, n_packets: int, what: str) -> dict:
    """The health's live block once the ingest process has archived ``n_packets``."""
    return _wait_live(client, lambda live: live.get("packets_archived", 0) >= n_packets, what)


def _unpaced(port: int, satellite: str | None = None, dictionary: str | None = None) -> emulator.SendOptions:
    """Send to the loopback listener on ``port`` as fast as possible, three connection attempts."""
    return emulator.SendOptions("127.0.0.1", port, float("inf"), attempts=3, satellite=satellite, dictionary=dictionary)


def test_publish_never_waits_and_a_full_subscriber_keeps_the_newest_items() -> None:
    hub = LiveHub(capacity=10)
    stalled = hub.subscribe(["parameters/*"])
    other = hub.subscribe(["alarms"])
    for i in range(100_000):  # a publish that waited on the stalled subscriber would never finish
        hub.publish("parameters/q", i)
    assert stalled.dropped == 100_000 - 10
    assert [item["data"] for item in stalled.drain()] == list(range(99_990, 100_000))
    assert other.drain() == []


def test_bad_topic_names_the_field() -> None:
    with pytest.raises(ValueError, match="topics"):
        LiveHub(10).subscribe(["wheels"])


class _StalledSocket:
    def __init__(self) -> None:
        self.closed_with: int | None = None

    async def send_json(self, _: object) -> None:
        await asyncio.sleep(10)

    async def close(self, code: int, reason: str = "") -> None:
        self.closed_with = code


def test_a_client_that_stalls_a_send_is_dropped() -> None:
    hub = LiveHub(10)
    sub = hub.subscribe(["twin"])
    hub.publish("twin", {"residual_deg": 0.1})
    socket = _StalledSocket()
    asyncio.run(asyncio.wait_for(_send_batches(socket, sub, 0.01, 0.05), 2.0))  # type: ignore[arg-type]
    assert socket.closed_with == CLOSE_TOO_SLOW


def test_websocket_batches_what_was_published_and_needs_a_token(client: TestClient, tokens: dict[str, str]) -> None:
    with pytest.raises(WebSocketDisconnect) as refused, client.websocket_connect("/api/v1/ws") as ws:
        ws.receive_json()
    assert refused.value.code == CLOSE_UNAUTHORIZED
    hub = client.app.state.services.hub
    with client.websocket_connect(f"/api/v1/ws?token={tokens['viewer']}") as ws:
        ws.send_json({"op": "subscribe", "topics": ["parameters/x", "bogus"]})
        assert ws.receive_json()["field"] == "topics"
        ws.send_json(["not", "an", "object"])
        assert ws.receive_json()["field"] == "op"
        _subscribe(ws, hub, "parameters/x")

        def publish_fifty() -> None:
            for i in range(50):
                hub.publish("parameters/x", i)

        # published at once, in one call on the app's event loop: its sender task cannot drain between two of them
        # (from the test's thread, a pause of the thread longer than the 0.1-s period could split them)
        ws.portal.call(publish_fifty)
        received, batches = 0, 0
        while received < 50:
            message = ws.receive_json()
            batches, received = batches + 1, received + len(message["items"])
        assert batches == 1 and received == 50


class _Enough(Exception):
    """Ends the sender after the sends a test wanted."""


def test_the_sender_waits_one_period_before_each_batch(monkeypatch: pytest.MonkeyPatch) -> None:
    """At most rate_hz batches a second, by construction: every send follows a wait of period_s = 1/rate_hz since
    the previous one (the waits recorded in order with the sends, no clock read)."""
    hub = LiveHub(100)
    sub = hub.subscribe(["twin"])
    events: list[tuple[str, float]] = []
    real_sleep = asyncio.sleep

    async def recorded_sleep(delay_s: float) -> None:
        events.append(("wait", delay_s))
        hub.publish("twin", len(events))  # something to send after every wait
        await real_sleep(0)

    class _Recorder:
        async def send_json(self, message: dict) -> None:
            events.append(("send", len(message["items"])))
            if sum(kind == "send" for kind, _ in events) == 5:
                raise _Enough

        async def close(self, code: int, reason: str = "") -> None:
            raise AssertionError(f"closed with {code}")

    monkeypatch.setattr("backend.routes.live.asyncio.sleep", recorded_sleep)
    with pytest.raises(_Enough):
        asyncio.run(_send_batches(_Recorder(), sub, 0.1, 2.0))  # type: ignore[arg-type]
    assert [kind for kind, _ in events] == ["wait", "send"] * 5
    assert all(delay == 0.1 for kind, delay in events if kind == "wait")


def test_uploaded_packets_reach_a_websocket_subscriber(
    client: TestClient, tokens: dict[str, str], shared_data: Path
) -> None:
    data = (shared_data / NOAA20_DIARY).read_bytes()
    with client.websocket_connect("/api/v1/ws", headers=bearer(tokens["viewer"])) as ws:
        _subscribe(ws, client.app.state.services.hub, "parameters/q_ib_0")
        client.post("/api/v1/telemetry/uploads", content=data, headers=bearer(tokens["operator"]))
        item = ws.receive_json()["items"][0]
    assert item["topic"] == "parameters/q_ib_0" and len(item["data"]["values"]) == 7200


def test_packets_streamed_over_tcp_are_archived_and_reach_a_websocket_subscriber(
    tmp_path: Path, database_url: str, shared_data: Path
) -> None:
    """End to end: TCP link (real NOAA-20 packets) → ingest process → archive and → WebSocket subscriber."""
    packets = (shared_data / NOAA20_DIARY).read_bytes()
    n_sent = 500
    settings = make_settings(tmp_path, database_url, **NOAA20_LISTENER)
    with TestClient(create_app(settings)) as client:
        viewer = client.app.state.services.auth.issue("viewer", Role.viewer)[1]
        port = client.get("/api/v1/health").json()["live"]["port"]
        with client.websocket_connect(f"/api/v1/ws?token={viewer}") as ws:
            _subscribe(ws, client.app.state.services.hub, "parameters/q_ib_0")
            with socket.create_connection(("127.0.0.1", port)) as link:
                link.sendall(packets[: n_sent * NOAA20_OCTETS])
            seen = 0
            while seen < n_sent:
                seen += sum(len(item["data"]["values"]) for item in ws.receive_json()["items"])
        _wait_archived(client, n_sent, "live packets")
        samples = client.get("/api/v1/parameters/q_ib_0/samples", headers=bearer(viewer)).json()
    assert seen == n_sent and samples["total_points"] == n_sent
    assert not client.app.state.services.telemetry.live_stats()  # the ingest process has stopped


EMULATED_S = 60.0  # one minute of the demo satellite: 240 ACS_HK packets at T_q = 0.25 s


def test_emulated_satellite_over_tcp_reaches_archive_and_websocket(tmp_path: Path, database_url: str) -> None:
    """The issue's end-to-end path: emulator → TCP → ingest process → archive, and → WebSocket subscriber."""
    settings = make_settings(tmp_path, database_url, live_enabled=True)
    _, series, stream = emulator.emulate("somov-ge4-scan", [], EMULATED_S, "2026-03-20T00:00:00Z")
    sent_q0 = np.asarray(series["ACS_HK"].values["q_est_ib_0"], dtype=float)
    with TestClient(create_app(settings)) as client:
        viewer = client.app.state.services.auth.issue("viewer", Role.viewer)[1]
        port = client.get("/api/v1/health").json()["live"]["port"]
        with client.websocket_connect(f"/api/v1/ws?token={viewer}") as ws:
            _subscribe(ws, client.app.state.services.hub, "parameters/q_est_ib_0")
            asyncio.run(emulator.send_stream(stream, _unpaced(port)))
            live: list[float] = []
            while len(live) < sent_q0.size:
                for item in ws.receive_json()["items"]:
                    live.extend(item["data"]["values"])
        _wait_archived(client, len(stream), "emulated packets")
        archived = client.get(
            f"/api/v1/parameters/q_est_ib_0/samples?satellite={settings.live_satellite}&max_points={sent_q0.size}",
            headers=bearer(viewer),
        ).json()
    assert np.allclose(live, sent_q0, atol=QUATERNION_RESOLUTION)
    assert np.allclose(archived["values"], sent_q0, atol=QUATERNION_RESOLUTION)


def test_a_mixed_fleet_on_one_listener_each_satellite_decoded_with_the_dictionary_its_hello_names(
    tmp_path: Path, database_url: str, shared_data: Path
) -> None:
    """End to end: a listener whose own dictionary is NOAA-20's takes real NOAA-20 packets, the emulated reference
    satellite naming its dictionary in its hello line, and a connection naming an unknown one (refused, said)."""
    noaa = (shared_data / NOAA20_DIARY).read_bytes()
    n_noaa = 300
    settings = make_settings(tmp_path, database_url, **NOAA20_LISTENER)
    _, series, stream = emulator.emulate("somov-ge4-scan", [], 20.0, "2026-03-20T00:00:00Z")
    sent_q0 = np.asarray(series["ACS_HK"].values["q_est_ib_0"], dtype=float)
    with TestClient(create_app(settings)) as client:
        viewer = client.app.state.services.auth.issue("viewer", Role.viewer)[1]
        port = client.get("/api/v1/health").json()["live"]["port"]
        with socket.create_connection(("127.0.0.1", port)) as link:
            link.sendall(noaa[: n_noaa * NOAA20_OCTETS])  # no hello: the listener's own satellite and dictionary
        asyncio.run(emulator.send_stream(stream, _unpaced(port, "REF-9", emulator.REFERENCE_DICTIONARY)))
        with socket.create_connection(("127.0.0.1", port)) as link:
            link.sendall(hello("BAD-1", "nope.yaml") + stream.data)  # a dictionary the listener does not know
        live = _wait_live(
            client,
            lambda block: (
                block.get("packets_archived", 0) >= n_noaa + len(stream) and bool(block.get("hellos_refused"))
            ),
            "the fleet's packets",
        )
        archived = client.get(
            f"/api/v1/parameters/q_est_ib_0/samples?satellite=REF-9&max_points={sent_q0.size}", headers=bearer(viewer)
        ).json()
        noaa_samples = client.get("/api/v1/parameters/q_ib_0/samples?satellite=NOAA-20", headers=bearer(viewer)).json()
        names = {s["name"] for s in client.get("/api/v1/satellites", headers=bearer(viewer)).json()}
    assert np.allclose(archived["values"], sent_q0, atol=QUATERNION_RESOLUTION)
    assert noaa_samples["total_points"] == n_noaa and "BAD-1" not in names
    assert live["hellos_refused"] == 1 and "'nope.yaml'" in live["last_hello_error"]
    assert emulator.REFERENCE_DICTIONARY in live["last_hello_error"]  # the error lists the known dictionaries
    assert "BAD-1" in live["last_hello_error"]


def test_revoking_a_token_closes_its_open_websocket_as_the_revocation_is_made(
    client: TestClient, tokens: dict[str, str]
) -> None:
    """The DELETE itself closes the token's open WebSocket (the authenticator calls the socket's on-revoke): the
    revocation watch, which would also close it within REVOCATION_POLL_S, is stopped first, so the close seen
    can only come from the DELETE (no timing: the order of events is the truth)."""
    viewer = tokens["viewer"]
    services = client.app.state.services
    token_id = services.auth.resolve(viewer).token_id
    services.auth.stop_revocation_watch()
    with client.websocket_connect(f"/api/v1/ws?token={viewer}") as ws:
        _subscribe(ws, services.hub, "alarms")  # the socket's handler runs and watches its token
        assert client.delete(f"/api/v1/tokens/{token_id}", headers=bearer(tokens["admin"])).status_code == 200
        closed = ws.receive()
    assert closed["type"] == "websocket.close" and closed["code"] == 4401


FLEET_S = 40.0  # seconds of flight each satellite of the fleet sends


@pytest.mark.timeout(120)  # the WebSocket wait below has no end of its own
def test_one_listener_takes_a_fleet_each_satellite_archived_with_its_live_twin(
    tmp_path: Path, database_url: str
) -> None:
    """End to end for a fleet: two emulated satellites, each on its own TCP connection naming it (emulator
    satellite=...), and the server's own satellite without a name → one ingest process → each satellite's
    samples in the archive under its name, its own live twin (state, residuals), the twin topic on the WebSocket."""
    settings = make_settings(tmp_path, database_url, live_enabled=True)
    _, series, stream = emulator.emulate("somov-ge4-scan", [], FLEET_S, "2026-03-20T00:00:00Z")
    n_hk = series["ACS_HK"].t_utc_ns.size
    fleet = ("SAT-A", "SAT-B", None)
    with TestClient(create_app(settings)) as client:
        viewer = client.app.state.services.auth.issue("viewer", Role.viewer)[1]
        port = client.get("/api/v1/health").json()["live"]["port"]
        with client.websocket_connect(f"/api/v1/ws?token={viewer}") as ws:
            ws.send_json({"op": "subscribe", "topics": ["twin"]})

            async def send_all() -> None:
                await asyncio.gather(*(emulator.send_stream(stream, _unpaced(port, s)) for s in fleet))

            asyncio.run(send_all())
            names = {s or settings.live_satellite for s in fleet}
            propagating: set[str] = set()
            while propagating != names:
                for item in ws.receive_json()["items"]:
                    if item["data"]["state"] == "propagating":
                        propagating.add(item["data"]["satellite"])
        _wait_archived(client, 3 * len(stream), "the fleet's packets")
        listed = {s["name"] for s in client.get("/api/v1/satellites", headers=bearer(viewer)).json()}
        for name in names:
            samples = client.get(
                f"/api/v1/parameters/q_est_ib_0/samples?satellite={name}&max_points={n_hk}", headers=bearer(viewer)
            ).json()
            twin = client.get(f"/api/v1/satellites/{name}/twin", headers=bearer(viewer)).json()
            passes = client.get(f"/api/v1/passes?satellite={name}", headers=bearer(viewer)).json()
            assert samples["total_points"] == n_hk
            assert [p["origin"] for p in passes] == ["data"]  # made from its data by the ingest process
            assert (
                twin["samples_compared"] > 0 and twin["attitude_residual_arcsec"] < ATTITUDE_LIMIT_ARCSEC * RED_FACTOR
            )
        assert client.get("/api/v1/health").json()["live"]["satellites"] == 3
    assert names <= listed
