"""Telemetry uploads (CCSDS / CSV / JSONL, streamed, size-limited) and telemetry dictionaries."""

from __future__ import annotations

import os
import tempfile
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Any, BinaryIO, Literal

from fastapi import APIRouter, Query, Request
from fastapi import Path as PathParam
from pydantic import Field
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.ingest.dictionary_catalogue import DICTIONARY_NAME, DICTIONARY_NAME_MAX
from backend.ingest.telemetry_gateway import TelemetryGateway
from backend.schemas import (
    NAME_MAX,
    SATELLITE_NAME,
    DictionaryNames,
    DictionaryStored,
    IngestReportPublic,
    KeptRawCounts,
    RedecodeReportPublic,
)
from telemetry.archive.records import UploadRecord

router = APIRouter(tags=["telemetry"], responses=ERROR_RESPONSES)

BINARY_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/octet-stream": {"schema": {"type": "string", "format": "binary"}},
            "text/csv": {"schema": {"type": "string"}},
            "application/x-ndjson": {"schema": {"type": "string"}},
        },
    }
}
SPOOL_BLOCK_OCTETS = 4 * 2**20  # an uploaded body goes to disk in blocks of about this size, from a worker thread
DEFINITION_BODY = {
    "requestBody": {
        "required": True,
        "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}},
    }
}


async def read_limited(request: Request, max_bytes: int) -> bytes:
    """The request body read as a stream, 413 naming max_upload_mb once it grows past max_bytes."""
    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > max_bytes:
        raise ApiError(413, f"body of {int(declared)} bytes over max_upload_mb", "max_upload_mb")
    body = bytearray()
    async for chunk in request.stream():
        body.extend(chunk)
        if len(body) > max_bytes:
            raise ApiError(413, f"body over max_upload_mb ({max_bytes} bytes)", "max_upload_mb")
    if not body:
        raise ApiError(422, "body: empty upload", "body")
    return bytes(body)


async def spool_limited(request: Request, max_bytes: int, folder: Path) -> Path:
    """The request body streamed to a new file in folder (413 naming max_upload_mb past max_bytes, 422 if empty).

    The event loop only gathers the body's chunks: every SPOOL_BLOCK_OCTETS of them go to disk in a worker
    thread (the loop never waits on the disk), as the file is created and deleted there too.
    """
    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > max_bytes:
        raise ApiError(413, f"body of {int(declared)} bytes over max_upload_mb", "max_upload_mb")
    path = await run_in_threadpool(_new_spool_file, folder)
    try:
        with path.open("wb") as f:
            size = await _spool_chunks(request, max_bytes, f)
        if size == 0:
            raise ApiError(422, "body: empty upload", "body")
    except BaseException:
        path.unlink(missing_ok=True)
        raise
    return path


async def _spool_chunks(request: Request, max_bytes: int, f: BinaryIO) -> int:
    """Octets of the body written to f, block by block from a worker thread; 413 past max_bytes."""
    block: list[bytes] = []
    size = in_block = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > max_bytes:
            raise ApiError(413, f"body over max_upload_mb ({max_bytes} bytes)", "max_upload_mb")
        block.append(chunk)
        in_block += len(chunk)
        if in_block >= SPOOL_BLOCK_OCTETS:
            await run_in_threadpool(f.writelines, block)
            block, in_block = [], 0
    await run_in_threadpool(f.writelines, block)
    return size


def _new_spool_file(folder: Path) -> Path:
    """A new empty file in folder (made if missing) for a body being received."""
    folder.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(prefix="upload-", suffix=".ccsds", dir=folder)
    os.close(handle)
    return Path(name)


def _ingest_spooled(
    gateway: TelemetryGateway, satellite: str, path: Path, dictionary: str, source: str, uploaded_by: str
) -> tuple[int, dict[str, Any]]:
    """(octets, ingest report) of a spooled packet file decoded and archived, the file deleted after
    (blocking: the decoder's work and the disk; call from a thread)."""
    try:
        return path.stat().st_size, gateway.ingest_packet_file(satellite, path, dictionary, source, uploaded_by)
    finally:
        path.unlink(missing_ok=True)


def _parse_failure(exc: Exception, field: str) -> ApiError:
    return ApiError(422, f"{field}: could not be read: {exc}", field)


@router.post(
    "/telemetry/uploads",
    response_model=IngestReportPublic,
    summary="Upload telemetry (CCSDS packets, CSV or JSONL)",
    openapi_extra=BINARY_BODY,
)
async def upload_telemetry(
    request: Request,
    services: ServicesDep,
    principal: OperatorDep,
    satellite: str = Query("NOAA-20", min_length=1, max_length=NAME_MAX, pattern=SATELLITE_NAME, examples=["NOAA-20"]),
    dictionary: str = Query(
        "noaa20_apid11_ccsdspy.yaml",
        max_length=DICTIONARY_NAME_MAX,
        pattern=DICTIONARY_NAME,
        examples=["noaa20_apid11_ccsdspy.yaml"],
    ),
    format: Literal["ccsds", "csv", "jsonl"] = Query("ccsds"),
    source: str = Query("upload", max_length=200),
) -> dict[str, Any]:
    """Decode, validate, archive (limits checked, duplicates dropped) and return the ingest report.

    CCSDS packets stream to a file on disk as they arrive (written from a worker thread) and decode chunk by
    chunk in the upload decoder process (or a worker thread for a small file), so neither memory nor the event
    loop follows the upload's size.
    """
    gateway = services.telemetry
    max_bytes = int(services.settings.max_upload_mb * 1e6)
    if format == "ccsds":
        path = await spool_limited(request, max_bytes, services.settings.data_dir / "uploads")
        size, report = await run_in_threadpool(
            _ingest_spooled, gateway, satellite, path, dictionary, source, principal.name
        )
    else:
        data = await read_limited(request, max_bytes)
        size = len(data)
        report = await run_in_threadpool(
            gateway.ingest_ground_file, satellite, data, format, dictionary, source, principal.name
        )
    await run_in_threadpool(
        services.audit.record,
        principal.name,
        "telemetry.upload",
        f"satellite/{satellite}",
        {
            "bytes": size,
            "format": format,
            "upload_id": report["archive"]["upload_id"],
            "packets_accepted": report["archive"]["packets_accepted"],
        },
    )
    return report


@router.get(
    "/telemetry/uploads",
    response_model=list[UploadRecord],
    summary="Uploads of a satellite (who, when, source, report)",
)
def list_uploads(
    services: ServicesDep, _: ViewerDep, satellite: str = Query("NOAA-20", min_length=1, max_length=NAME_MAX)
) -> list[dict[str, Any]]:
    """Every upload with its checksum, tallies and stored ingest report, oldest first."""
    return [asdict(u) for u in services.telemetry.archive.uploads(satellite)]


@router.get(
    "/telemetry/undefined",
    response_model=KeptRawCounts,
    summary="Packets kept raw per APID for want of a definition",
)
def kept_raw(
    services: ServicesDep,
    _: ViewerDep,
    satellite: str = Query("NOAA-20", min_length=1, max_length=NAME_MAX, pattern=SATELLITE_NAME),
) -> dict[str, int]:
    """APID (as text) → packets kept raw: no definition when they came, or quarantined by a later one."""
    return {str(a): n for a, n in services.telemetry.archive.undefined_counts(satellite).items()}


@router.post(
    "/telemetry/redecode",
    response_model=RedecodeReportPublic,
    summary="Decode packets kept raw, now that a dictionary defines their APID",
)
async def redecode_kept(
    services: ServicesDep,
    principal: OperatorDep,
    satellite: str = Query("NOAA-20", min_length=1, max_length=NAME_MAX, pattern=SATELLITE_NAME),
    dictionary: str = Query(max_length=DICTIONARY_NAME_MAX, pattern=DICTIONARY_NAME, examples=["cygnss_adcs.csv"]),
    apid: list[Annotated[int, Field(ge=0, le=2047)]] = Query(
        [], description="Only these APIDs (repeat the key); default: every APID the dictionary defines."
    ),
) -> dict[str, Any]:
    """The kept packets of the dictionary's APIDs decoded and archived as one upload, in the upload decoder process;
    packets the dictionary quarantines stay kept (a corrected one may read them later). A second call finds
    nothing kept and archives nothing."""
    report = await run_in_threadpool(
        services.telemetry.redecode, satellite, dictionary, tuple(sorted(set(apid))), principal.name
    )
    await run_in_threadpool(
        services.audit.record,
        principal.name,
        "telemetry.redecode",
        f"satellite/{satellite}",
        {
            "dictionary": dictionary,
            "apids": report["apids"],
            "upload_id": report["archive"]["upload_id"] if report["archive"] else None,
            "packets_accepted": report["archive"]["packets_accepted"] if report["archive"] else 0,
        },
    )
    return report


@router.get("/dictionaries", response_model=DictionaryNames, summary="Known telemetry dictionaries")
def list_dictionaries(services: ServicesDep, _: ViewerDep) -> list[str]:
    """File names usable as ``dictionary=`` in uploads (shipped and uploaded)."""
    return services.telemetry.dictionaries.names()


@router.post(
    "/dictionaries/{name}",
    status_code=201,
    response_model=DictionaryStored,
    summary="Upload a dictionary (YAML, XTCE, ccsdspy CSV)",
    openapi_extra=DEFINITION_BODY,
)
async def upload_dictionary(
    name: Annotated[str, PathParam(max_length=DICTIONARY_NAME_MAX, pattern=DICTIONARY_NAME, examples=["ops.yaml"])],
    request: Request,
    services: ServicesDep,
    principal: OperatorDep,
    apid: int | None = Query(None, ge=0, le=2046, description="APID of a ccsdspy CSV layout."),
    time_code: str | None = Query(None, max_length=200, description="Time code spec for CSV/XTCE."),
    time_fields: str | None = Query(
        None,
        max_length=500,
        examples=["year=*_YEAR,doy=*_DAY,hour=*_HOUR,minute=*_MIN,second=*_SEC,microsecond=*_USEC"],
        description="Time from packet fields for CSV/XTCE (as acs-twin ingest --time-fields).",
    ),
) -> dict[str, Any]:
    """Store a definition for a new spacecraft or APID once it loads; lists its packets."""
    data = await read_limited(request, int(services.settings.max_upload_mb * 1e6))
    try:
        loaded, version = await run_in_threadpool(
            services.telemetry.dictionaries.add, name, data, apid, time_code, time_fields
        )
    except (ValueError, ApiError):
        raise
    except Exception as exc:  # a malformed XML/YAML file raises its parser's own errors
        raise _parse_failure(exc, "body") from exc
    await run_in_threadpool(
        services.audit.record,
        principal.name,
        "dictionary.upload",
        f"dictionary/{name}",
        {"bytes": len(data), "version": version},
    )
    return {"name": name, "packets": {str(a): p.name for a, p in loaded.packets.items()}}
