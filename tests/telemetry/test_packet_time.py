"""Packet time from named fields: calendar (UTC, day of year from 1) and coarse/fine counters (plain addition).

Truths: Python's datetime calendar, and TAI − UTC = 37 s since 2017-01-01 (IERS Bulletin C).
"""

from __future__ import annotations

import calendar
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


def _calendar_truth(fields: dict[str, int]) -> tuple[int | None, str]:
    """Python's calendar: UTC ns of valid calendar fields, else None and the first problem (year, date, then the
    time-of-day fields in order)."""
    year = fields["year"]
    if not 1 <= year <= 9_999:
        return None, "year outside 1..9999"
    if "doy" in fields:
        days = 366 if calendar.isleap(year) else 365
        if not 1 <= fields["doy"] <= days:
            return None, "day of year outside the year"
        date = dt.datetime(year, 1, 1) + dt.timedelta(days=fields["doy"] - 1)
    else:
        if not 1 <= fields["month"] <= 12:
            return None, "month outside 1..12"
        if not 1 <= fields["day"] <= calendar.monthrange(year, fields["month"])[1]:
            return None, "day outside the month"
        date = dt.datetime(year, fields["month"], fields["day"])
    for key, high, problem in (
        ("hour", 23, "hour outside 0..23"),
        ("minute", 59, "minute outside 0..59"),
        ("second", 60, "second outside 0..60"),
        ("millisecond", 999, "millisecond outside 0..999"),
    ):
        if not 0 <= fields[key] <= high:
            return None, problem
    rest = dt.timedelta(hours=fields["hour"], minutes=fields["minute"], milliseconds=fields["millisecond"])
    return _ns(date + rest) + fields["second"] * 10**9, ""  # second 60: a leap second, counted on as plain addition


@pytest.mark.parametrize("date_keys", [("doy",), ("month", "day")])
def test_calendar_fields_over_the_proleptic_gregorian_range_match_pythons_calendar(date_keys: tuple[str, ...]) -> None:
    rng = np.random.default_rng(12)
    n = 4_000
    keys = ("year", *date_keys, "hour", "minute", "second", "millisecond")
    highs = {"year": 9_999, "doy": 366, "month": 12, "day": 31, "hour": 23, "minute": 59, "second": 60}
    columns = {k: rng.integers(0 if k != "year" else 1, highs.get(k, 999) + 1, n) for k in keys}
    columns["year"][:2_000] = rng.integers(1_678, 2_262, 2_000)  # times in int64 ns
    columns["year"][:600] = rng.choice([1, 4, 100, 400, 1700, 1900, 2000, 2100, 2104, 9_999], 600)  # century rules
    bad = rng.integers(0, n, n // 10)  # a tenth with one field out of range (some twice: the first problem counts)
    for i, k in zip(bad.tolist(), rng.choice(keys, bad.size).tolist()):
        columns[k][i] = rng.choice([0, -1, highs.get(k, 999) + 1, 10_000]) if k != "second" else 61
    tf = parse_time_fields(",".join(f"{k}={k.upper()}" for k in keys))
    t, code = field_times({k.upper(): v.astype(np.uint16 if k != "year" else np.int32) for k, v in columns.items()}, tf)
    for i in range(n):
        expected, problem = _calendar_truth({k: int(v[i]) for k, v in columns.items()})
        assert TIME_PROBLEMS[int(code[i])] == problem, (i, {k: int(v[i]) for k, v in columns.items()})
        if expected is not None and -(2**63) <= expected < 2**63:  # int64 ns span 1677..2262
            assert int(t[i]) == expected


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


def test_a_prefixed_name_is_offered_only_with_a_wildcard_that_matches_it() -> None:
    """'*SHCOARSE' is offered for ILO.SHCOARSE, not for SHCOARSE_US (it would match nothing there either)."""
    tf = parse_time_fields("coarse=SHCOARSE,epoch=2010-01-01T00:00:00Z")
    with pytest.raises(ValueError, match=r"\(but \['ILO\.SHCOARSE'\]: e\.g\. '\*SHCOARSE' matches a prefixed name\)"):
        tf.bound_to(["ILO.SHCOARSE", "X"])
    with pytest.raises(ValueError, match=r"no parameter matching 'SHCOARSE'$"):
        tf.bound_to(["SHCOARSE_US", "X"])
