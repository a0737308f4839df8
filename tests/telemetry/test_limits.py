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
