"""Simulation jobs: submit (202), status, cancel, result files, downsampled time series, CSV/Parquet export."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, Body, Query, Request
from fastapi.openapi.models import Example
from fastapi.responses import FileResponse, StreamingResponse

from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.schemas import (
    PARQUET_MEDIA_TYPE,
    RESULT_FILE_MEDIA_TYPES,
    FilePublic,
    JobAccepted,
    JobPublic,
    ScenarioNames,
    SeriesPublic,
    SimulationCreate,
)
from backend.services import Services
from telemetry.downsampling import minmax_indices

router = APIRouter(tags=["simulations"], responses=ERROR_RESPONSES)

SCENARIO_EXAMPLES: dict[str, Example] = {
    "rigid-spin": {
        "summary": "Torque-free spin of two bodies (built-in workload)",
        "value": {
            "kind": "rigid-spin",
            "duration_s": 60.0,
            "dt_s": 0.01,
            "inertia_kg_m2": [[35.0, 30.0, 25.0], [500.0, 200.0, 300.0]],
            "omega0_rad_s": [[0.01, -0.02, 0.03], [0.5, -0.4, 0.7]],
        },
    },
    "library": {
        "summary": "A library scenario with overrides (GET /api/v1/scenarios lists them)",
        "value": {"library": "somov-ge4-scan", "set": ["duration_s=600"]},
    },
    "scenario": {
        "summary": "A full sim_core Scenario (defaults for every omitted field)",
        "value": {"name": "short-hold", "duration_s": 120.0},
    },
}


def _job(services: Services, job_id: str) -> JobPublic:
    row = services.job_repo.get(job_id)
    if row is None:
        raise ApiError(404, f"no simulation job {job_id!r}", "id")
    job = JobPublic.model_validate(row)
    live = services.jobs.progress(job_id)
    if live is not None and job.status == "running":
        job.progress = min(max(live, 0.0), 1.0)
    return job


@router.get("/scenarios", response_model=ScenarioNames, summary="Library scenarios")
def list_scenarios(_: ViewerDep) -> list[str]:
    """Names usable as ``{"library": NAME}`` in POST /simulations."""
    from backend.jobs.simulators import library_names

    return library_names()


@router.post("/simulations", response_model=JobAccepted, status_code=202, summary="Queue a simulation")
def create_simulation(
    request: Request,
    services: ServicesDep,
    principal: OperatorDep,
    scenario: Annotated[
        SimulationCreate,
        Body(
            title="SimulationCreate",
            description='A rigid spin when "kind" is "rigid-spin", else a library scenario when it has a "library" '
            "key, else a full sim_core Scenario (every omitted field takes its default).",
            openapi_examples=SCENARIO_EXAMPLES,
        ),
    ],
) -> JobAccepted:
    """Validate the scenario and its limits, queue it; poll the returned URL."""
    job_id = services.jobs.submit(scenario, principal.name)
    services.audit.record(
        principal.name, "simulation.create", f"simulation/{job_id}", {"kind": scenario.get("kind", "engine")}
    )
    return JobAccepted(id=job_id, status="queued", url=str(request.url_for("get_simulation", job_id=job_id)))


@router.get("/simulations", response_model=list[JobPublic], summary="Recent simulation jobs")
def list_simulations(services: ServicesDep, _: ViewerDep, limit: int = Query(100, ge=1, le=1000)) -> list[JobPublic]:
    """Newest first."""
    return [_job(services, row.id) for row in services.job_repo.list(limit)]


@router.get("/simulations/{job_id}", response_model=JobPublic, summary="Job status, progress, summary")
def get_simulation(job_id: str, services: ServicesDep, _: ViewerDep) -> JobPublic:
    """Status with live progress while running, summary when done."""
    return _job(services, job_id)


@router.delete("/simulations/{job_id}", response_model=JobPublic, summary="Cancel a job")
def cancel_simulation(job_id: str, services: ServicesDep, principal: OperatorDep) -> JobPublic:
    """Cancel a queued or running job (its worker process is stopped); 409 if already finished."""
    job = _job(services, job_id)
    if not services.jobs.cancel(job_id):
        raise ApiError(409, f"job {job_id} is already {job.status}", "id")
    services.audit.record(principal.name, "simulation.cancel", f"simulation/{job_id}")
    return _job(services, job_id)


def _result_dir(services: Services, job_id: str) -> Path:
    job = _job(services, job_id)
    if job.status != "succeeded":
        raise ApiError(409, f"job {job_id} is {job.status}: results exist once it succeeded", "id")
    return services.jobs.result_dir(job_id)


@router.get("/simulations/{job_id}/files", response_model=list[FilePublic], summary="Result files")
def list_files(job_id: str, request: Request, services: ServicesDep, _: ViewerDep) -> list[FilePublic]:
    """Files written by the job (trajectory.npz, summary.json, scenario.json)."""
    folder = _result_dir(services, job_id)
    return [
        FilePublic(
            name=p.name, size_bytes=p.stat().st_size, url=str(request.url_for("get_file", job_id=job_id, name=p.name))
        )
        for p in sorted(folder.iterdir())
        if p.is_file()
    ]


RESULT_FILE = {"schema": {"type": "string", "format": "binary"}}


@router.get(
    "/simulations/{job_id}/files/{name}",
    summary="Download a result file",
    response_class=FileResponse,
    responses={
        200: {
            "description": "The file's bytes, typed by its extension: summary.json and scenario.json as "
            "application/json, trajectory.npz as application/octet-stream. The time series as CSV or Parquet: "
            "GET /simulations/{job_id}/export.",
            "content": {
                "application/json": {"schema": {"type": "object"}},  # summary.json, scenario.json
                "application/octet-stream": RESULT_FILE,
            },
        }
    },
)
def get_file(job_id: str, name: str, services: ServicesDep, _: ViewerDep) -> FileResponse:
    """One result file as bytes."""
    folder = _result_dir(services, job_id)
    path = folder / name
    if "/" in name or "\\" in name or name.startswith(".") or not path.is_file():
        raise ApiError(404, f"no file {name!r} in job {job_id}", "name")
    return FileResponse(path, filename=name, media_type=RESULT_FILE_MEDIA_TYPES.get(path.suffix))


@router.get(
    "/simulations/{job_id}/export",
    summary="Export a result's time series as CSV or Parquet",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/csv": RESULT_FILE, PARQUET_MEDIA_TYPE: RESULT_FILE}}},
)
def export_result(
    job_id: str, services: ServicesDep, _: ViewerDep, format: Literal["csv", "parquet"] = "csv"
) -> StreamingResponse:
    """Every time series of trajectory.npz at full resolution, one row per batch member and sample: ``member``,
    ``t_s``, one column per component (``q_ib_0`` …); made and streamed batch by batch, nothing spooled (the
    CSV/Parquet writers of the samples export)."""
    from backend.jobs.trajectory_files import npz_rows
    from telemetry.export import csv_chunks, parquet_chunks

    schema, batches = npz_rows(_result_dir(services, job_id) / "trajectory.npz")
    headers = {"Content-Disposition": f'attachment; filename="{job_id}-trajectory.{format}"'}
    if format == "csv":
        return StreamingResponse(csv_chunks(schema, batches), media_type="text/csv", headers=headers)
    return StreamingResponse(parquet_chunks(schema, batches), media_type=PARQUET_MEDIA_TYPE, headers=headers)


def _series_columns(array: np.ndarray, n: int, member: int, name: str) -> np.ndarray:
    if array.shape[:1] == (n,):
        return array.reshape(n, -1)
    if array.ndim >= 2 and array.shape[1] == n:
        if not 0 <= member < array.shape[0]:
            raise ApiError(422, f"member {member} outside 0..{array.shape[0] - 1}", "member")
        return array[member].reshape(n, -1)
    raise ApiError(422, f"{name!r} is not a time series (shape {array.shape})", "name")


@router.get(
    "/simulations/{job_id}/series/{name}",
    response_model=SeriesPublic,
    summary="Downsampled time series of one result array",
)
def get_series(
    job_id: str,
    name: str,
    services: ServicesDep,
    _: ViewerDep,
    member: int = Query(0, ge=0, description="Batch member (fault variant)."),
    max_points: int = Query(2000, ge=2, le=100_000),
) -> SeriesPublic:
    """Array ``name`` of trajectory.npz against t_s, min/max-bucket downsampled to max_points."""
    with np.load(_result_dir(services, job_id) / "trajectory.npz") as npz:
        if name not in npz.files or name == "t_s":
            raise ApiError(404, f"no series {name!r}; available: {sorted(set(npz.files) - {'t_s'})}", "name")
        t = npz["t_s"]
        y = _series_columns(npz[name], t.size, member, name)
    keep = minmax_indices(y, max_points)
    return SeriesPublic(
        name=name,
        t_s=t[keep].tolist(),
        values=y[keep].tolist(),
        columns=[f"{name}[{i}]" for i in range(y.shape[1])],
        total_points=int(t.size),
    )
