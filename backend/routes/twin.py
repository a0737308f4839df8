"""Twin sessions: start a simulation aligned to telemetry with a fault hypothesis; residuals vs telemetry."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Any

import numpy as np
from fastapi import APIRouter, Query
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.downsampling import minmax_indices
from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.core.time import utc_ns

router = APIRouter(tags=["twin"], responses=ERROR_RESPONSES)

NS_PER_S = 1_000_000_000


class TwinSessionCreate(BaseModel):
    """Where to align the twin, how long to fly it, and the operator's fault hypothesis."""

    satellite: str = Field("REFSAT", min_length=1, max_length=100)
    dictionary: str = Field("reference_satellite.yaml", max_length=130)
    scenario: str = Field("somov-ge4-scan", max_length=100, description="Library scenario the satellite flies.")
    align_utc: datetime = Field(description="Start of the twin (the first ACS_HK sample at or after it).",
                                examples=["2026-03-20T00:05:00Z"])
    duration_s: float = Field(gt=0, le=86_400, examples=[200.0])
    alternatives: dict[str, list[str]] = Field(default_factory=dict, max_length=15,
                                               examples=[{"nominal": [], "wheel-2-fails": ["wheel:2:failure@30"]}],
                                               description="What-if variants flown from the same state.")
    scenario_epoch_utc: datetime | None = Field(None, description="When the satellite started the scenario's "
                                                "route (default: the library scenario's epoch).")
    faults: list[str] = Field(default_factory=list, max_length=16, examples=[["wheel:1:failure@50"]],
                              description="Hypothesis, TARGET:INDEX:TYPE@ONSET[+DUR][,gain=G|,value=V] "
                                          "(onset in s after align).")


def _session_public(services: Any, row: Any) -> dict[str, Any]:
    job = services.job_repo.get(row.job_id)
    return {"id": row.id, "satellite": row.satellite, "scenario": row.scenario, "align_utc_ns": row.align_utc_ns,
            "duration_s": row.duration_s, "faults": row.faults, "created_by": row.created_by,
            "variants": ["twin", *row.alternatives],
            "job_id": row.job_id, "status": job.status if job else "unknown",
            "progress": services.jobs.progress(row.job_id) or (job.progress if job else 0.0)}


def start_session(services: Any, body: TwinSessionCreate, actor: str) -> dict[str, Any]:
    """Align a twin to archived telemetry and queue its simulation; the session as answered by the API."""
    from backend.twin.twin_sessions import GPS_MARGIN_S, actual_track_between, twin_start

    align_ns = utc_ns(body.align_utc, 0)
    dictionary = services.telemetry.dictionaries.load(body.dictionary)
    track = actual_track_between(services.telemetry.archive, dictionary, body.satellite,
                                 align_ns - int(GPS_MARGIN_S * NS_PER_S), align_ns + int(body.duration_s * NS_PER_S))
    epoch_ns = None if body.scenario_epoch_utc is None else utc_ns(body.scenario_epoch_utc, 0)
    t_align, scenario, options = twin_start(track, body.scenario, align_ns, body.duration_s, body.faults, epoch_ns,
                                            body.alternatives)
    job_id = services.jobs.submit(scenario, actor, options)
    row = services.twin_sessions.add(id=uuid.uuid4().hex, job_id=job_id, satellite=body.satellite,
                                     dictionary=body.dictionary, scenario=body.scenario, align_utc_ns=t_align,
                                     duration_s=body.duration_s, faults=body.faults, alternatives=body.alternatives,
                                     created_by=actor)
    return _session_public(services, row)


@router.post("/twin/sessions", status_code=202, summary="Start a twin session from archived telemetry")
async def create_session(body: TwinSessionCreate, services: ServicesDep, principal: OperatorDep) -> dict[str, Any]:
    """Align the twin to telemetry at align_utc, fly it with the hypothesis (a simulation job)."""
    session = await run_in_threadpool(start_session, services, body, principal.name)
    services.audit.record(principal.name, "twin.create", f"twin/{session['id']}", {"faults": body.faults})
    return session


@router.get("/twin/sessions", summary="Twin sessions, newest first")
def list_sessions(services: ServicesDep, _: ViewerDep, limit: int = Query(100, ge=1, le=1000)) -> list[dict[str, Any]]:
    """Sessions with the state of their simulation."""
    return [_session_public(services, row) for row in services.twin_sessions.list(limit)]


def _row(services: Any, session_id: str) -> Any:
    row = services.twin_sessions.get(session_id)
    if row is None:
        raise ApiError(404, f"no twin session {session_id!r}", "session_id")
    return row


@router.get("/twin/sessions/{session_id}", summary="One twin session")
def get_session(session_id: str, services: ServicesDep, _: ViewerDep) -> dict[str, Any]:
    """The session and the state of its simulation."""
    return _session_public(services, _row(services, session_id))


def session_feed(services: Any, session_id: str) -> Any:
    """The monitors' TwinFeed of a finished session (telemetry of its window against its twin)."""
    from backend.twin.twin_feed import SessionFeed
    from backend.twin.twin_sessions import actual_track_between

    row = _row(services, session_id)
    job = services.job_repo.get(row.job_id)
    if job is None or job.status != "succeeded":
        raise ApiError(409, f"twin simulation is {job.status if job else 'missing'}", "session_id")
    dictionary = services.telemetry.dictionaries.load(row.dictionary)
    t1 = row.align_utc_ns + int(row.duration_s * NS_PER_S)
    track = actual_track_between(services.telemetry.archive, dictionary, row.satellite, row.align_utc_ns, t1)
    alarms = services.telemetry.archive.alarms(row.satellite, include_cleared=True)
    return SessionFeed(track, services.jobs.result_dir(row.job_id) / "trajectory.npz", row.align_utc_ns, alarms)


def _residuals(services: Any, row: Any) -> tuple[list[str], list[Any]]:
    from backend.twin.twin_sessions import actual_track_between, residuals, variant_names

    job = services.job_repo.get(row.job_id)
    if job is None or job.status != "succeeded":
        raise ApiError(409, f"twin simulation is {job.status if job else 'missing'}: residuals once it succeeded",
                       "session_id")
    dictionary = services.telemetry.dictionaries.load(row.dictionary)
    t1 = row.align_utc_ns + int(row.duration_s * NS_PER_S)
    track = actual_track_between(services.telemetry.archive, dictionary, row.satellite, row.align_utc_ns, t1)
    npz = services.jobs.result_dir(row.job_id) / "trajectory.npz"
    names = variant_names(npz)
    return names, [residuals(track, npz, row.align_utc_ns, v) for v in range(len(names))]


@router.get("/twin/sessions/{session_id}/residuals", summary="Twin minus telemetry residuals")
async def get_residuals(session_id: str, services: ServicesDep, _: ViewerDep,
                        variant: int = Query(0, ge=0, le=15, description="0 = the twin, then the alternatives."),
                        max_points: int = Query(1000, ge=2, le=100_000)) -> dict[str, Any]:
    """Attitude angle (deg), rate difference (deg/s), wheel-speed differences (rpm) of one variant, downsampled;
    the summary of every variant (the what-if comparison); published on 'twin'."""
    row = _row(services, session_id)
    names, found = await run_in_threadpool(_residuals, services, row)
    if variant >= len(names):
        raise ApiError(422, f"variant: {variant} outside 0..{len(names) - 1}", "variant")
    chosen = found[variant]
    columns = np.column_stack([np.degrees(chosen.attitude_rad), np.degrees(chosen.rate_rad_s),
                               chosen.wheel_speed_rad_s * 30.0 / np.pi])
    keep = minmax_indices(columns, max_points) if chosen.t_s.size else np.arange(0)
    summaries = {name: r.summary() for name, r in zip(names, found)}
    answer = {"session_id": session_id, "variant": names[variant], "summary": summaries[names[variant]],
              "summaries": summaries, "t_s": chosen.t_s[keep].tolist(), "attitude_deg": columns[keep, 0].tolist(),
              "rate_deg_s": columns[keep, 1].tolist(), "wheel_speed_rpm": columns[keep, 2:].tolist()}
    services.hub.publish("twin", {"session_id": session_id, "summaries": summaries})
    return answer
