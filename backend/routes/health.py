"""GET /api/v1/health: liveness, version and which parts are plugged in."""

from __future__ import annotations

from functools import cache
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter
from sqlalchemy import text

from backend.deps import ServicesDep
from backend.schemas import Health

router = APIRouter(tags=["health"])


@cache
def _version() -> str:
    """The installed package's version, looked up once (a scan of every path entry's metadata: milliseconds)."""
    try:
        return version("acs-twin")
    except PackageNotFoundError:
        return "0+unknown"


@router.get("/health", response_model=Health, summary="Liveness (no token needed)")
def health(services: ServicesDep) -> Health:
    """Answer ok after a round trip to the database."""
    with services.engine.connect() as connection:
        connection.execute(text("SELECT 1"))
    return Health(
        version=_version(),
        database=services.engine.dialect.name,
        auth_enabled=services.settings.auth_enabled,
        components=services.telemetry.components(),
        live=services.telemetry.live_stats(),
        twins=services.twins.backlog(),
    )
