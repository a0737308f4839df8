"""Errors of the API as JSON ``{"message", "field", "status"}``, replacing FastAPI's defaults."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ValidationError

if TYPE_CHECKING:  # FastAPI is imported where it answers: ApiError is raised in the server's own processes too
    from fastapi import FastAPI, Request
    from fastapi.responses import JSONResponse

__all__ = ["ApiError", "ErrorBody", "install_error_handlers", "ERROR_RESPONSES", "described_pattern"]

_PATTERN_MEANINGS: dict[str, str] = {}


def described_pattern(pattern: str, meaning: str) -> str:
    """``pattern`` (returned as given, to declare on a field), with what it means in words: a value that does not
    match is a 422 saying "must be <meaning>" instead of quoting the regular expression."""
    _PATTERN_MEANINGS[pattern] = meaning
    return pattern


class ErrorBody(BaseModel):
    """Body of every error answer: what went wrong, which input field, the HTTP status."""

    message: str
    field: str | None = None
    status: int


class ApiError(Exception):
    """An error to answer with ``status``; ``field`` names the offending input."""

    def __init__(
        self, status: int, message: str, field: str | None = None, headers: dict[str, str] | None = None
    ) -> None:
        super().__init__(message)
        self.status, self.message, self.field, self.headers = status, message, field, headers

    def __reduce__(self) -> tuple[type[ApiError], tuple[int, str, str | None, dict[str, str] | None]]:
        """Pickled whole (it crosses from the upload decoder's process to the server)."""
        return ApiError, (self.status, self.message, self.field, self.headers)


ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorBody, "description": text}
    for code, text in [
        (401, "Missing or unknown token"),
        (403, "Role too low"),
        (404, "Not found"),
        (409, "Conflicts with the current state"),
        (413, "Body over max_upload_mb"),
        (422, "Invalid input or over a limit"),
        (429, "Job queue full (see Retry-After)"),
        (503, "A telemetry component is not available in this build"),
    ]
}


def _json(status: int, message: str, field: str | None, headers: dict[str, str] | None = None) -> JSONResponse:
    from fastapi.responses import JSONResponse

    body = ErrorBody(message=message, field=field, status=status).model_dump()
    return JSONResponse(body, status_code=status, headers=headers)


def _message(error: Any) -> str:
    """A validation error's message; a declared pattern said in words where :func:`described_pattern` gave them."""
    if error.get("type") == "string_pattern_mismatch":
        meaning = _PATTERN_MEANINGS.get((error.get("ctx") or {}).get("pattern", ""))
        if meaning is not None:
            return f"must be {meaning}"
    return str(error.get("msg"))


def _field_of(loc: Sequence[int | str]) -> str | None:
    parts = [str(p) for p in loc if p not in ("body", "query", "path", "header", "cookie")]
    return ".".join(parts) or (str(loc[0]) if loc else None)


async def _on_api_error(_: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ApiError)
    return _json(exc.status, exc.message, exc.field, exc.headers)


async def _on_validation(_: Request, exc: Exception) -> JSONResponse:
    from fastapi.exceptions import RequestValidationError

    assert isinstance(exc, RequestValidationError)
    first = exc.errors()[0] if exc.errors() else {"loc": (), "msg": "invalid request"}
    loc = tuple(first.get("loc", ()))
    if len(loc) == 3 and loc[0] == "query" and isinstance(loc[2], int):  # one value of a repeated key (?apid=1&apid=2)
        key, value = str(loc[1]), str(first.get("input"))[:40]
        return _json(422, f"{key}: {value} (value {loc[2] + 1} of the repeated {key}): {_message(first)}", key)
    field = _field_of(loc)
    return _json(422, f"{field}: {_message(first)}" if field else _message(first), field)


async def _on_http(_: Request, exc: Exception) -> JSONResponse:
    from starlette.exceptions import HTTPException as StarletteHTTPException

    assert isinstance(exc, StarletteHTTPException)
    return _json(exc.status_code, str(exc.detail), None, getattr(exc, "headers", None))


async def _on_pydantic(_: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ValidationError)
    first = exc.errors()[0]
    field = _field_of(first.get("loc", ())) or exc.title
    return _json(422, f"{field}: {_message(first)}", field)


async def _on_value_error(_: Request, exc: Exception) -> JSONResponse:
    message = str(exc)
    field = message.split(":", 1)[0] if ":" in message else None
    return _json(422, message, field)


def install_error_handlers(app: FastAPI) -> None:
    """Route ApiError, request/pydantic validation errors, HTTP errors and ValueError to JSON bodies."""
    from fastapi.exceptions import RequestValidationError
    from starlette.exceptions import HTTPException as StarletteHTTPException

    app.add_exception_handler(ApiError, _on_api_error)
    app.add_exception_handler(RequestValidationError, _on_validation)
    app.add_exception_handler(StarletteHTTPException, _on_http)
    app.add_exception_handler(ValidationError, _on_pydantic)
    app.add_exception_handler(ValueError, _on_value_error)
