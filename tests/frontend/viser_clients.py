"""A viser client without a browser, for the monitors' per-viewer tests: a WebSocket speaking viser's
subprotocol that sends the one camera message after which the server registers the client (DESIGN.md:
learned facts), and drains whatever the server sends so that the server never waits on it."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import msgspec
import viser
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

CAMERA = {
    "type": "ViewerCameraMessage",
    "wxyz": [1.0, 0.0, 0.0, 0.0],
    "position": [0.0, 0.0, 3.2],
    "fov": 0.8,
    "near": 0.01,
    "far": 100.0,
    "image_height": 800,
    "image_width": 1280,
    "look_at": [0.0, 0.0, 0.0],
    "up_direction": [0.0, 0.0, 1.0],
}


@contextmanager
def viser_client(port: int, headers: dict[str, str] | None = None, received: list | None = None) -> Iterator[object]:
    """An open viser client on 127.0.0.1:port (registered once the server has read its camera message); the arrival
    time (time.monotonic) of every websocket message the server sends is appended to ``received`` if given."""
    with connect(
        f"ws://127.0.0.1:{port}/",
        subprotocols=[f"viser-v{viser.__version__}"],
        additional_headers=headers or {},
        open_timeout=30,
        max_size=None,
    ) as ws:
        ws.send(msgspec.msgpack.encode(CAMERA))
        stop = threading.Event()

        def drain() -> None:
            while not stop.is_set():
                try:
                    ws.recv(timeout=0.2)
                    if received is not None:
                        received.append(time.monotonic())
                except TimeoutError:
                    continue
                except ConnectionClosed:
                    return

        thread = threading.Thread(target=drain, daemon=True)
        thread.start()
        try:
            yield ws
        finally:
            stop.set()


def wait_for_viewers(handles, role: str, n: int, timeout_s: float = 30.0) -> list:
    """The n viewers of a monitor once their clients are registered (in connection order)."""
    deadline = time.monotonic() + timeout_s
    while len(handles.viewers.get(role, {})) < n:
        if time.monotonic() > deadline:
            raise AssertionError(f"{n} viewer(s) of the {role} monitor not registered in {timeout_s} s")
        time.sleep(0.05)
    return [handles.viewers[role][k] for k in sorted(handles.viewers[role])]
