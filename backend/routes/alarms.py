"""Alarms: list, events, acknowledge, shelve, unshelve (operator actions are audited)."""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Any

from fastapi import APIRouter, Query

from backend.core.auth import Principal
from backend.core.errors import ERROR_RESPONSES
from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.schemas import NAME_MAX, AlarmActed, DbId, ShelveRequest
from backend.services import Services
from telemetry.archive.records import AlarmEventRecord, AlarmRecord

router = APIRouter(tags=["alarms"], responses=ERROR_RESPONSES)


@router.get("/alarms", response_model=list[AlarmRecord], summary="Alarms of a satellite")
def list_alarms(
    services: ServicesDep,
    _: ViewerDep,
    satellite: str = Query("NOAA-20", min_length=1, max_length=NAME_MAX),
    include_cleared: bool = False,
) -> list[dict[str, Any]]:
    """Active (and optionally cleared) alarms with state, severity and level."""
    return [asdict(a) for a in services.telemetry.archive.alarms(satellite, include_cleared=include_cleared)]


@router.get("/alarms/{alarm_id}/events", response_model=list[AlarmEventRecord], summary="History of one alarm")
def alarm_events(alarm_id: DbId, services: ServicesDep, _: ViewerDep) -> list[dict[str, Any]]:
    """Enter, leave, acknowledge, shelve … events in order."""
    return [asdict(e) for e in services.telemetry.archive.alarm_events(alarm_id)]


def _act(
    services: Services, principal: Principal, alarm_id: int, action: str, until_ns: int | None = None
) -> dict[str, Any]:
    services.telemetry.archive.alarm_action(alarm_id, action, principal.name, shelved_until_ns=until_ns)
    services.audit.record(
        principal.name, f"alarm.{action}", f"alarm/{alarm_id}", {"shelved_until_ns": until_ns} if until_ns else {}
    )
    services.hub.publish("alarms", {"alarm_id": alarm_id, "action": action, "actor": principal.name})
    return {"alarm_id": alarm_id, "action": action}


@router.post("/alarms/{alarm_id}/acknowledge", response_model=AlarmActed, summary="Acknowledge an alarm")
def acknowledge(alarm_id: DbId, services: ServicesDep, principal: OperatorDep) -> dict[str, Any]:
    """Mark the alarm seen by the operator."""
    return _act(services, principal, alarm_id, "acknowledge")


@router.post("/alarms/{alarm_id}/shelve", response_model=AlarmActed, summary="Shelve an alarm for duration_s")
def shelve(alarm_id: DbId, body: ShelveRequest, services: ServicesDep, principal: OperatorDep) -> dict[str, Any]:
    """Hide the alarm until now + duration_s."""
    return _act(services, principal, alarm_id, "shelve", time.time_ns() + int(body.duration_s * 1e9))


@router.post("/alarms/{alarm_id}/unshelve", response_model=AlarmActed, summary="Unshelve an alarm")
def unshelve(alarm_id: DbId, services: ServicesDep, principal: OperatorDep) -> dict[str, Any]:
    """Bring a shelved alarm back now."""
    return _act(services, principal, alarm_id, "unshelve")
