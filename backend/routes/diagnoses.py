"""Diagnoses: start one on a satellite and telemetry window, poll it, read the ranked hypotheses."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.schemas import NAME_MAX, DbId, DiagnosisCreate, DiagnosisPublic
from backend.twin.diagnosis import start_archived

router = APIRouter(tags=["diagnosis"], responses=ERROR_RESPONSES)


@router.post(
    "/diagnoses", status_code=202, response_model=DiagnosisPublic, summary="Diagnose archived telemetry of a satellite"
)
async def create_diagnosis(body: DiagnosisCreate, services: ServicesDep, principal: OperatorDep) -> DiagnosisPublic:
    """Detect, name and rank the fault in [start_utc, end_utc]; poll GET /diagnoses/{id} for the result."""
    telemetry = services.telemetry
    run = await run_in_threadpool(
        start_archived, services.diagnoses, telemetry.archive, telemetry.dictionaries.load, body, principal.name
    )
    target, details = f"diagnoses/{run['id']}", {"satellite": body.satellite}
    await run_in_threadpool(services.audit.record, principal.name, "diagnosis.create", target, details)
    return DiagnosisPublic(**run)


@router.get("/diagnoses", response_model=list[DiagnosisPublic], summary="Diagnoses, newest first")
def list_diagnoses(
    services: ServicesDep,
    _: ViewerDep,
    alarm_id: Annotated[DbId | None, Query(description="Only the diagnosis this alarm started.")] = None,
    satellite: str | None = Query(None, min_length=1, max_length=NAME_MAX),
) -> list[DiagnosisPublic]:
    """The stored diagnoses (the newest 200), with their state and result."""
    return [DiagnosisPublic(**r) for r in services.diagnoses.list(alarm_id=alarm_id, satellite=satellite)]


@router.get("/diagnoses/{diagnosis_id}", response_model=DiagnosisPublic, summary="One diagnosis")
def get_diagnosis(diagnosis_id: str, services: ServicesDep, _: ViewerDep) -> DiagnosisPublic:
    """State (running, succeeded, failed with the reason) and, once succeeded, the ranked hypotheses."""
    run = services.diagnoses.get(diagnosis_id)
    if run is None:
        raise ApiError(404, f"no diagnosis {diagnosis_id!r}", "diagnosis_id")
    return DiagnosisPublic(**run)
