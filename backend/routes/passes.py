"""Satellites, ground stations, TLE upload, passes (listed, by id) and pass prediction."""

from __future__ import annotations

from dataclasses import asdict
from datetime import datetime
from typing import Any

from fastapi import APIRouter, Query, Request
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.core.time import EARLIEST_NS, LATEST_NS, utc_ns
from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.routes.telemetry import read_limited
from backend.schemas import (
    NAME_MAX,
    SATELLITE_NAME,
    DbId,
    PassPublic,
    PassSummaryPublic,
    SatelliteCreate,
    SatelliteCreated,
    SatelliteName,
    StationCreate,
    StationName,
    TlePublic,
    TleStored,
)
from backend.services import Services
from telemetry.archive.records import PassRecord, StationRecord

router = APIRouter(tags=["passes"], responses=ERROR_RESPONSES)

SatelliteQuery = Query("NOAA-20", min_length=1, max_length=NAME_MAX, pattern=SATELLITE_NAME, examples=["NOAA-20"])
MAX_TLE_BYTES = 64_000
TLE_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "text/plain": {
                "schema": {"type": "string"},
                "example": "NOAA 20\n1 43013U 17073A   21099.50000000  .00000012  00000-0  26000-4 0  9991\n"
                "2 43013  98.7200  40.0000 0001500  90.0000 270.0000 14.19550000177000",
            }
        },
    }
}


def _pass_public(record: PassRecord) -> dict[str, Any]:
    return {**asdict(record), "completeness": record.completeness}


@router.post("/satellites", status_code=201, response_model=SatelliteCreated, summary="Register a satellite")
def create_satellite(body: SatelliteCreate, services: ServicesDep, principal: OperatorDep) -> dict[str, Any]:
    """Id of the satellite (created on first use)."""
    sat_id = services.telemetry.archive.satellite_id(body.name, body.norad_id)
    services.audit.record(principal.name, "satellite.create", f"satellite/{body.name}")
    return {"id": sat_id, "name": body.name}


def _tle_lines(text: str) -> tuple[str, str, int]:
    from sgp4.api import Satrec

    lines = [ln.rstrip() for ln in text.splitlines() if ln.strip()]
    pair = [ln for ln in lines if ln[:2] in ("1 ", "2 ")]
    if len(pair) != 2 or not pair[0].startswith("1 ") or not pair[1].startswith("2 "):
        raise ApiError(422, "body: expected a TLE (optional name line, then lines 1 and 2)", "body")
    satrec = Satrec.twoline2rv(pair[0], pair[1])
    if satrec.error:
        raise ApiError(422, f"body: TLE rejected by SGP4 (error {satrec.error})", "body")
    epoch_ns = round(((satrec.jdsatepoch - 2440587.5) + satrec.jdsatepochF) * 86_400e9)
    return pair[0], pair[1], int(epoch_ns)


@router.post(
    "/satellites/{name}/tles", status_code=201, response_model=TleStored, summary="Upload a TLE", openapi_extra=TLE_BODY
)
async def upload_tle(
    name: SatelliteName, request: Request, services: ServicesDep, principal: OperatorDep
) -> dict[str, Any]:
    """Store a two-line element set (epoch read by SGP4)."""
    text = (await read_limited(request, MAX_TLE_BYTES)).decode("ascii", errors="replace")
    line1, line2, epoch_ns = _tle_lines(text)
    tle_id = await run_in_threadpool(_store_tle, services, principal.name, name, line1, line2, epoch_ns)
    return {"id": tle_id, "satellite": name, "epoch_utc_ns": epoch_ns}


def _store_tle(services: Services, caller: str, name: str, line1: str, line2: str, epoch_ns: int) -> int:
    """Id of the TLE archived for ``name``, with its audit row (blocking: the database; call from a thread)."""
    tle_id = services.telemetry.archive.add_tle(name, line1, line2, epoch_ns)
    services.audit.record(caller, "tle.upload", f"satellite/{name}", {"tle_id": tle_id})
    return tle_id


@router.get("/satellites/{name}/tle", response_model=TlePublic, summary="Newest TLE of a satellite")
def latest_tle(name: SatelliteName, services: ServicesDep, _: ViewerDep) -> dict[str, Any]:
    """The most recent TLE (id and lines)."""
    tle_id, line1, line2 = services.telemetry.archive.latest_tle(name)
    return {"id": tle_id, "line1": line1, "line2": line2}


@router.post(
    "/ground-stations", status_code=201, response_model=StationRecord, summary="Register or update a ground station"
)
def create_station(body: StationCreate, services: ServicesDep, principal: OperatorDep) -> dict[str, Any]:
    """Id of the station."""
    station_id = services.telemetry.archive.add_ground_station(
        body.name, body.lat_deg, body.lon_deg, body.alt_m, body.min_elevation_deg
    )
    services.audit.record(principal.name, "station.upsert", f"ground-station/{body.name}")
    return {"id": station_id, **body.model_dump()}


@router.get("/ground-stations/{name}", response_model=StationRecord, summary="One ground station")
def get_station(name: StationName, services: ServicesDep, _: ViewerDep) -> dict[str, Any]:
    """Location and elevation mask."""
    return asdict(services.telemetry.archive.ground_station(name))


@router.get("/passes", response_model=list[PassPublic], summary="Passes of a satellite in a time window")
def list_passes(
    services: ServicesDep,
    _: ViewerDep,
    satellite: str = SatelliteQuery,
    start: datetime | None = None,
    end: datetime | None = None,
) -> list[dict[str, Any]]:
    """Predicted passes with what was received (completeness = received / expected packets)."""
    records = services.telemetry.archive.passes(satellite, utc_ns(start, EARLIEST_NS), utc_ns(end, LATEST_NS))
    return [_pass_public(r) for r in records]


@router.get("/passes/{pass_id}", response_model=PassPublic, summary="One pass")
def get_pass(pass_id: DbId, services: ServicesDep, _: ViewerDep, satellite: str = SatelliteQuery) -> dict[str, Any]:
    """The pass with this id (of the given satellite)."""
    try:
        return _pass_public(services.telemetry.archive.pass_record(satellite, pass_id))
    except ValueError as exc:
        raise ApiError(404, str(exc), str(exc).split(":", 1)[0]) from exc


@router.get(
    "/passes/{pass_id}/summary", response_model=PassSummaryPublic, summary="Pass summary: reception, statistics, alarms"
)
def pass_summary(pass_id: DbId, services: ServicesDep, _: ViewerDep, satellite: str = SatelliteQuery) -> dict[str, Any]:
    """Completeness, per-parameter count/min/max/mean and the alarms raised during the pass."""
    summary = services.telemetry.pass_summary(satellite, pass_id)
    return {**summary, "pass": _pass_public(summary["pass"]), "alarms": [asdict(a) for a in summary["alarms"]]}


@router.post(
    "/satellites/{name}/passes/reception",
    response_model=list[PassPublic],
    summary="Recount reception of passes in a window",
)
def record_reception(
    name: SatelliteName,
    services: ServicesDep,
    principal: OperatorDep,
    start: datetime | None = None,
    end: datetime | None = None,
) -> list[dict[str, Any]]:
    """Per pass: received span, packets and missing packets (sequence-count gaps) → completeness."""
    records = services.telemetry.record_reception(name, utc_ns(start, EARLIEST_NS), utc_ns(end, LATEST_NS))
    services.audit.record(principal.name, "passes.reception", f"satellite/{name}", {"passes": len(records)})
    return [_pass_public(r) for r in records]


@router.post(
    "/satellites/{name}/passes/predict",
    response_model=list[PassPublic],
    summary="Predict passes over a station from the TLE",
)
def predict_passes(
    name: SatelliteName,
    services: ServicesDep,
    principal: OperatorDep,
    station: str = Query(..., min_length=1, max_length=NAME_MAX),
    start: datetime = Query(...),
    end: datetime = Query(...),
) -> list[dict[str, Any]]:
    """Passes of the newest TLE over the station in [start, end], stored and returned."""
    passes = services.telemetry.predict_passes(name, station, utc_ns(start, 0), utc_ns(end, 0))
    services.audit.record(principal.name, "passes.predict", f"satellite/{name}", {"station": station})
    return [_pass_public(p) for p in passes]
