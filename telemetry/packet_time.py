"""Packet time from named fields, as the mission defines it: UTC calendar fields or a coarse/fine counter.

Calendar fields (``year``, ``doy`` or ``month`` + ``day``, ``hour``, ``minute``, ``second``,
``millisecond``, ``microsecond``) are UTC, day of year and day of month start at 1; impossible
values (year 0, day 400, hour 24 …) are reported per packet, never rolled over. A counter is
``epoch + coarse + fine / 2**fine_bits`` seconds, plain addition as the mission's own tools do;
leap seconds apply only when the counter's time scale is TAI or GPS (as for CUC codes,
CCSDS 301.0-B-4 §3.2). All times leave as int64 ns of UTC since the Unix epoch (DESIGN.md).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit

from telemetry.ccsds import CCSDS_EPOCH_NS, NS_PER_DAY, NS_PER_S, TIME_SCALE_OFFSET_S, scale_to_utc

__all__ = ["TimeFields", "parse_time_fields", "field_times", "TIME_PROBLEMS", "CALENDAR_KEYS", "COUNTER_KEYS"]

CALENDAR_KEYS = ("year", "doy", "month", "day", "hour", "minute", "second", "millisecond", "microsecond")
COUNTER_KEYS = ("coarse", "fine")
OPTION_KEYS = ("fine_bits", "epoch", "time_scale")
TIME_PROBLEMS = (
    "",
    "year outside 1..9999",
    "month outside 1..12",
    "day outside the month",
    "day of year outside the year",
    "hour outside 0..23",
    "minute outside 0..59",
    "second outside 0..60",
    "millisecond outside 0..999",
    "microsecond outside 0..999999",
    "fine counter wider than fine_bits",
    "coarse counter negative",
)
_RANGES = {
    "hour": (5, 0, 23),
    "minute": (6, 0, 59),
    "second": (7, 0, 60),
    "millisecond": (8, 0, 999),
    "microsecond": (9, 0, 999_999),
}
_UNIT_NS = {
    "hour": 3_600 * NS_PER_S,
    "minute": 60 * NS_PER_S,
    "second": NS_PER_S,
    "millisecond": 1_000_000,
    "microsecond": 1_000,
}


@dataclass(frozen=True)
class TimeFields:
    """Which packet fields carry the time (key -> parameter name), and the counter's fine bits, epoch, scale."""

    fields: tuple[tuple[str, str], ...]
    fine_bits: int = 0
    epoch_ns: int = CCSDS_EPOCH_NS
    time_scale: str = "UTC"

    def __post_init__(self) -> None:
        keys = [k for k, _ in self.fields]
        unknown = set(keys) - set(CALENDAR_KEYS) - set(COUNTER_KEYS)
        if unknown:
            raise ValueError(f"time_fields: unknown keys {sorted(unknown)} (use {CALENDAR_KEYS + COUNTER_KEYS})")
        if len(set(keys)) != len(keys):
            raise ValueError("time_fields: a key is given twice")
        if self.is_counter:
            if set(keys) & set(CALENDAR_KEYS):
                raise ValueError("time_fields: mix of counter (coarse/fine) and calendar keys")
            if "coarse" not in keys:
                raise ValueError("time_fields: a counter needs coarse=FIELD")
            if not 0 <= self.fine_bits <= 63 or ("fine" in keys) != (self.fine_bits > 0):
                raise ValueError("time_fields: fine=FIELD needs fine_bits=1..63, and fine_bits needs fine=FIELD")
        else:
            if "year" not in keys or not (("doy" in keys) ^ ("month" in keys and "day" in keys)):
                raise ValueError("time_fields: calendar time needs year and either doy or month and day")
            if "doy" in keys and ({"month", "day"} & set(keys)):
                raise ValueError("time_fields: give doy or month/day, not both")
        if self.time_scale not in TIME_SCALE_OFFSET_S:
            raise ValueError(f"time_fields.time_scale: expected one of {sorted(TIME_SCALE_OFFSET_S)}")

    @property
    def is_counter(self) -> bool:
        """True for a coarse/fine counter, False for calendar fields."""
        return any(k == "coarse" for k, _ in self.fields)

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names the time is read from."""
        return tuple(name for _, name in self.fields)

    def bound_to(self, names: Iterable[str]) -> TimeFields:
        """The same time with each field name resolved among a packet's parameters (``*`` / ``?`` wildcards
        allowed, e.g. ``year=*_HDR_YEAR`` for one spec across packets); ValueError unless exactly one matches."""
        names = list(names)
        bound = []
        for key, pattern in self.fields:
            found = [n for n in names if fnmatch.fnmatchcase(n, pattern)]
            if len(found) != 1:
                what = "no parameter" if not found else f"{len(found)} parameters {found[:4]}"
                wider = "*" + pattern.lstrip("*")  # offered only where it matches: not for a suffix or other case
                near = [n for n in names if fnmatch.fnmatchcase(n, wider)] if not found else []
                hint = f" (but {near[:3]}: e.g. {wider!r} matches a prefixed name)" if near else ""
                raise ValueError(f"time_fields.{key}: {what} matching {pattern!r}{hint}")
            bound.append((key, found[0]))
        return replace(self, fields=tuple(bound))

    def field(self, key: str) -> str | None:
        """Parameter name of a key, if given."""
        return next((name for k, name in self.fields if k == key), None)


def parse_time_fields(spec: str | Mapping[str, Any] | None) -> TimeFields | None:
    """TimeFields from ``year=F1,doy=F2,…`` / ``coarse=C,fine=F,fine_bits=16,epoch=ISO`` or a YAML mapping."""
    if spec is None or spec == "":
        return None
    if isinstance(spec, str):
        pairs = [item.partition("=") for item in spec.split(",") if item.strip()]
        bad = [k for k, eq, v in pairs if not eq or not v.strip()]
        if bad:
            raise ValueError(f"time_fields: expected KEY=VALUE items, got {bad}")
        mapping: dict[str, Any] = {k.strip(): v.strip() for k, _, v in pairs}
    else:
        mapping = dict(spec)
    options = {k: mapping.pop(k) for k in OPTION_KEYS if k in mapping}
    kwargs: dict[str, Any] = {}
    if "fine_bits" in options:
        kwargs["fine_bits"] = int(options["fine_bits"])
    if "epoch" in options:
        from telemetry.dictionary import parse_utc_ns

        kwargs["epoch_ns"] = parse_utc_ns(options["epoch"])
    if "time_scale" in options:
        kwargs["time_scale"] = str(options["time_scale"]).upper()
    return TimeFields(fields=tuple((str(k), str(v)) for k, v in mapping.items()), **kwargs)


_CALENDAR_ROWS = ("year", "doy", "month", "day", *_RANGES)  # rows of _calendar_kernel's field matrix
_RANGE_CODE = np.array([c for c, _, _ in _RANGES.values()], dtype=np.int8)
_RANGE_LOW = np.array([lo for _, lo, _ in _RANGES.values()], dtype=np.int64)
_RANGE_HIGH = np.array([hi for _, _, hi in _RANGES.values()], dtype=np.int64)
_RANGE_UNIT_NS = np.array([_UNIT_NS[k] for k in _RANGES], dtype=np.int64)


@njit(cache=True, nogil=True, inline="always")
def _days_from_civil(year: int, month: int, day: int) -> int:
    """Days from 1970-01-01 to a proleptic Gregorian date (H. Hinnant's days_from_civil: 400-year eras)."""
    y = year - (month <= 2)
    era = (y if y >= 0 else y - 399) // 400
    yoe = y - era * 400
    doy = (153 * (month + (-3 if month > 2 else 9)) + 2) // 5 + day - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146_097 + doe - 719_468


@njit(cache=True, nogil=True)
def _calendar_kernel(
    fields: np.ndarray,
    given: np.ndarray,
    code: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    unit_ns: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """UTC ns and problem codes of calendar fields (compiled kernel, one pass): fields[k] is the column of
    _CALENDAR_ROWS[k] (given[k]: the mission gives it; a row not given is 0), the time-of-day rows checked
    against low..high (else problem code) and weighted by unit_ns. The first problem found is the packet's;
    a packet with a problem gets a time of its clipped fields (it is quarantined)."""
    n = fields.shape[1]
    t = np.empty(n, dtype=np.int64)
    problem = np.zeros(n, dtype=np.int8)
    for i in range(n):
        year = fields[0, i]
        if year < 1 or year > 9_999:
            problem[i], year = 1, 1_970
        if given[1]:
            leap = (year % 4 == 0 and year % 100 != 0) or year % 400 == 0
            doy = fields[1, i]
            if problem[i] == 0 and (doy < 1 or doy > (366 if leap else 365)):
                problem[i] = 4
            day = _days_from_civil(year, 1, 1) + min(max(doy, 1), 366) - 1
        else:
            month, dom = fields[2, i], fields[3, i]
            if problem[i] == 0 and (month < 1 or month > 12):
                problem[i] = 2
            month = min(max(month, 1), 12)
            first = _days_from_civil(year, month, 1)
            length = _days_from_civil(year + (month == 12), month % 12 + 1, 1) - first
            if problem[i] == 0 and (dom < 1 or dom > length):
                problem[i] = 3
            day = first + min(max(dom, 1), 31) - 1
        ns = day * NS_PER_DAY
        for k in range(code.shape[0]):
            if given[4 + k]:
                v = fields[4 + k, i]
                if problem[i] == 0 and (v < low[k] or v > high[k]):
                    problem[i] = code[k]
                ns += v * unit_ns[k]
        t[i] = ns
    return t, problem


def _calendar(values: Mapping[str, np.ndarray], tf: TimeFields, n: int) -> tuple[np.ndarray, np.ndarray]:
    """UTC ns and problem codes of calendar fields (UTC, day of year from 1)."""
    fields = np.zeros((len(_CALENDAR_ROWS), n), dtype=np.int64)
    given = np.zeros(len(_CALENDAR_ROWS), dtype=np.bool_)
    for k, key in enumerate(_CALENDAR_ROWS):
        name = tf.field(key)
        if name is not None:
            fields[k], given[k] = values[name], True
    return _calendar_kernel(fields, given, _RANGE_CODE, _RANGE_LOW, _RANGE_HIGH, _RANGE_UNIT_NS)


def field_times(values: Mapping[str, np.ndarray], tf: TimeFields) -> tuple[np.ndarray, np.ndarray]:
    """UTC ns of each packet from its raw time fields, and an index into TIME_PROBLEMS (0 = valid)."""
    missing = [name for name in tf.names if name not in values]
    if missing:
        raise ValueError(f"time_fields: no parameters {missing} in the packet")
    n = len(values[tf.names[0]])
    if not tf.is_counter:
        return _calendar(values, tf, n)
    coarse = np.asarray(values[str(tf.field("coarse"))]).astype(np.int64)
    problem = np.where(coarse < 0, 11, 0).astype(np.int8)
    t = tf.epoch_ns + coarse * NS_PER_S
    fine_name = tf.field("fine")
    if fine_name is not None:
        fine = np.asarray(values[fine_name]).astype(np.int64)
        problem[(problem == 0) & ((fine < 0) | (fine >> tf.fine_bits != 0))] = 10
        bits = tf.fine_bits
        t += (
            (fine * NS_PER_S + (1 << bits >> 1)) >> bits
            if bits <= 32
            else np.rint(fine / 2.0**bits * 1e9).astype(np.int64)
        )
    return scale_to_utc(t, tf.time_scale), problem
