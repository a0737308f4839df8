"""Packet time from named fields: calendar (UTC, day of year from 1) and coarse/fine counters (plain addition).

Truths: Python's datetime calendar, and TAI − UTC = 37 s since 2017-01-01 (IERS Bulletin C).
"""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from telemetry.packet_time import TIME_PROBLEMS, field_times, parse_time_fields

UNIX = dt.datetime(1970, 1, 1)


def _ns(t: dt.datetime) -> int:
    return (t - UNIX) // dt.timedelta(microseconds=1) * 1_000


def test_month_day_and_milliseconds_are_the_utc_calendar() -> None:
    tf = parse_time_fields("year=Y,month=M,day=D,hour=h,minute=m,second=s,millisecond=ms")
    when = [dt.datetime(2024, 2, 29, 23, 59, 59, 999_000), dt.datetime(1999, 12, 31), dt.datetime(2030, 7, 4, 12)]
    values = {
        k: np.array([getattr(w, a) for w in when])
        for k, a in (("Y", "year"), ("M", "month"), ("D", "day"), ("h", "hour"), ("m", "minute"), ("s", "second"))
    }
    values["ms"] = np.array([w.microsecond // 1000 for w in when])
    t, problem = field_times(values, tf)
    assert t.tolist() == [_ns(w) for w in when] and problem.tolist() == [0, 0, 0]


@pytest.mark.parametrize(
    ("fields", "problem"),
    [
        ({"Y": 2023, "M": 2, "D": 29}, "day outside the month"),
        ({"Y": 2023, "M": 13, "D": 1}, "month outside 1..12"),
        ({"Y": 0, "M": 1, "D": 1}, "year outside 1..9999"),
        ({"Y": 2023, "M": 4, "D": 31}, "day outside the month"),
    ],
)
def test_impossible_dates_are_reported_never_rolled_over(fields: dict, problem: str) -> None:
    tf = parse_time_fields("year=Y,month=M,day=D")
    _, code = field_times({k: np.array([v]) for k, v in fields.items()}, tf)
    assert TIME_PROBLEMS[int(code[0])] == problem


def test_day_of_year_366_only_in_leap_years() -> None:
    tf = parse_time_fields({"year": "Y", "doy": "D"})
    t, code = field_times({"Y": np.array([2024, 2023]), "D": np.array([366, 366])}, tf)
    assert int(t[0]) == _ns(dt.datetime(2024, 12, 31)) and code.tolist() == [
        0,
        TIME_PROBLEMS.index("day of year outside the year"),
    ]


def test_counter_is_epoch_plus_coarse_plus_fine_fraction() -> None:
    tf = parse_time_fields("coarse=C,fine=F,fine_bits=16,epoch=2000-01-01T11:58:55.816Z")
    t, code = field_times({"C": np.array([10_768, 0]), "F": np.array([54_119, 32_768])}, tf)
    epoch = dt.datetime(2000, 1, 1, 11, 58, 55, 816_000)
    assert t.tolist() == [_ns(epoch) + 10_768 * 10**9 + round(54_119 / 65_536 * 1e9), _ns(epoch) + 500_000_000]
    assert code.tolist() == [0, 0]


def test_tai_counter_drops_the_leap_seconds() -> None:
    tf = parse_time_fields("coarse=C,epoch=1958-01-01,time_scale=TAI")
    seconds = (dt.datetime(2020, 1, 1) - dt.datetime(1958, 1, 1)) // dt.timedelta(seconds=1) + 37
    t, _ = field_times({"C": np.array([seconds])}, tf)
    assert int(t[0]) == _ns(dt.datetime(2020, 1, 1))


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("year=Y,hour=H", "either doy or month and day"),
        ("coarse=C,fine=F", "fine_bits"),
        ("coarse=C,year=Y", "mix of counter"),
        ("year=Y,doy", "KEY=VALUE"),
        ("week=W", "unknown keys"),
    ],
)
def test_bad_time_specs_are_refused_naming_the_problem(spec: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_time_fields(spec)


def test_wildcards_bind_to_exactly_one_parameter() -> None:
    tf = parse_time_fields("year=*_YEAR,doy=*_DAY")
    assert tf.bound_to(["PKT_YEAR", "PKT_DAY", "X"]).names == ("PKT_YEAR", "PKT_DAY")
    with pytest.raises(ValueError, match="2 parameters"):
        tf.bound_to(["A_YEAR", "B_YEAR", "A_DAY"])
