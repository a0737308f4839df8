"""Twin sessions: start a simulation aligned to telemetry with a fault hypothesis; residuals vs telemetry."""

from __future__ import annotations

from fastapi import APIRouter, Query
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES
from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.schemas import ResidualsPublic, TwinSessionCreate, TwinSessionPublic
from backend.twin.session_service import session_public, session_residuals, session_row, start_session

router = APIRouter(tags=["twin"], responses=ERROR_RESPONSES)


@router.post(
    "/twin/sessions",
    status_code=202,
    response_model=TwinSessionPublic,
    summary="Start a twin session from archived telemetry",
)
async def create_session(body: TwinSessionCreate, services: ServicesDep, principal: OperatorDep) -> TwinSessionPublic:
    """Align the twin to telemetry at align_utc, fly it with the hypothesis (a simulation job)."""
    session = await run_in_threadpool(start_session, services, body, principal.name)
    await run_in_threadpool(
        services.audit.record, principal.name, "twin.create", f"twin/{session.id}", {"faults": body.faults}
    )
    return session


@router.get("/twin/sessions", response_model=list[TwinSessionPublic], summary="Twin sessions, newest first")
def list_sessions(
    services: ServicesDep, _: ViewerDep, limit: int = Query(100, ge=1, le=1000)
) -> list[TwinSessionPublic]:
    """Sessions with the state of their simulation."""
    return [session_public(services, row) for row in services.twin_sessions.list(limit)]


@router.get("/twin/sessions/{session_id}", response_model=TwinSessionPublic, summary="One twin session")
def get_session(session_id: str, services: ServicesDep, _: ViewerDep) -> TwinSessionPublic:
    """The session and the state of its simulation."""
    return session_public(services, session_row(services, session_id))


@router.get(
    "/twin/sessions/{session_id}/residuals", response_model=ResidualsPublic, summary="Twin minus telemetry residuals"
)
async def get_residuals(
    session_id: str,
    services: ServicesDep,
    _: ViewerDep,
    variant: int = Query(0, ge=0, le=15, description="0 = the twin, then the alternatives."),
    max_points: int = Query(1000, ge=2, le=100_000),
) -> ResidualsPublic:
    """Attitude angle (deg), rate difference (deg/s), wheel-speed differences (rpm) of one variant, downsampled;
    the summary of every variant (the what-if comparison); published on 'twin'."""
    answer = await run_in_threadpool(session_residuals, services, session_id, variant, max_points)
    services.hub.publish("twin", {"session_id": session_id, "summaries": answer.summaries})
    return answer
