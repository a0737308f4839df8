"""Bounds on every request before a route parses it: no NUL character in its text; JSON bodies sized, strict, shallow.

PostgreSQL's text holds no NUL (U+0000): a path, query value or JSON string with one reached the
database as a 500 (psycopg refuses it), while SQLite stored it. No name, id or field of ours
contains one, so the request is answered 422 naming where it was (``path``, the query key, the
body's field) before any route runs.

Python's json (which FastAPI uses) takes ``NaN`` and ``Infinity`` as numbers and recurses until its
stack runs out; RFC 8259 has neither. This ASGI middleware reads a JSON body (content type
``application/json`` or ``…+json``) up to ``max_bytes`` (413 beyond, read no further), checks it
with orjson (strict RFC 8259) and a depth limit, and answers 422 naming ``body`` when it fails;
a body that passes is replayed to the application unchanged.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import parse_qsl

import orjson

__all__ = ["MAX_JSON_DEPTH", "RequestBounds", "json_problem", "nul_problem"]

MAX_JSON_DEPTH = 32  # a scenario body nests 6 deep; 32 leaves room and bounds every walk of the body

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]


NUL = "\x00"
NUL_REFUSED = "holds a NUL character (U+0000), which no name, id or field of this API contains"


def nul_problem(path: str, query_string: bytes) -> tuple[str, str] | None:
    """(field, message) when the decoded path or a query key or value holds a NUL, else None."""
    if NUL in path:
        return "path", f"path: {NUL_REFUSED}"
    for key, value in parse_qsl(query_string.decode("latin-1"), keep_blank_values=True):
        if NUL in key or NUL in value:
            field = key.replace(NUL, "\\0")
            return field, f"{field}: {NUL_REFUSED}"
    return None


def _child_field(field: str, key: str | int) -> str:
    """Where a JSON value sits, dotted as a validation error's field (``faults.0``); ``body`` is the whole body."""
    return str(key) if field == "body" else f"{field}.{key}"


def _nul_place(value: Any) -> tuple[str, str] | None:
    """(field, why) of the first string or key holding a NUL, breadth first; None when there is none."""
    level: list[tuple[str, Any]] = [("body", value)]
    while level:
        for field, item in level:
            if isinstance(item, str) and NUL in item:
                return field, f"{field}: {NUL_REFUSED}"
            if isinstance(item, dict) and any(NUL in key for key in item):
                return field, f"{field}: a key {NUL_REFUSED}"
        level = [
            (_child_field(field, key), child)
            for field, item in level
            if isinstance(item, (dict, list))
            for key, child in (item.items() if isinstance(item, dict) else enumerate(item))
        ]
    return None


def json_problem(body: bytes, max_depth: int = MAX_JSON_DEPTH) -> tuple[str, str] | None:
    """(field, why) when ``body`` is not acceptable JSON (invalid, NaN/Infinity, nested deeper than max_depth, a
    string or key holding a NUL), else None; the field is ``body`` or the place in it (``faults.0``)."""
    try:
        value = orjson.loads(body)
    except orjson.JSONDecodeError as exc:
        return "body", f"body: not valid JSON (RFC 8259: no NaN or Infinity, nesting at most {max_depth}): {exc}"
    level, depth = [value], 0
    while level:
        depth += 1
        if depth > max_depth:
            return "body", f"body: JSON nested deeper than {max_depth} levels"
        level = [
            child
            for item in level
            if isinstance(item, (dict, list))
            for child in (item.values() if isinstance(item, dict) else item)
        ]
    # RFC 8259 writes a NUL in a string only as the escape \u0000 (a raw control character is invalid JSON): bodies
    # without one skip the walk that names places
    return _nul_place(value) if b"\\u0000" in body else None


def _is_json(scope: Scope) -> bool:
    for key, value in scope.get("headers", ()):
        if key == b"content-type":
            kind = value.split(b";", 1)[0].strip().lower()
            return kind == b"application/json" or kind.endswith(b"+json")
    return False


async def _answer(send: Send, status: int, message: str, field: str = "body") -> None:
    body = orjson.dumps({"message": message, "field": field, "status": status})
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())],
        }
    )
    await send({"type": "http.response.body", "body": body})


class RequestBounds:
    """ASGI middleware: no NUL in the path, query or JSON strings; JSON bodies at most ``max_bytes``, strict, at
    most MAX_JSON_DEPTH deep."""

    def __init__(self, app: Callable[[Scope, Receive, Send], Awaitable[None]], max_bytes: int) -> None:
        self.app, self.max_bytes = app, max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check the path, query and a JSON body, then hand the request on (body replayed) or answer 413/422."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if nul := nul_problem(scope.get("path", ""), scope.get("query_string", b"")):
            await _answer(send, 422, nul[1], nul[0])
            return
        if not _is_json(scope):
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
            await _answer(send, 422, problem[1], problem[0])
            return
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if replayed:
                return await receive()
            replayed = True
            return {"type": "http.request", "body": body, "more_body": False}

        await self.app(scope, replay, send)
