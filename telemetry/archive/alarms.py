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

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias, cast

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import Connection, Table, bindparam, select, update

from telemetry.archive.engine import fetch_rows, insert_returning_ids, insert_rows, run_update
from telemetry.archive.models import Alarm, AlarmEvent
from telemetry.limits import NOMINAL, SEVERITY_NAMES

__all__ = ["LevelChanges", "apply_level_changes", "current_levels", "operator_action"]

OPEN_STATES = ("active", "acknowledged", "shelved")
ALARM = cast(Table, Alarm.__table__)
EVENT = cast(Table, AlarmEvent.__table__)
EVENT_COLUMNS = ("alarm_id", "upload_id", "t_ns", "kind", "severity", "value", "actor")
EventRow: TypeAlias = tuple[int, int | None, int, str, str | None, float | None, str | None]  # EVENT_COLUMNS
# The statements of limit checking on ingest, built once and run through the driver (engine.fetch_rows): built per
# call, SQLAlchemy took ~1 ms of Python each, most of a live group commit's CPU when its uploads carry limits.
STATE_COLUMNS = ("state", "severity", "level", "first_t_ns", "last_t_ns")  # what limit changes move
_OPEN_LEVELS = select(ALARM.c.parameter, ALARM.c.id, ALARM.c.level).where(
    ALARM.c.satellite_id == bindparam("sat"),
    ALARM.c.state.in_(OPEN_STATES),
    ALARM.c.parameter.in_(bindparam("names", expanding=True)),
)
_ALARM_STATE = select(ALARM.c.id, *(ALARM.c[c] for c in STATE_COLUMNS)).where(ALARM.c.id == bindparam("alarm"))
_SAVE_STATE = (
    update(ALARM).where(ALARM.c.id == bindparam("alarm")).values({c: bindparam(f"new_{c}") for c in STATE_COLUMNS})
)


@dataclass(frozen=True)
class LevelChanges:
    """A parameter changing alarm level at samples (from limit checking on ingest), in time order: per change the
    sample's time, the level it enters and the value that caused it."""

    parameter: str
    t_ns: NDArray[np.int64]
    level: NDArray[np.int8]
    value: NDArray[np.float64]

    def part(self, start: int, stop: int | None = None) -> LevelChanges:
        """The changes ``start`` to ``stop`` (exclusive; None: to the last)."""
        part = slice(start, stop)
        return LevelChanges(self.parameter, self.t_ns[part], self.level[part], self.value[part])


def current_levels(conn: Connection, satellite_id: int, parameters: list[str]) -> dict[str, tuple[int, int]]:
    """Open alarm (id, level) per parameter that has one."""
    if not parameters:
        return {}
    rows = fetch_rows(conn, _OPEN_LEVELS, {"sat": satellite_id, "names": parameters})
    return {name: (int(alarm_id), int(level)) for name, alarm_id, level in rows}


def apply_level_changes(conn: Connection, satellite_id: int, upload_id: int, changes: Sequence[LevelChanges]) -> int:
    """Open, update and close alarms for level changes taken in time order (ties in the order given), parameter by
    parameter in the order each first changes; returns events written."""
    changes = [c for c in changes if c.t_ns.size]
    if not changes:
        return 0
    codes: dict[str, int] = {}
    code = np.repeat([codes.setdefault(c.parameter, len(codes)) for c in changes], [c.t_ns.size for c in changes])
    t_ns = np.concatenate([c.t_ns for c in changes])
    order = np.argsort(t_ns, kind="stable")
    code, t_ns = code[order], t_ns[order]
    level = np.concatenate([c.level for c in changes])[order]
    value = np.concatenate([c.value for c in changes])[order]
    names = list(codes)
    open_alarms = current_levels(conn, satellite_id, names)
    by_parameter = np.argsort(code, kind="stable")  # each parameter's changes together, still in time order
    bounds = np.searchsorted(code[by_parameter], np.arange(len(names) + 1))
    _, first = np.unique(code, return_index=True)
    events: list[EventRow] = []
    for parameter in code[np.sort(first)].tolist():
        rows = by_parameter[bounds[parameter] : bounds[parameter + 1]]
        name = names[parameter]
        run = LevelChanges(name, t_ns[rows], level[rows], value[rows])
        events.extend(_apply_parameter(conn, satellite_id, upload_id, run, open_alarms.get(name)))
    if events:
        insert_rows(conn, EVENT, EVENT_COLUMNS, events)
    return len(events)


def _apply_parameter(
    conn: Connection, satellite_id: int, upload_id: int, changes: LevelChanges, open_alarm: tuple[int, int] | None
) -> list[EventRow]:
    """One parameter's alarm through its changes; the events. Out of limits with no alarm open opens one (active);
    an active or shelved alarm takes every later change as it comes (an event each, no change of state), so those
    are handled at once; an acknowledged one is re-activated by an escalation and cleared by a return to nominal."""
    events: list[EventRow] = []
    alarm = _load(conn, open_alarm[0]) if open_alarm else None
    i = 0
    while i < changes.t_ns.size:
        if alarm is None:
            out_of_limits = np.flatnonzero(changes.level[i:] > NOMINAL)
            if out_of_limits.size == 0:
                return events
            i += int(out_of_limits[0])
            alarm = _open(conn, satellite_id, changes.parameter, int(changes.t_ns[i]), int(changes.level[i]))
        if alarm["state"] != "acknowledged":
            rest = changes.part(i)
            events.extend(_change_events(alarm["id"], upload_id, rest))
            _follow(alarm, rest)
            break
        alarm = _acknowledged_change(conn, alarm, upload_id, changes, i, events)
        i += 1
    if alarm is not None:
        _save(conn, alarm)
    return events


def _open(conn: Connection, satellite_id: int, name: str, t_ns: int, level: int) -> dict[str, Any]:
    """A new active alarm of ``name``, out of limits at ``level`` since ``t_ns``."""
    alarm: dict[str, Any] = {
        "id": None,
        "state": "active",
        "severity": SEVERITY_NAMES[level],
        "level": level,
        "first_t_ns": t_ns,
        "last_t_ns": t_ns,
    }
    alarm["id"] = _create(conn, satellite_id, name, alarm)
    return alarm


def _change_events(alarm_id: int, upload_id: int, changes: LevelChanges) -> list[EventRow]:
    """An enter (out of limits) or leave (back within them) event per change."""
    finite = np.isfinite(changes.value).tolist()
    return [
        (
            alarm_id,
            upload_id,
            t_ns,
            "enter" if level > NOMINAL else "leave",
            SEVERITY_NAMES[level],
            value if ok else None,
            None,
        )
        for t_ns, level, value, ok in zip(
            changes.t_ns.tolist(), changes.level.tolist(), changes.value.tolist(), finite, strict=True
        )
    ]


def _follow(alarm: dict[str, Any], changes: LevelChanges) -> None:
    """The alarm's severity (the highest level reached), level (the last) and last time after ``changes``."""
    alarm["severity"] = SEVERITY_NAMES[max(SEVERITY_NAMES.index(alarm["severity"]), int(changes.level.max()))]
    alarm["level"], alarm["last_t_ns"] = int(changes.level[-1]), max(alarm["last_t_ns"], int(changes.t_ns.max()))


def _acknowledged_change(
    conn: Connection, alarm: dict[str, Any], upload_id: int, changes: LevelChanges, i: int, events: list[EventRow]
) -> dict[str, Any] | None:
    """The ``i``-th change to an acknowledged alarm (its event added to ``events``): an escalation re-activates it,
    a return to nominal clears it (saved; None returned)."""
    change = changes.part(i, i + 1)
    events.extend(_change_events(alarm["id"], upload_id, change))
    level = int(change.level[0])
    if level > alarm["level"]:
        alarm["state"] = "active"
    elif level == NOMINAL:
        alarm["state"] = "cleared"
        events.append(_event(alarm["id"], upload_id, int(change.t_ns[0]), "clear", "system"))
    _follow(alarm, change)
    if alarm["state"] != "cleared":
        return alarm
    _save(conn, alarm)
    return None


def _load(conn: Connection, alarm_id: int) -> dict[str, Any]:
    (row,) = fetch_rows(conn, _ALARM_STATE, {"alarm": alarm_id})
    return dict(zip(("id", *STATE_COLUMNS), row, strict=True))


def _create(conn: Connection, satellite_id: int, name: str, alarm: dict[str, Any]) -> int:
    row = (satellite_id, name, *(alarm[c] for c in STATE_COLUMNS))
    return insert_returning_ids(conn, ALARM, ("satellite_id", "parameter", *STATE_COLUMNS), [row])[0]


def _save(conn: Connection, alarm: dict[str, Any]) -> None:
    run_update(conn, _SAVE_STATE, {"alarm": alarm["id"], **{f"new_{c}": alarm[c] for c in STATE_COLUMNS}})


def _event(alarm_id: int, upload_id: int | None, t_ns: int, kind: str, actor: str) -> EventRow:
    """The row of an event of no level (an operator action or a clear)."""
    return alarm_id, upload_id, int(t_ns), kind, None, None, actor


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
    events = [_event(alarm_id, None, t_ns, action, actor)]
    if extra:
        events.append(_event(alarm_id, None, t_ns, extra, "system"))
    insert_rows(conn, EVENT, EVENT_COLUMNS, events)


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
