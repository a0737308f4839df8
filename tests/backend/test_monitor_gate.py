"""The 3D monitors behind the app's tokens: a real viser server reached only through MonitorGate.

Truths: viser's own page (its index.html) and its WebSocket handshake (subprotocol viser-v<version>)
answered through the gate for a viewer token, a 401 without one, and a revoked token's open
WebSocket closed by the revocation itself.
"""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest
import viser
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from backend.core.auth import Role
from backend.core.settings import Settings
from backend.services import build_services
from backend.twin.monitor_gate import COOKIE, MonitorGate

HANG_S = 60.0  # a socket left open fails the test after this (a hang bound, not a budget)


@pytest.fixture
def gated(tmp_path: Path):
    services = build_services(Settings(data_dir=tmp_path))
    monitor = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    gate = MonitorGate(services.auth, "127.0.0.1", 0, monitor.get_port())
    gate.start()
    try:
        yield services, gate
    finally:
        gate.stop()
        monitor.stop()
        services.close()


def test_no_token_no_monitor(gated) -> None:
    _, gate = gated
    assert httpx.get(f"http://127.0.0.1:{gate.port}/").status_code == 401
    forged = httpx.get(f"http://127.0.0.1:{gate.port}/", cookies={COOKIE: "acs_forged"})
    assert forged.status_code == 401 and gate.refused == 2


def test_a_viewer_token_opens_the_page_and_is_kept_out_of_the_url(gated) -> None:
    services, gate = gated
    _, token = services.auth.issue("monitor viewer", Role.viewer)
    with httpx.Client(base_url=f"http://127.0.0.1:{gate.port}") as browser:
        first = browser.get("/", params={"token": token})
        assert first.status_code == 303 and first.headers["location"] == "/"
        assert "HttpOnly" in first.headers["set-cookie"]
        page = browser.get("/")
    assert page.status_code == 200 and "<html" in page.text.lower()


def test_revoking_the_token_closes_the_open_monitor_websocket(gated) -> None:
    """The authenticator's forget (what a revocation calls) closes the monitor's open WebSocket itself: no revocation
    watch runs here (build_services starts none), so the close can only come from it."""
    services, gate = gated
    token_id, token = services.auth.issue("monitor viewer", Role.viewer)
    with connect(
        f"ws://127.0.0.1:{gate.port}/",
        subprotocols=[f"viser-v{viser.__version__}"],
        additional_headers={"Cookie": f"{COOKIE}={token}"},
        open_timeout=10,
    ) as ws:
        assert ws.subprotocol == f"viser-v{viser.__version__}"
        services.tokens.revoke(token_id)
        services.auth.forget(token_id)
        with pytest.raises(ConnectionClosed):
            while True:
                ws.recv(timeout=HANG_S)  # viser's own messages, until the gate closes the socket
