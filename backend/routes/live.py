"""WebSocket /api/v1/ws: live parameters, alarms, twin state and archive commits in batches of at most rate_hz/s.

Protocol: the client sends ``{"op": "subscribe" | "unsubscribe", "topics": [...]}`` with topics
``parameters/<name>``, ``parameters/*``, ``alarms``, ``twin``, ``archive`` (one item per committed upload or
redecode: satellite, upload id, packets, time span, and whether its samples went out on ``parameters/``);
the server sends
``{"type": "batch", "items": [{"topic", "data"}...], "dropped": n}`` (n items thinned so far) and
``{"type": "error", "message", "field"}``. Token: ``?token=`` or an Authorization header (viewer).
"""

from __future__ import annotations

import asyncio
import contextlib

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from backend.core.auth import Role
from backend.ingest.live_hub import LiveHub, Subscription

router = APIRouter(tags=["live"])

CLOSE_UNAUTHORIZED = 4401  # 4000-4999: application codes (RFC 6455 §7.4.2), 4401 mirrors HTTP 401
CLOSE_FORBIDDEN = 4403
CLOSE_TOO_SLOW = 4408  # the client did not take a batch within ws_send_timeout_s


def _token(websocket: WebSocket) -> str | None:
    header = websocket.headers.get("authorization", "")
    if header.lower().startswith("bearer "):
        return header[7:].strip()
    return websocket.query_params.get("token")


async def _send_batches(websocket: WebSocket, sub: Subscription, period_s: float, timeout_s: float) -> None:
    while True:
        await asyncio.sleep(period_s)
        items = sub.drain()
        if not items:
            continue
        message = {"type": "batch", "items": items, "dropped": sub.dropped}
        try:
            await asyncio.wait_for(websocket.send_json(message), timeout_s)
        except TimeoutError:
            await websocket.close(CLOSE_TOO_SLOW, "too slow: dropped")
            return


async def _receive_commands(websocket: WebSocket, hub: LiveHub, sub: Subscription) -> None:
    while True:
        message = await websocket.receive_json()
        try:
            if not isinstance(message, dict):
                raise ValueError('op: expected a JSON object {"op": ..., "topics": [...]}')
            op, topics = message.get("op"), message.get("topics", [])
            if not isinstance(topics, list) or not all(isinstance(t, str) for t in topics):
                raise ValueError("topics: expected a list of strings")
            if op == "subscribe":
                hub.update(sub, topics, [])
            elif op == "unsubscribe":
                hub.update(sub, [], topics)
            else:
                raise ValueError(f"op: expected 'subscribe' or 'unsubscribe', got {op!r}")
        except ValueError as exc:
            field = str(exc).split(":", 1)[0]
            await websocket.send_json({"type": "error", "message": str(exc), "field": field})


async def _close_when_revoked(websocket: WebSocket, revoked: asyncio.Event) -> None:
    await revoked.wait()
    await websocket.close(CLOSE_UNAUTHORIZED, "token revoked")


@router.websocket("/ws")
async def live(websocket: WebSocket) -> None:
    """Authenticate, then run the batch sender and the command receiver until either ends."""
    services = websocket.app.state.services
    principal = services.auth.resolve(_token(websocket))
    if principal is None or principal.role < Role.viewer:
        await websocket.close(CLOSE_UNAUTHORIZED if principal is None else CLOSE_FORBIDDEN)
        return
    await websocket.accept()
    settings = services.settings
    sub = services.hub.subscribe()
    revoked, loop = asyncio.Event(), asyncio.get_running_loop()
    unwatch = services.auth.watch(principal, lambda: loop.call_soon_threadsafe(revoked.set))
    tasks = [
        asyncio.create_task(_send_batches(websocket, sub, 1.0 / settings.ws_rate_hz, settings.ws_send_timeout_s)),
        asyncio.create_task(_receive_commands(websocket, services.hub, sub)),
        asyncio.create_task(_close_when_revoked(websocket, revoked)),
    ]
    try:
        done, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in pending:
            task.cancel()
        for task in done:
            with contextlib.suppress(WebSocketDisconnect, RuntimeError, ValueError):
                task.result()
    finally:
        unwatch()
        services.hub.unsubscribe(sub)
