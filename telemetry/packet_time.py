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
                raise ValueError(f"time_fields.{key}: {what} matching {pattern!r}")
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


def _days_since_unix(year: np.ndarray) -> np.ndarray:
    """Days from 1970-01-01 to January 1 of each (proleptic Gregorian) year (1..10000): numpy's calendar run once
    per year of the span the packets cover (usually one), then looked up."""
    if year.size == 0:
        return np.zeros(0, np.int64)
    first = int(year.min())
    span = np.arange(first, int(year.max()) + 1, dtype=np.int64)
    table = (np.datetime64("1970", "Y") + (span - 1970).astype("timedelta64[Y]")).astype("datetime64[D]")
    days: np.ndarray = table.astype(np.int64)[year - first]
    return days


def _calendar(values: Mapping[str, np.ndarray], tf: TimeFields, n: int) -> tuple[np.ndarray, np.ndarray]:
    """UTC ns and problem codes of calendar fields (UTC, day of year from 1)."""

    def get(key: str) -> np.ndarray:
        name = tf.field(key)
        return np.zeros(n, np.int64) if name is None else np.asarray(values[name]).astype(np.int64)

    problem = np.zeros(n, dtype=np.int8)
    year = get("year")
    problem[(year < 1) | (year > 9999)] = 1
    year = np.where(problem == 0, year, 1970)
    jan1 = _days_since_unix(year)
    leap = _days_since_unix(year + 1) - jan1 == 366
    if tf.field("doy") is not None:
        doy = get("doy")
        problem[(problem == 0) & ((doy < 1) | (doy > np.where(leap, 366, 365)))] = 4
        day = jan1 + np.clip(doy, 1, 366) - 1
    else:
        month, dom = get("month"), get("day")
        problem[(problem == 0) & ((month < 1) | (month > 12))] = 2
        month = np.clip(month, 1, 12)
        first = (np.datetime64("1970", "Y") + (year - 1970).astype("timedelta64[Y]")).astype("datetime64[M]")
        first = first + (month - 1).astype("timedelta64[M]")
        length = ((first + np.timedelta64(1, "M")).astype("datetime64[D]") - first.astype("datetime64[D]")).astype(
            np.int64
        )
        problem[(problem == 0) & ((dom < 1) | (dom > length))] = 3
        day = first.astype("datetime64[D]").astype(np.int64) + np.clip(dom, 1, 31) - 1
    t = day * NS_PER_DAY
    for key, (code, low, high) in _RANGES.items():
        if tf.field(key) is None:
            continue
        v = get(key)
        problem[(problem == 0) & ((v < low) | (v > high))] = code
        t += v * _UNIT_NS[key]
    return t, problem


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
