"""GET /api/v1/health: liveness, version and which parts are plugged in."""

from __future__ import annotations

from functools import cache
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter

from backend.core.errors import ApiError, ErrorBody
from backend.deps import ServicesDep
from backend.schemas import Health

router = APIRouter(tags=["health"])

DATABASE_STALE_S = 10.0  # health is 503 once the database watch has had no answer for this long (it asks every 1 s)


@cache
def _version() -> str:
    """The installed package's version, looked up once (a scan of every path entry's metadata: milliseconds)."""
    try:
        return version("acs-twin")
    except PackageNotFoundError:
        return "0+unknown"


@router.get(
    "/health",
    response_model=Health,
    summary="Liveness (no token needed)",
    responses={503: {"model": ErrorBody, "description": "The database answered no round trip for DATABASE_STALE_S"}},
)
async def health(services: ServicesDep) -> Health:
    """Ok while the database answers (its watch made a round trip within DATABASE_STALE_S), else 503 naming
    ``database``. Answered on the event loop alone, from figures in memory: it waits for neither a worker thread
    nor the database, so a busy server (a large upload, a full thread pool) answers it within one loop turn."""
    age_s, error = services.database_watch.last_answer()
    if age_s is None or age_s > DATABASE_STALE_S:
        silence = "yet" if age_s is None else f"for {age_s:.0f} s"
        raise ApiError(503, f"database: no answer {silence} ({error})", "database")
    return Health(
        version=_version(),
        database=services.engine.dialect.name,
        auth_enabled=services.settings.auth_enabled,
        components=services.telemetry.components(),
        live=services.telemetry.live_stats(),
        twins=services.twins.backlog(),
    )
