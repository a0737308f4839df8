"""Bounds on every JSON request body before a route parses it: size, nesting depth, strict numbers.

Python's json (which FastAPI uses) takes ``NaN`` and ``Infinity`` as numbers and recurses until its
stack runs out; RFC 8259 has neither. This ASGI middleware reads a JSON body (content type
``application/json`` or ``…+json``) up to ``max_bytes`` (413 beyond, read no further), checks it
with orjson (strict RFC 8259) and a depth limit, and answers 422 naming ``body`` when it fails;
a body that passes is replayed to the application unchanged.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

import orjson

__all__ = ["MAX_JSON_DEPTH", "JsonBodyBounds", "json_problem"]

MAX_JSON_DEPTH = 32  # a scenario body nests 6 deep; 32 leaves room and bounds every walk of the body

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]


def json_problem(body: bytes, max_depth: int = MAX_JSON_DEPTH) -> str | None:
    """Why ``body`` is not acceptable JSON (invalid, NaN/Infinity, nested deeper than max_depth), else None."""
    try:
        value = orjson.loads(body)
    except orjson.JSONDecodeError as exc:
        return f"body: not valid JSON (RFC 8259: no NaN or Infinity, nesting at most {max_depth}): {exc}"
    level, depth = [value], 0
    while level:
        depth += 1
        if depth > max_depth:
            return f"body: JSON nested deeper than {max_depth} levels"
        level = [
            child
            for item in level
            if isinstance(item, (dict, list))
            for child in (item.values() if isinstance(item, dict) else item)
        ]
    return None


def _is_json(scope: Scope) -> bool:
    for key, value in scope.get("headers", ()):
        if key == b"content-type":
            kind = value.split(b";", 1)[0].strip().lower()
            return kind == b"application/json" or kind.endswith(b"+json")
    return False


async def _answer(send: Send, status: int, message: str) -> None:
    body = orjson.dumps({"message": message, "field": "body", "status": status})
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())],
        }
    )
    await send({"type": "http.response.body", "body": body})


class JsonBodyBounds:
    """ASGI middleware: JSON bodies at most ``max_bytes``, strict, at most MAX_JSON_DEPTH deep."""

    def __init__(self, app: Callable[[Scope, Receive, Send], Awaitable[None]], max_bytes: int) -> None:
        self.app, self.max_bytes = app, max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check a JSON body, then hand the request on (body replayed) or answer 413/422."""
        if scope["type"] != "http" or not _is_json(scope):
            await self.app(scope, receive, send)
            return
        chunks, size, more = [], 0, True
        while more:
            message = await receive()
            if message["type"] != "http.request":
                return  # the client left
            chunks.append(message.get("body", b""))
            size += len(chunks[-1])
            more = message.get("more_body", False)
            if size > self.max_bytes:
                await _answer(send, 413, f"body: JSON bodies are limited to {self.max_bytes} bytes (max_json_kb)")
                return
        body = b"".join(chunks)
        if body and (problem := json_problem(body)):
            await _answer(send, 422, problem)
            return
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if replayed:
                return await receive()
            replayed = True
            return {"type": "http.request", "body": body, "more_body": False}

        await self.app(scope, replay, send)
