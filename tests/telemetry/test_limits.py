"""Limit checking and the alarm lifecycle (enter/leave events, acknowledge, shelve, clear)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from telemetry.archive import Archive, PacketBatch
from telemetry.dictionary import Dictionary, Limits, PacketDefinition, Parameter
from telemetry.limits import RED, YELLOW, LimitSet, dictionary_limits, level_changes, limit_levels, limit_set
from tests.telemetry.archive_databases import archive, archive_url  # noqa: F401  (fixtures)

WHEEL = LimitSet(yellow_low=-5_000.0, yellow_high=5_000.0, red_low=-6_000.0, red_high=6_000.0)
SAT = "REF-SAT"
T0_NS = 1_700_000_000 * 10**9
SECOND_NS = 10**9


def wheel_batch(speeds_rpm: list[float], first: int = 0) -> PacketBatch:
    """One packet per second carrying ``wheel_rpm``."""
    index = np.arange(first, first + len(speeds_rpm))
    packets = [int(i).to_bytes(4, "big") for i in index]
    return PacketBatch.from_packets(
        200, T0_NS + index * SECOND_NS, index % 16_384, packets, {"wheel_rpm": np.array(speeds_rpm)}
    )


def test_levels_match_the_hand_classified_boundaries() -> None:
    values = np.array([0.0, 5_000.0, 5_000.1, -5_000.1, 6_000.0, 6_000.1, -6_000.1, math.nan])
    np.testing.assert_array_equal(limit_levels(values, WHEEL), [0, 0, YELLOW, YELLOW, YELLOW, RED, RED, RED])


def test_level_changes_start_from_the_level_before_the_batch() -> None:
    levels = np.array([1, 1, 0, 2, 2, 0], dtype=np.int8)
    np.testing.assert_array_equal(level_changes(levels, initial_level=0), [0, 2, 3, 5])
    np.testing.assert_array_equal(level_changes(levels, initial_level=1), [2, 3, 5])


def test_missing_yellow_bounds_fall_back_to_red_and_infinite_means_unlimited() -> None:
    only_red = limit_set(red_low=-1.0, yellow_low=None, yellow_high=None, red_high=None)
    np.testing.assert_array_equal(limit_levels(np.array([-2.0, 0.0, 1e300]), only_red), [RED, 0, 0])


def test_dictionary_limits_are_read_from_the_telemetry_dictionary() -> None:
    speed = Parameter("wheel_rpm", "float", 48, 32, limits=Limits(-6_000.0, -5_000.0, 5_000.0, 6_000.0))
    plain = Parameter("mode", "uint", 80, 8)
    packet = PacketDefinition("hk", 200, 11, (speed, plain))
    assert dictionary_limits(Dictionary("ref", {200: packet})) == {"wheel_rpm": WHEEL}


def test_inconsistent_limits_name_the_field() -> None:
    with pytest.raises(ValueError, match="limits"):
        LimitSet(yellow_low=1.0, yellow_high=0.0)
    with pytest.raises(ValueError, match="initial_level"):
        level_changes(np.zeros(3, dtype=np.int8), initial_level=7)


def test_alarm_enters_escalates_leaves_and_is_cleared_by_acknowledgement(archive: Archive) -> None:
    speeds = [0.0, 5_500.0, 6_500.0, 5_500.0, 0.0, 0.0]
    result = archive.ingest(SAT, [wheel_batch(speeds)], source="hk", uploaded_by="tester", limits={"wheel_rpm": WHEEL})
    assert result.alarm_events == 4
    (alarm,) = archive.alarms(SAT)
    assert (alarm.state, alarm.severity, alarm.level) == ("active", "red", 0)
    events = [(e.t_ns, e.kind, e.severity, e.value) for e in archive.alarm_events(alarm.id)]
    assert events == [
        (T0_NS + 1 * SECOND_NS, "enter", "yellow", 5_500.0),
        (T0_NS + 2 * SECOND_NS, "enter", "red", 6_500.0),
        (T0_NS + 3 * SECOND_NS, "enter", "yellow", 5_500.0),
        (T0_NS + 4 * SECOND_NS, "leave", "nominal", 0.0),
    ]
    archive.alarm_action(alarm.id, "acknowledge", "operator", t_ns=T0_NS + 10 * SECOND_NS)
    assert archive.alarms(SAT) == []
    assert [e.kind for e in archive.alarm_events(alarm.id)][-2:] == ["acknowledge", "clear"]


def test_acknowledged_alarm_clears_itself_on_leaving_and_reactivates_on_escalation(archive: Archive) -> None:
    archive.ingest(
        SAT, [wheel_batch([5_500.0, 5_600.0])], source="a", uploaded_by="tester", limits={"wheel_rpm": WHEEL}
    )
    (alarm,) = archive.alarms(SAT)
    archive.alarm_action(alarm.id, "acknowledge", "operator", t_ns=T0_NS + 2 * SECOND_NS)
    assert archive.alarms(SAT)[0].state == "acknowledged"
    archive.ingest(
        SAT, [wheel_batch([6_500.0], first=2)], source="b", uploaded_by="tester", limits={"wheel_rpm": WHEEL}
    )
    assert archive.alarms(SAT)[0].state == "active"
    archive.alarm_action(alarm.id, "acknowledge", "operator", t_ns=T0_NS + 4 * SECOND_NS)
    archive.ingest(SAT, [wheel_batch([0.0], first=3)], source="c", uploaded_by="tester", limits={"wheel_rpm": WHEEL})
    assert archive.alarms(SAT) == []
    assert archive.alarms(SAT, include_cleared=True)[0].state == "cleared"


def test_shelved_alarm_returns_active_when_the_shelf_time_passes(archive: Archive) -> None:
    archive.ingest(SAT, [wheel_batch([6_500.0])], source="a", uploaded_by="tester", limits={"wheel_rpm": WHEEL})
    (alarm,) = archive.alarms(SAT)
    until = T0_NS + 60 * SECOND_NS
    archive.alarm_action(alarm.id, "shelve", "operator", t_ns=T0_NS + SECOND_NS, shelved_until_ns=until)
    assert archive.alarms(SAT, now_ns=until - 1)[0].state == "shelved"
    assert archive.alarms(SAT, now_ns=until)[0].state == "active"
    archive.alarm_action(alarm.id, "unshelve", "operator", t_ns=T0_NS + 2 * SECOND_NS)
    assert archive.alarms(SAT, now_ns=T0_NS)[0].state == "active"


def test_operator_actions_refuse_what_the_state_forbids(archive: Archive) -> None:
    archive.ingest(SAT, [wheel_batch([6_500.0])], source="a", uploaded_by="tester", limits={"wheel_rpm": WHEEL})
    (alarm,) = archive.alarms(SAT)
    with pytest.raises(ValueError, match="out of limits"):
        archive.alarm_action(alarm.id, "clear", "operator")
    with pytest.raises(ValueError, match="shelved_until_ns"):
        archive.alarm_action(alarm.id, "shelve", "operator", t_ns=T0_NS, shelved_until_ns=T0_NS)
    with pytest.raises(ValueError, match="actor"):
        archive.alarm_action(alarm.id, "acknowledge", "")
    with pytest.raises(ValueError, match="alarm_id"):
        archive.alarm_action(alarm.id + 99, "acknowledge", "operator")


class _ReferenceAlarms:
    """The alarm rules of telemetry.archive.alarms applied one sample at a time, in plain Python (the truth for the
    archive's handling of whole runs of changes): per parameter its open alarm, every alarm ever opened and its
    events (time, kind, severity, value, actor) in the order they happened."""

    def __init__(self) -> None:
        self.open: dict[str, dict] = {}
        self.alarms: list[dict] = []

    def upload(self, t_ns: list[int], values: dict[str, list[float]], limit: LimitSet) -> None:
        for name, series in values.items():
            previous = self.open[name]["level"] if name in self.open else 0
            for t, value in zip(t_ns, series, strict=True):
                level = _reference_level(value, limit)
                if level != previous:
                    self._change(name, t, level, value)
                previous = level

    def _change(self, name: str, t: int, level: int, value: float) -> None:
        severity = ("nominal", "yellow", "red")[level]
        alarm = self.open.get(name)
        if alarm is None:
            if level == 0:
                return
            alarm = {"parameter": name, "state": "active", "severity": severity, "level": level, "first": t, "last": t}
            alarm["events"] = []
            self.alarms.append(alarm)
            self.open[name] = alarm
        alarm["events"].append((t, "enter" if level else "leave", severity, None if math.isnan(value) else value, None))
        if alarm["state"] == "acknowledged" and level > alarm["level"]:
            alarm["state"] = "active"
        if alarm["state"] == "acknowledged" and level == 0:
            alarm["state"] = "cleared"
            alarm["events"].append((t, "clear", None, None, "system"))
            del self.open[name]
        alarm["severity"] = max(alarm["severity"], severity, key=("nominal", "yellow", "red").index)
        alarm["level"], alarm["last"] = level, max(alarm["last"], t)

    def act(self, name: str, action: str, t: int) -> None:
        alarm = self.open[name]
        alarm["events"].append((t, action, None, None, "operator"))
        if action == "acknowledge" and alarm["level"] == 0:
            alarm["state"] = "cleared"
            alarm["events"].append((t, "clear", None, None, "system"))
            del self.open[name]
        else:
            alarm["state"] = {"acknowledge": "acknowledged", "shelve": "shelved"}[action]


def _reference_level(value: float, limit: LimitSet) -> int:
    if math.isnan(value) or not limit.red_low <= value <= limit.red_high:
        return RED
    return YELLOW if not limit.yellow_low <= value <= limit.yellow_high else 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_runs_of_changes_across_uploads_and_operator_actions_follow_the_alarm_rules(
    archive: Archive, seed: int
) -> None:
    """Chattering parameters (each sample nominal, yellow, red or NaN at random) over three uploads, with their open
    alarms acknowledged after the first and some shelved after the second: the archive's alarms and events are the
    ones the rules give taken one sample at a time."""
    rng = np.random.default_rng(seed)
    reference, names, n = _ReferenceAlarms(), ("wheel_rpm", "rate_x", "rate_y"), 60
    speeds = np.array([0.0, 5_500.0, -5_500.0, 6_500.0, -7_000.0, math.nan])
    for upload in range(3):
        index = np.arange(upload * n, (upload + 1) * n)
        values = {name: speeds[rng.choice(speeds.size, n, p=[0.4, 0.2, 0.1, 0.15, 0.1, 0.05])] for name in names}
        batch = PacketBatch.from_packets(
            200, T0_NS + index * SECOND_NS, index % 16_384, [int(i).to_bytes(4, "big") for i in index], values
        )
        limits = dict.fromkeys(names, WHEEL)
        archive.ingest(SAT, [batch], source=f"u{upload}", uploaded_by="tester", limits=limits)
        reference.upload((T0_NS + index * SECOND_NS).tolist(), {k: v.tolist() for k, v in values.items()}, WHEEL)
        t_action = T0_NS + (upload + 1) * n * SECOND_NS - SECOND_NS // 2
        by_parameter = {a.parameter: a for a in archive.alarms(SAT, now_ns=t_action)}
        for name in sorted(reference.open):
            action = "acknowledge" if upload == 0 or name == "rate_y" else "shelve"
            until = t_action + 10**6 * SECOND_NS if action == "shelve" else None
            archive.alarm_action(by_parameter[name].id, action, "operator", t_ns=t_action, shelved_until_ns=until)
            reference.act(name, action, t_action)
    alarms = archive.alarms(SAT, now_ns=T0_NS, include_cleared=True)
    got = [(a.parameter, a.state, a.severity, a.level, a.first_t_ns, a.last_t_ns) for a in alarms]
    want = [(a["parameter"], a["state"], a["severity"], a["level"], a["first"], a["last"]) for a in reference.alarms]
    assert sorted(got) == sorted(want)
    assert any(a["state"] == "cleared" for a in reference.alarms)  # the rules' every branch was taken
    assert {e[1] for a in reference.alarms for e in a["events"]} >= {"enter", "leave", "clear", "shelve"}
    events = {
        (a.parameter, a.first_t_ns): [
            (e.t_ns, e.kind, e.severity, e.value, e.actor) for e in archive.alarm_events(a.id)
        ]
        for a in alarms
    }
    assert events == {(a["parameter"], a["first"]): a["events"] for a in reference.alarms}
