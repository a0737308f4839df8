"""Alarm state machine of the archive (ISA-18.2 style): limit transitions and operator actions.

Out of limits opens an alarm (state *active*, event *enter*); back in limits records *leave*; an
*acknowledged* alarm back in limits is *cleared* automatically, an unacknowledged one stays
active until acknowledged.  Escalation (yellow -> red) of an acknowledged alarm re-activates it.
*Shelved* alarms keep recording events and come back as active when the shelf time passes.
Limits are checked per upload in time order, starting from the level the parameter's open alarm
holds; back-filled (older) data is checked against that level and does not rewrite history.
All functions run on a connection inside the caller's transaction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from sqlalchemy import Connection, Table, insert, select, update

from telemetry.archive.models import Alarm, AlarmEvent
from telemetry.limits import NOMINAL, SEVERITY_NAMES

__all__ = ["LevelChange", "apply_level_changes", "current_levels", "operator_action"]

OPEN_STATES = ("active", "acknowledged", "shelved")
ALARM = cast(Table, Alarm.__table__)
EVENT = cast(Table, AlarmEvent.__table__)


@dataclass(frozen=True)
class LevelChange:
    """A parameter changing alarm level at a sample (from limit checking on ingest)."""

    parameter: str
    t_ns: int
    level: int
    value: float


def current_levels(conn: Connection, satellite_id: int, parameters: list[str]) -> dict[str, tuple[int, int]]:
    """Open alarm (id, level) per parameter that has one."""
    rows = conn.execute(
        select(ALARM.c.parameter, ALARM.c.id, ALARM.c.level).where(
            ALARM.c.satellite_id == satellite_id,
            ALARM.c.state.in_(OPEN_STATES),
            ALARM.c.parameter.in_(parameters),
        )
    )
    return {name: (alarm_id, level) for name, alarm_id, level in rows}


def apply_level_changes(conn: Connection, satellite_id: int, upload_id: int, changes: list[LevelChange]) -> int:
    """Open, update and close alarms for time-ordered level changes; returns events written."""
    by_parameter: dict[str, list[LevelChange]] = {}
    for change in changes:
        by_parameter.setdefault(change.parameter, []).append(change)
    open_alarms = current_levels(conn, satellite_id, list(by_parameter))
    events: list[dict[str, Any]] = []
    for name, param_changes in by_parameter.items():
        events.extend(_apply_parameter(conn, satellite_id, upload_id, name, param_changes, open_alarms.get(name)))
    if events:
        conn.execute(insert(EVENT), events)
    return len(events)


def _apply_parameter(
    conn: Connection,
    satellite_id: int,
    upload_id: int,
    name: str,
    changes: list[LevelChange],
    open_alarm: tuple[int, int] | None,
) -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = []
    alarm = _load(conn, open_alarm[0]) if open_alarm else None
    for change in changes:
        severity = SEVERITY_NAMES[change.level]
        if change.level > NOMINAL and alarm is None:
            alarm = {
                "id": None,
                "state": "active",
                "severity": severity,
                "level": change.level,
                "first_t_ns": change.t_ns,
                "last_t_ns": change.t_ns,
            }
            alarm["id"] = _create(conn, satellite_id, name, alarm)
        elif alarm is None:
            continue
        kind = "enter" if change.level > NOMINAL else "leave"
        events.append(_event(alarm["id"], upload_id, change.t_ns, kind, severity, change.value, None))
        if change.level > alarm["level"] and alarm["state"] == "acknowledged":
            alarm["state"] = "active"
        if change.level == NOMINAL and alarm["state"] == "acknowledged":
            alarm["state"] = "cleared"
            events.append(_event(alarm["id"], upload_id, change.t_ns, "clear", None, None, "system"))
        alarm["severity"] = SEVERITY_NAMES[max(SEVERITY_NAMES.index(alarm["severity"]), change.level)]
        alarm["level"], alarm["last_t_ns"] = change.level, max(alarm["last_t_ns"], change.t_ns)
        if alarm["state"] == "cleared":
            _save(conn, alarm)
            alarm = None
    if alarm is not None:
        _save(conn, alarm)
    return events


def _load(conn: Connection, alarm_id: int) -> dict[str, Any]:
    row = conn.execute(
        select(ALARM.c.id, ALARM.c.state, ALARM.c.severity, ALARM.c.level, ALARM.c.first_t_ns, ALARM.c.last_t_ns).where(
            ALARM.c.id == alarm_id
        )
    ).one()
    return dict(row._mapping)


def _create(conn: Connection, satellite_id: int, name: str, alarm: dict[str, Any]) -> int:
    values = {k: v for k, v in alarm.items() if k != "id"}
    return int(
        conn.execute(
            insert(ALARM).values(satellite_id=satellite_id, parameter=name, **values).returning(ALARM.c.id)
        ).scalar_one()
    )


def _save(conn: Connection, alarm: dict[str, Any]) -> None:
    values = {k: v for k, v in alarm.items() if k != "id"}
    conn.execute(update(ALARM).where(ALARM.c.id == alarm["id"]).values(**values))


def _event(
    alarm_id: int,
    upload_id: int | None,
    t_ns: int,
    kind: str,
    severity: str | None,
    value: float | None,
    actor: str | None,
) -> dict[str, Any]:
    value_f = None if value is None or not np.isfinite(value) else float(value)
    return {
        "alarm_id": alarm_id,
        "upload_id": upload_id,
        "t_ns": int(t_ns),
        "kind": kind,
        "severity": severity,
        "value": value_f,
        "actor": actor,
    }


def operator_action(
    conn: Connection, alarm_id: int, action: str, actor: str, t_ns: int, shelved_until_ns: int | None = None
) -> None:
    """Acknowledge, shelve, unshelve or clear an alarm on behalf of ``actor``."""
    if not actor:
        raise ValueError("actor: an operator name is required for alarm actions")
    row = conn.execute(select(ALARM.c.state, ALARM.c.level).where(ALARM.c.id == alarm_id)).one_or_none()
    if row is None:
        raise ValueError(f"alarm_id: no alarm {alarm_id}")
    state, level = row
    new_state, extra = _next_state(action, state, level, shelved_until_ns, t_ns)
    values: dict[str, Any] = {"state": new_state}
    if action == "acknowledge":
        values["acknowledged_by"] = actor
    if action == "shelve":
        values["shelved_until_ns"] = shelved_until_ns
    conn.execute(update(ALARM).where(ALARM.c.id == alarm_id).values(**values))
    events = [_event(alarm_id, None, t_ns, action, None, None, actor)]
    if extra:
        events.append(_event(alarm_id, None, t_ns, extra, None, None, "system"))
    conn.execute(insert(EVENT), events)


def _next_state(action: str, state: str, level: int, shelved_until_ns: int | None, t_ns: int) -> tuple[str, str | None]:
    if state == "cleared":
        raise ValueError("alarm_id: the alarm is already cleared")
    if action == "acknowledge":
        return ("cleared", "clear") if level == NOMINAL else ("acknowledged", None)
    if action == "shelve":
        if shelved_until_ns is None or shelved_until_ns <= t_ns:
            raise ValueError("shelved_until_ns: must be later than the time of the action")
        return "shelved", None
    if action == "unshelve":
        if state != "shelved":
            raise ValueError(f"action: cannot unshelve an alarm in state {state!r}")
        return "active", None
    if action == "clear":
        if level != NOMINAL:
            raise ValueError("action: cannot clear an alarm whose parameter is still out of limits")
        return "cleared", None
    raise ValueError(f"action: expected acknowledge, shelve, unshelve or clear, got {action!r}")
