"""Satellites the archive knows and the state of each one's live twin (backend.twin.live)."""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter, Path
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.deps import ServicesDep, ViewerDep
from backend.schemas import NAME_MAX, LiveTwinPublic, SatellitePublic
from backend.twin.live import TWIN_APID

router = APIRouter(tags=["satellites"], responses=ERROR_RESPONSES)


def _iso(t_ns: int | None) -> str | None:
    return None if t_ns is None else f"{np.datetime64(int(t_ns), 'ns').astype('datetime64[ms]')}Z"


@router.get("/satellites", response_model=list[SatellitePublic], summary="Every satellite the archive knows")
async def list_satellites(services: ServicesDep, _: ViewerDep) -> list[SatellitePublic]:
    """Satellites by name with their oldest and newest archived telemetry (the twin's residuals not counted) and
    the state of their live twin; a satellite registered without telemetry has ``latest_telemetry_utc`` null."""
    rows = await run_in_threadpool(services.telemetry.archive.satellites, (TWIN_APID,))
    out = []
    for row in rows:
        twin = services.twins.state(row["name"]) or {}
        out.append(
            SatellitePublic(
                name=row["name"],
                norad_id=row["norad_id"],
                first_telemetry_utc=_iso(row["first_t_ns"]),
                latest_telemetry_utc=_iso(row["last_t_ns"]),
                twin_state=twin.get("state"),
                acs_model=twin.get("acs_model"),
            )
        )
    return out


@router.get("/satellites/{name}/twin", response_model=LiveTwinPublic, summary="The live twin of one satellite")
def get_twin(
    services: ServicesDep, _: ViewerDep, name: str = Path(min_length=1, max_length=NAME_MAX, examples=["REFSAT"])
) -> dict[str, Any]:
    """State of the satellite's live twin; the same object is published on the WebSocket topic ``twin`` whenever a
    telemetry batch has been compared and once when the satellite turns stale.

    Shape: ``satellite``, ``dictionary``, ``acs_model`` (library scenario, null without ACS model) and
    ``model_note`` (why there is no twin, else null); ``state`` (waiting | synchronised | propagating | stale |
    actual_only), ``stale`` (bool), ``last_packet_age_s`` (s since telemetry last reached the server),
    ``stale_after_s``; ``telemetry_utc`` (newest actual sample), ``twin_utc`` (newest instant the twin was compared
    at), ``twin_behind_telemetry_s``, ``synchronised_utc`` (last re-sync instant), ``horizon_utc`` (end of the flown
    segment), all ISO 8601 UTC or null; ``actual_q_ib`` and ``twin_q_ib`` (scalar-first, body→inertial);
    ``attitude_residual_arcsec`` (actual vs twin at ``twin_utc``; null without ACS model),
    ``rate_residual_b_rad_s`` [x, y, z], ``wheel_speed_residual_rad_s`` [one per wheel] (twin minus telemetry);
    ``resyncs``, ``forced_resyncs`` (residual beyond the sensors' noise), ``samples_compared``; ``issues``: the
    newest bad-input findings ``{kind: mapping | time_backwards | gap | quaternion | sync | residual, message, utc,
    count}``. The residuals are archived parameters too: ``twin_attitude_residual_arcsec``,
    ``twin_rate_residual_b_rad_s_{x,y,z}``, ``twin_wheel_speed_residual_rad_s_{1..n}`` (samples, exports, alarms
    and ``parameters/<name>`` topics like any other parameter).
    """
    state = services.twins.state(name)
    if state is not None:
        return state
    known = {row["name"] for row in services.telemetry.archive.satellites((TWIN_APID,))}
    if name not in known:
        raise ApiError(404, f"no satellite {name!r} in the archive", "name")
    raise ApiError(
        404,
        f"satellite {name!r} has no live twin: no attitude mapping (<dictionary>.attitude.yaml) "
        "fits its dictionary, or no telemetry arrived since the server started",
        "name",
    )
