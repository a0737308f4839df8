"""What the operator console reads besides the archive: the server's constants, who the caller is, and the
dictionary entry (units, description, enumeration, limits) of every archived parameter of a satellite."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Query
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES
from backend.deps import ServicesDep, ViewerDep
from backend.schemas import NAME_MAX, Caller, ConsoleConstants, ParametersInfo, ShelveRequest
from backend.twin.twin_sessions import GPS_MARGIN_S

router = APIRouter(tags=["console"], responses=ERROR_RESPONSES)

SEVERITIES = {"yellow": "warning", "red": "critical"}


@router.get("/constants", response_model=ConsoleConstants, summary="Constants the console shares with the server")
def constants(services: ServicesDep, _: ViewerDep) -> dict[str, Any]:
    """Values the dashboard must not copy: twin orbit-fit margin, staleness, answer and shelving bounds."""
    settings = services.settings
    shelve = ShelveRequest.model_fields["duration_s"].metadata
    return {
        "gps_margin_s": GPS_MARGIN_S,
        "stale_after_s": services.twins.stale_after_s,  # the live twins' own threshold: one home for "stale"
        "max_points": settings.max_points,
        "ws_rate_hz": settings.ws_rate_hz,
        "shelve_max_s": next(m.le for m in shelve if getattr(m, "le", None) is not None),
        "severities": SEVERITIES,
        "auth_enabled": settings.auth_enabled,
    }


@router.get("/whoami", response_model=Caller, summary="The caller's name and role")
def whoami(principal: ViewerDep) -> dict[str, Any]:
    """Name and role of the token (the console greys out what the role may not do)."""
    return {"name": principal.name, "role": principal.role.name}


@router.get("/parameters/info", response_model=ParametersInfo, summary="Dictionary entry of each archived parameter")
async def parameters_info(
    services: ServicesDep, _: ViewerDep, satellite: str = Query("NOAA-20", min_length=1, max_length=NAME_MAX)
) -> dict[str, Any]:
    """{name: {units, description, enumeration, limits}} from the dictionaries that define the satellite's names."""
    archived = await run_in_threadpool(services.telemetry.archive.parameters, satellite)
    return await run_in_threadpool(services.telemetry.dictionaries.describe, archived)
