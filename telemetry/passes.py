"""Ground-station passes from a TLE (issue 5): AOS, LOS and maximum elevation, vectorised.

Method (skyfield's ``find_events`` strategy, vectorised over all passes at once): the elevation
is sampled on a coarse grid; each sampled peak brackets a culmination, refined by vectorised
golden-section search; culminations above the station's minimum elevation are passes; AOS and
LOS are the minimum-elevation crossings between a culmination and the nearest sample below it,
refined by vectorised bisection.  Positions come from SGP4 (AIAA 2006-6753) through
``sim_core.orbit.propagate_tle`` (TEME -> GCRS) and ``sim_core.frames.eci_to_ecef`` (-> ITRS);
the elevation is geometric (no refraction, no light time) above the WGS84 ellipsoid normal.
Only passes whose AOS and LOS both fall inside the searched window are returned.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from sim_core import frames, orbit
from telemetry.archive import DERIVED_APID, Archive, PassRecord, StationRecord, sequence_gaps

__all__ = [
    "PredictedPasses",
    "elevation_deg",
    "predict_passes",
    "predict_station_passes",
    "assign_to_passes",
    "record_reception",
    "merge_data_passes",
    "passes_from_data",
    "DATA_PASS_GAP_S",
    "COARSE_STEP_S",
    "REFINE_TOLERANCE_S",
]

COARSE_STEP_S = 60.0  # a LEO pass above the horizon lasts minutes; its peak spans several samples
REFINE_TOLERANCE_S = 1e-3  # bracket width at which AOS/LOS/culmination refinement stops
NS_PER_S = 10**9
SECONDS_PER_DAY = 86_400.0
GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0
# Telemetry closer than this in time is one pass: a LEO pass over one station lasts ≤ ~15 min and consecutive
# passes over it are a ~100 min orbit apart, so a 10 min silence ends a contact.
DATA_PASS_GAP_S = 600.0


@dataclass(frozen=True)
class PredictedPasses:
    """Passes over one station as arrays: AOS, LOS, culmination time (UTC ns) and max elevation."""

    aos_ns: np.ndarray
    los_ns: np.ndarray
    max_elevation_ns: np.ndarray
    max_elevation_deg: np.ndarray

    def rows(self) -> list[tuple[int, int, int, float]]:
        """(aos_ns, los_ns, max_elevation_ns, max_elevation_deg) tuples for ``Archive.save_passes``."""
        return list(
            zip(
                self.aos_ns.tolist(),
                self.los_ns.tolist(),
                self.max_elevation_ns.tolist(),
                self.max_elevation_deg.tolist(),
            )
        )

    def __iter__(self) -> Iterator[tuple[int, int, int, float]]:
        return iter(self.rows())

    def __len__(self) -> int:
        return int(self.aos_ns.size)


def elevation_deg(
    line1: str, line2: str, lat_deg: float, lon_deg: float, alt_m: float, t_unix_s: np.ndarray
) -> np.ndarray:
    """Geometric elevation (deg) of the TLE's satellite seen from a WGS84 site (SGP4, AIAA 2006-6753)."""
    return _elevation_function(line1, line2, lat_deg, lon_deg, alt_m)(np.asarray(t_unix_s, dtype=float))


def _elevation_function(
    line1: str, line2: str, lat_deg: float, lon_deg: float, alt_m: float
) -> Callable[[np.ndarray], np.ndarray]:
    satrec = orbit.parse_tle(line1, line2)
    site = frames.geodetic_to_ecef(lat_deg, lon_deg, alt_m)
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])

    def elevation(t_unix_s: np.ndarray) -> np.ndarray:
        r_eci, v_eci = orbit.propagate_tle(satrec, t_unix_s.ravel())
        r_ecef, _ = frames.eci_to_ecef(r_eci, v_eci, t_unix_s.ravel())
        rel = r_ecef - site
        sin_el = rel @ up / np.linalg.norm(rel, axis=-1)
        elevation_deg: np.ndarray = np.degrees(np.arcsin(np.clip(sin_el, -1.0, 1.0))).reshape(t_unix_s.shape)
        return elevation_deg

    return elevation


def predict_passes(
    line1: str,
    line2: str,
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    min_elevation_deg: float,
    start_utc_ns: int,
    days: float,
) -> PredictedPasses:
    """Passes with AOS and LOS inside [start, start + days] (SGP4, AIAA 2006-6753; skyfield's method)."""
    if not days > 0.0:
        raise ValueError(f"days: expected a positive duration, got {days}")
    if not -90.0 <= min_elevation_deg < 90.0:
        raise ValueError(f"min_elevation_deg: {min_elevation_deg} outside [-90, 90)")
    elevation = _elevation_function(line1, line2, lat_deg, lon_deg, alt_m)
    t0 = start_utc_ns / NS_PER_S
    t_end = t0 + days * SECONDS_PER_DAY
    t = np.append(np.arange(t0, t_end, COARSE_STEP_S), t_end)
    el = elevation(t)
    peaks = np.flatnonzero((el[1:-1] >= el[:-2]) & (el[1:-1] > el[2:])) + 1
    t_max = _golden_maximum(elevation, t[peaks - 1], t[peaks + 1])
    el_max = elevation(t_max)
    keep = el_max >= min_elevation_deg
    t_max, el_max = t_max[keep], el_max[keep]
    below = el < min_elevation_deg
    position = np.searchsorted(t, t_max)
    last_below = np.maximum.accumulate(np.where(below, np.arange(t.size), -1))[position - 1]
    next_below = np.minimum.accumulate(np.where(below, np.arange(t.size), t.size)[::-1])[::-1][
        np.minimum(position, t.size - 1)
    ]
    complete = (last_below >= 0) & (next_below < t.size)
    t_max, el_max, last_below, next_below = (
        t_max[complete],
        el_max[complete],
        last_below[complete],
        next_below[complete],
    )
    crossing = lambda s: elevation(s) - min_elevation_deg  # noqa: E731
    aos = _bisect_crossing(crossing, t[last_below], t_max)
    los = _bisect_crossing(crossing, t[next_below], t_max)
    aos_ns, unique = np.unique(np.round(aos * NS_PER_S).astype(np.int64), return_index=True)
    return PredictedPasses(
        aos_ns,
        np.round(los[unique] * NS_PER_S).astype(np.int64),
        np.round(t_max[unique] * NS_PER_S).astype(np.int64),
        el_max[unique],
    )


def predict_station_passes(line1: str, line2: str, station: StationRecord, t0_ns: int, t1_ns: int) -> PredictedPasses:
    """Passes over an archived ground station with AOS and LOS inside [t0_ns, t1_ns] (see predict_passes)."""
    if t1_ns <= t0_ns:
        raise ValueError(f"t1_ns: {t1_ns} must be after t0_ns {t0_ns}")
    days = (t1_ns - t0_ns) / (SECONDS_PER_DAY * NS_PER_S)
    return predict_passes(
        line1, line2, station.lat_deg, station.lon_deg, station.alt_m, station.min_elevation_deg, t0_ns, days
    )


def _golden_maximum(f: Callable[[np.ndarray], np.ndarray], a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Vectorised golden-section search for the maximum of f on each [a, b] (unimodal)."""
    a, b = a.astype(float), b.astype(float)
    c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
    fc, fd = f(c), f(d)
    while a.size and np.max(b - a) > REFINE_TOLERANCE_S:
        left = fc > fd
        a, b = np.where(left, a, c), np.where(left, d, b)
        new = np.where(left, b - GOLDEN * (b - a), a + GOLDEN * (b - a))
        f_new = f(new)
        c, d, fc, fd = (
            np.where(left, new, d),
            np.where(left, c, new),
            np.where(left, f_new, fd),
            np.where(left, fc, f_new),
        )
    t_max: np.ndarray = 0.5 * (a + b)
    return t_max


def _bisect_crossing(g: Callable[[np.ndarray], np.ndarray], below: np.ndarray, above: np.ndarray) -> np.ndarray:
    """Vectorised bisection for g = 0 between times where g < 0 (``below``) and g >= 0 (``above``)."""
    below, above = below.astype(float), above.astype(float)
    while below.size and np.max(np.abs(above - below)) > REFINE_TOLERANCE_S:
        mid = 0.5 * (below + above)
        is_above = g(mid) >= 0.0
        above, below = np.where(is_above, mid, above), np.where(is_above, below, mid)
    t_cross: np.ndarray = 0.5 * (below + above)
    return t_cross


def assign_to_passes(t_utc_ns: np.ndarray, aos_ns: np.ndarray, los_ns: np.ndarray) -> np.ndarray:
    """Index of the pass (AOS-sorted, non-overlapping) containing each time, -1 outside every pass."""
    t, aos, los = (np.asarray(a, dtype=np.int64) for a in (t_utc_ns, aos_ns, los_ns))
    if aos.shape != los.shape or np.any(los < aos) or np.any(aos[1:] < los[:-1]):
        raise ValueError("aos_ns/los_ns: expected AOS-sorted, non-overlapping passes with LOS >= AOS")
    k = np.searchsorted(aos, t, side="right") - 1
    inside = (k >= 0) & (t <= los[np.maximum(k, 0)])
    return np.where(inside, k, -1)


def record_reception(archive: Archive, satellite: str, passes: list[PassRecord]) -> list[PassRecord]:
    """Store, per pass, the received span, packets and sequence-count gaps; returns updated records."""
    updated = []
    for p in passes:
        keys = archive.packet_keys(satellite, p.aos_ns, p.los_ns)
        keys.pop(DERIVED_APID, None)  # parameters derived on the ground were not received
        received = sum(t.size for t, _ in keys.values())
        missing = sum(int(sequence_gaps(seq).sum()) for _, seq in keys.values())
        starts = [int(t[0]) for t, _ in keys.values() if t.size]
        ends = [int(t[-1]) for t, _ in keys.values() if t.size]
        span = (min(starts), max(ends)) if starts else (None, None)
        archive.record_reception(p.id, span[0], span[1], received, missing)
        updated.append(
            PassRecord(
                p.id,
                p.station,
                p.aos_ns,
                p.los_ns,
                p.max_elevation_ns,
                p.max_elevation_deg,
                span[0],
                span[1],
                received,
                missing,
                p.origin,
            )
        )
    return updated


def _runs(t_ns: np.ndarray, free: np.ndarray, gap_ns: int) -> list[tuple[int, int]]:
    """[first, last] of the runs of sorted times where ``free`` holds, broken by a non-free sample or by more than
    gap_ns of silence."""
    index = np.flatnonzero(free)
    if index.size == 0:
        return []
    breaks = np.flatnonzero((np.diff(index) > 1) | (np.diff(t_ns[index]) > gap_ns))
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [index.size - 1]])
    return [(int(t_ns[index[a]]), int(t_ns[index[b]])) for a, b in zip(starts, ends)]


def passes_from_data(
    archive: Archive, satellite: str, t0_ns: int, t1_ns: int, station: str | None = None
) -> list[PassRecord]:
    """The passes holding the telemetry archived in [t0_ns, t1_ns], their reception recounted: predicted passes
    that cover it, and passes made from the data itself (origin "data", AOS/LOS = first/last sample, station
    ``station`` or unknown) where none does; data continuing a pass from data within DATA_PASS_GAP_S widens it,
    and passes from data it brings within DATA_PASS_GAP_S of each other become one (:func:`merge_data_passes`)."""
    gap = int(DATA_PASS_GAP_S * NS_PER_S)
    keys = archive.packet_keys(satellite, t0_ns, t1_ns)
    keys.pop(DERIVED_APID, None)
    if not keys:
        return []
    t = np.unique(np.concatenate([k[0] for k in keys.values()]))
    known = archive.passes(satellite, int(t[0]) - gap, int(t[-1]) + gap)
    predicted = [p for p in known if p.origin != "data"]
    covered = np.zeros(t.shape, dtype=bool)
    for p in predicted:
        covered |= (t >= p.aos_ns) & (t <= p.los_ns)
    touched = {p.id for p in predicted if p.aos_ns <= t[-1] and p.los_ns >= t[0]}
    for first, last in _runs(t, ~covered, gap):
        near = [p for p in known if p.origin == "data" and p.aos_ns - gap <= last and p.los_ns + gap >= first]
        if near:
            p = near[0]
            touched.add(archive.save_data_pass(satellite, min(p.aos_ns, first), max(p.los_ns, last), pass_id=p.id))
            touched.update(q.id for q in near[1:])  # merged into p below unless at another station
        else:
            touched.add(archive.save_data_pass(satellite, first, last, station))
    touched |= merge_data_passes(archive, satellite, int(t[0]), int(t[-1]))
    span = archive.passes(satellite, int(t[0]) - gap, int(t[-1]) + gap)
    return record_reception(archive, satellite, [p for p in span if p.id in touched])


def _same_station(group: list[PassRecord], p: PassRecord) -> bool:
    """A pass from data joins a group unless both name different ground stations (two stations, two passes)."""
    return p.station is None or all(q.station in (None, p.station) for q in group)


def merge_data_passes(archive: Archive, satellite: str, t0_ns: int, t1_ns: int) -> set[int]:
    """Merge the passes from data near [t0_ns, t1_ns] that overlap or lie within DATA_PASS_GAP_S of each other
    (two uploads of one pass, an upload filling the gap between two, the live stream and an upload made at once)
    into the earliest of them; ids of the merged passes (their reception is to be recounted)."""
    gap = int(DATA_PASS_GAP_S * NS_PER_S)
    known = archive.passes(satellite, t0_ns - gap, t1_ns + gap)
    predicted = [(p.aos_ns, p.los_ns) for p in known if p.origin != "data"]
    groups: list[list[PassRecord]] = []
    for p in (p for p in known if p.origin == "data"):  # AOS order
        los = max(q.los_ns for q in groups[-1]) if groups else None
        if (
            los is not None
            and p.aos_ns <= los + gap
            and _same_station(groups[-1], p)
            and not any(los < a and b < p.aos_ns for a, b in predicted)  # never across a predicted pass
        ):
            groups[-1].append(p)
        else:
            groups.append([p])
    kept: set[int] = set()
    for group in (g for g in groups if len(g) > 1):
        station = next((q.station for q in group if q.station is not None), None)
        aos, los = min(q.aos_ns for q in group), max(q.los_ns for q in group)
        kept.add(archive.merge_data_passes(satellite, group[0].id, [q.id for q in group[1:]], aos, los, station))
    return kept
