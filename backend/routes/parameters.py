"""Archived parameters: list, latest values, downsampled samples and CSV/Parquet exports."""

from __future__ import annotations

import re
from datetime import datetime
from typing import Any, Literal

from fastapi import APIRouter, Query
from fastapi.responses import Response, StreamingResponse
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.core.time import EARLIEST_NS, LATEST_NS, utc_ns
from backend.deps import ServicesDep, ViewerDep
from backend.schemas import NAME_MAX, PARQUET_MEDIA_TYPE, SATELLITE_NAME, LatestValues, ParameterApids, SamplesPublic

router = APIRouter(tags=["parameters"], responses=ERROR_RESPONSES)

SatelliteQuery = Query("NOAA-20", min_length=1, max_length=NAME_MAX, pattern=SATELLITE_NAME, examples=["NOAA-20"])
MAX_EXPORT_PARAMETERS = 200


def _window(start: datetime | None, end: datetime | None) -> tuple[int, int]:
    t0, t1 = utc_ns(start, EARLIEST_NS), utc_ns(end, LATEST_NS)
    if t1 < t0:
        raise ApiError(422, "end: before start", "end")
    return t0, t1


@router.get("/parameters", response_model=ParameterApids, summary="Archived parameters and their APID")
def list_parameters(services: ServicesDep, _: ViewerDep, satellite: str = SatelliteQuery) -> dict[str, int]:
    """Every parameter name archived for the satellite."""
    return services.telemetry.archive.parameters(satellite)


@router.get("/parameters/latest", response_model=LatestValues, summary="Newest value of each parameter")
def latest_values(services: ServicesDep, _: ViewerDep, satellite: str = SatelliteQuery) -> dict[str, Any]:
    """{name: {t_utc_ns, value}} for every archived parameter."""
    latest = services.telemetry.archive.latest_values(satellite)
    return {name: {"t_utc_ns": t, "value": v} for name, (t, v) in latest.items()}


@router.get("/parameters/{name}/samples", response_model=SamplesPublic, summary="Samples of one parameter")
async def samples(
    name: str,
    services: ServicesDep,
    _: ViewerDep,
    satellite: str = SatelliteQuery,
    start: datetime | None = Query(None, examples=["2021-04-09T00:00:00Z"]),
    end: datetime | None = Query(None, examples=["2021-04-09T02:00:00Z"]),
    max_points: int = Query(1000, ge=2, le=100_000),
) -> Response:
    """Samples in [start, end] (ISO 8601 UTC), min/max-bucket downsampled to at most max_points.

    Answers (and archived series) are cached until ingested data overlaps them; a hit never leaves the event loop.
    """
    t0, t1 = _window(start, end)
    args = (satellite, name, t0, t1, min(max_points, services.settings.max_points))
    body = services.telemetry.samples_from_memory(*args)
    if body is None:
        body = await run_in_threadpool(services.telemetry.samples_json, *args)
    return Response(body, media_type="application/json")


@router.get(
    "/exports/samples",
    summary="Export every sample as CSV or Parquet (t_utc + one column per parameter)",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/csv": {}, PARQUET_MEDIA_TYPE: {}}}},
)
def export_samples(
    services: ServicesDep,
    _: ViewerDep,
    satellite: str = SatelliteQuery,
    names: str = Query(
        ...,
        min_length=1,
        max_length=MAX_EXPORT_PARAMETERS * 129,
        examples=["q_ib_0,q_ib_1"],
        description=f"Comma-separated parameter names (at most {MAX_EXPORT_PARAMETERS}).",
    ),
    start: datetime | None = None,
    end: datetime | None = None,
    format: Literal["csv", "parquet"] = "csv",
) -> StreamingResponse:
    """Full resolution, the same rows as ``acs-twin export``: ``t_utc`` (ISO 8601 UTC, ns) and one column per named
    parameter (empty where not sampled), read and streamed window by window (bounded memory, nothing spooled).
    A window whose archive chunks may hold more than max_export_rows rows is a 422 naming ``end``."""
    from telemetry.export import csv_chunks, parquet_chunks

    wanted = [n.strip() for n in names.split(",") if n.strip()]
    if not wanted or len(wanted) > MAX_EXPORT_PARAMETERS:
        raise ApiError(422, f"names: give 1..{MAX_EXPORT_PARAMETERS} parameter names", "names")
    t0, t1 = _window(start, end)
    schema, batches = services.telemetry.export_stream(satellite, wanted, t0, t1)
    filename = re.sub(r"[^A-Za-z0-9._-]+", "_", satellite)  # a header value carries no CR/LF, quote or path
    headers = {"Content-Disposition": f'attachment; filename="{filename}-samples.{format}"'}
    if format == "csv":
        return StreamingResponse(csv_chunks(schema, batches), media_type="text/csv", headers=headers)
    return StreamingResponse(parquet_chunks(schema, batches), media_type=PARQUET_MEDIA_TYPE, headers=headers)
