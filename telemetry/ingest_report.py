"""The ingest report: what a decode/validation run accepted, quarantined (why, where), and found missing.

The seam to the archive (telemetry/archive): ``telemetry.decoding.decode_stream`` and
``telemetry.ground_files.read_ground_file`` return an :class:`DecodeResult` — time-ordered
:class:`SampleBatch` es (one per packet type) plus this report; the archive stores the batches
and keeps ``report.to_dict()`` as the upload's JSON report.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any, NoReturn, cast

import numpy as np

__all__ = [
    "QuarantineRecord",
    "SequenceGap",
    "ApidSummary",
    "IngestReport",
    "SampleBatch",
    "DecodeResult",
    "REASONS",
    "UndefinedPackets",
    "absent_in_rows",
    "absent_samples",
    "ColumnMatrices",
    "positions_by_dtype",
]

MAX_LISTED = 10_000  # quarantine records / gaps listed in one report; the rest are counted
REASONS = (
    "bad_header",
    "unknown_apid",
    "bad_length",
    "truncated",
    "crc_failure",
    "time_out_of_range",
    "non_monotonic_sequence",
    "bad_row",
    "unknown_parameter",
    "invalid_time",
)


@dataclass(frozen=True)
class QuarantineRecord:
    """One rejected stretch of input: its byte offset and length, the reason, and what is known of it."""

    offset: int
    length: int
    reason: str
    apid: int | None = None
    sequence_count: int | None = None
    line: int | None = None
    detail: str = ""

    def __post_init__(self) -> None:
        if self.reason not in REASONS:
            raise ValueError(f"reason: expected one of {REASONS}, got {self.reason!r}")


@dataclass(frozen=True)
class SequenceGap:
    """Packets missing between two accepted packets of one APID (missing = -1: the counter restarted)."""

    apid: int
    after_count: int
    before_count: int
    missing: int
    t_after_utc_ns: int
    t_before_utc_ns: int


@dataclass
class ApidSummary:
    """Per-APID tallies of one ingest (quarantined: rejected stretches whose header named this APID)."""

    apid: int
    packet: str
    accepted: int = 0
    duplicates: int = 0
    quarantined: int = 0
    missing: int = 0
    gaps: list[SequenceGap] = field(default_factory=list)
    t_first_utc_ns: int | None = None
    t_last_utc_ns: int | None = None
    packet_octets: dict[int, int] = field(default_factory=dict)
    definition_octets: int | None = None
    longer_than_definition: int = 0
    shorter_than_definition: int = 0
    segmented: int = 0  # packets whose sequence flags mark a segment (CCSDS 133.0-B-2 §4.1.3.4.2.2)

    def absorb(self, other: ApidSummary) -> None:
        """Add the tallies of the same APID from the next chunk of the input."""
        for name in (
            "accepted",
            "duplicates",
            "quarantined",
            "missing",
            "longer_than_definition",
            "shorter_than_definition",
            "segmented",
        ):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.gaps.extend(other.gaps[: max(MAX_LISTED - len(self.gaps), 0)])
        for octets, n in other.packet_octets.items():
            self.packet_octets[octets] = self.packet_octets.get(octets, 0) + n
        self.definition_octets = other.definition_octets
        firsts = [t for t in (self.t_first_utc_ns, other.t_first_utc_ns) if t is not None]
        lasts = [t for t in (self.t_last_utc_ns, other.t_last_utc_ns) if t is not None]
        self.t_first_utc_ns, self.t_last_utc_ns = min(firsts, default=None), max(lasts, default=None)


@dataclass
class IngestReport:
    """Outcome of decoding and validating one input (file, upload or live batch)."""

    source: str
    octets: int = 0
    packets_accepted: int = 0
    samples_accepted: int = 0
    duplicates: int = 0
    idle_packets: int = 0
    quarantined: list[QuarantineRecord] = field(default_factory=list)
    apids: dict[int, ApidSummary] = field(default_factory=dict)
    undefined_apids: dict[int, int] = field(default_factory=dict)

    quarantined_not_listed: dict[str, int] = field(default_factory=dict)

    def reason_counts(self) -> dict[str, int]:
        """Number of quarantined stretches per reason (listed or not)."""
        counts = Counter(q.reason for q in self.quarantined)
        counts.update(self.quarantined_not_listed)
        return dict(counts)

    def absorb(self, other: IngestReport, offset: int) -> None:
        """Add the report of the next chunk of the same input (its byte offsets start at ``offset``).

        At most MAX_LISTED quarantine records are kept; the others are counted by reason.
        """
        self.octets += other.octets
        self.packets_accepted += other.packets_accepted
        self.samples_accepted += other.samples_accepted
        self.duplicates += other.duplicates
        self.idle_packets += other.idle_packets
        room = max(MAX_LISTED - len(self.quarantined), 0)
        self.quarantined.extend(replace(q, offset=q.offset + offset) for q in other.quarantined[:room])
        for q in other.quarantined[room:]:
            self.quarantined_not_listed[q.reason] = self.quarantined_not_listed.get(q.reason, 0) + 1
        for apid, n in other.undefined_apids.items():
            self.undefined_apids[apid] = self.undefined_apids.get(apid, 0) + n
        for apid, summary in other.apids.items():
            mine = self.apids.setdefault(apid, ApidSummary(apid, summary.packet))
            mine.absorb(summary)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready mapping (what ``acs-twin ingest`` prints and the archive stores)."""
        return {
            "source": self.source,
            "octets": self.octets,
            "packets_accepted": self.packets_accepted,
            "samples_accepted": self.samples_accepted,
            "duplicates": self.duplicates,
            "idle_packets": self.idle_packets,
            "quarantined_count": len(self.quarantined) + sum(self.quarantined_not_listed.values()),
            "quarantine_reasons": self.reason_counts(),
            "quarantined": [asdict(q) for q in self.quarantined],
            "apids": {str(a): asdict(s) for a, s in sorted(self.apids.items())},
            "undefined_apids": {str(a): n for a, n in sorted(self.undefined_apids.items())},
        }

    def to_json(self, indent: int | None = 2) -> str:
        """The report as JSON text."""
        return json.dumps(self.to_dict(), indent=indent)


class ColumnMatrices(dict[str, np.ndarray]):
    """Parameter columns (name -> 1-D array, in their order) that are the rows of one 2-D matrix per dtype.

    ``groups``: (dtype, positions of its columns, matrix of shape (len(positions), n)). The archive reads each
    matrix with one numpy call per step (range, narrowing, compression) where a mapping of separate columns
    costs one call per column and step (CYGNSS: ~100 columns of a few thousand samples per archive chunk).
    """

    def __init__(self, names: Sequence[str], groups: Sequence[tuple[np.dtype, Sequence[int], np.ndarray]]) -> None:
        columns: list[np.ndarray | None] = [None] * len(names)
        for _, positions, matrix in groups:
            for row, position in enumerate(positions):
                columns[position] = matrix[row]
        if any(c is None for c in columns):
            raise ValueError("groups: every column needs a row of one matrix")
        super().__init__(zip(names, cast("list[np.ndarray]", columns)))
        self.groups = [(np.dtype(d), list(p), m) for d, p, m in groups]

    def _read_only(self, *args: object, **kwargs: object) -> NoReturn:
        """The matrices are what the archive reads: a column added, replaced or removed here would not be in them."""
        raise TypeError("ColumnMatrices is read-only: build a new one, or a dict of its columns, to change columns")

    __setitem__ = __delitem__ = update = pop = popitem = clear = setdefault = __ior__ = _read_only

    def __reduce__(self) -> tuple[type[ColumnMatrices], tuple[list[str], list[tuple[np.dtype, list[int], np.ndarray]]]]:
        """Pickled (a decoder process hands its batches on) and copied as what it is built from."""
        return type(self), (list(self), self.groups)

    def layout(self) -> list[tuple[np.dtype, list[int]]]:
        """Each matrix's dtype and the positions of its columns: equal for two parts of one packet layout."""
        return [(d, p) for d, p, _ in self.groups]

    @classmethod
    def concatenated(cls, parts: Sequence[Mapping[str, np.ndarray]], lengths: Sequence[int]) -> dict[str, np.ndarray]:
        """The columns of ``parts`` (same names in the same order, ``lengths`` samples each) joined end to end: one
        matrix per dtype filled by one call per part and dtype; separate columns (np.concatenate's dtype
        promotion) when a column's dtype differs between parts."""
        names = list(parts[0])
        first = parts[0]
        if isinstance(first, ColumnMatrices) and all(
            isinstance(p, ColumnMatrices) and p.layout() == first.layout() for p in parts[1:]
        ):  # the decoder's matrices, laid out alike (one layout): one copy per part and matrix, no column lists
            ends = np.cumsum([0, *lengths]).tolist()
            joined_groups = []
            for g, (dtype, positions, _) in enumerate(first.groups):
                matrix = np.empty((len(positions), ends[-1]), dtype=dtype)
                for piece, lo, hi in zip(parts, ends[:-1], ends[1:]):
                    matrix[:, lo:hi] = cast("ColumnMatrices", piece).groups[g][2]
                joined_groups.append((dtype, positions, matrix))
            return cls(names, joined_groups)
        columns = [list(p.values()) for p in parts]
        dtypes = [c.dtype for c in columns[0]]
        if not names or any([c.dtype for c in part] != dtypes for part in columns[1:]):
            return {n: np.concatenate([np.asarray(p[n]) for p in parts]) for n in names}
        ends = np.cumsum([0, *lengths]).tolist()
        groups = []
        for members in positions_by_dtype(columns[0]).values():
            joined = np.concatenate([part[members[0]][:0] for part in columns]).dtype  # np.concatenate's: native order
            matrix = np.empty((len(members), ends[-1]), dtype=joined)
            for part, lo, hi in zip(columns, ends[:-1], ends[1:]):
                matrix[:, lo:hi] = [part[i] for i in members]  # one conversion in C (np.stack: ~1 us per column)
            groups.append((joined, members, matrix))
        return cls(names, groups)


def positions_by_dtype(columns: Sequence[np.ndarray]) -> dict[np.dtype, list[int]]:
    """Positions of ``columns`` grouped by dtype (dtypes in order of first use, positions in order)."""
    positions: dict[np.dtype, list[int]] = {}
    for i, column in enumerate(columns):
        positions.setdefault(column.dtype, []).append(i)
    return positions


@dataclass(frozen=True)
class SampleBatch:
    """Accepted samples of one packet type, in time order: times, counts, raw packets and values by parameter.

    ``t_utc_ns`` int64 (n,); ``sequence_count`` uint16 (n,) (zeros for ground files);
    ``packets`` (n, L) uint8 byte-exact raw packets (None for ground files);
    ``values`` parameter name → (n,) engineering values (float64, or int64 for uncalibrated integers
    and enumeration codes; float64 with NaN where a variable layout has no such element), derived
    parameters included. Packets of several lengths come as ``packets`` 1-D (all octets, in order)
    with ``packet_lengths`` (n,).
    """

    packet: str
    apid: int
    t_utc_ns: np.ndarray
    sequence_count: np.ndarray
    values: dict[str, np.ndarray]
    packets: np.ndarray | None = None
    packet_lengths: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        """Number of parameter samples (packets × parameters, less the NaN where a layout lacks a parameter)."""
        return len(self.t_utc_ns) * len(self.values) - absent_samples(self.values)


def absent_samples(values: Mapping[str, np.ndarray]) -> int:
    """NaN elements of float columns of one length: packets whose layout lacks the parameter (no such sample).
    The float columns are counted as one matrix (a batch's ~15 of them: ~40 us -> ~20 us, issue 12)."""
    if isinstance(values, ColumnMatrices):  # the decoder's float matrices as they are, not stacked again
        return sum(absent_in_rows(matrix) for dtype, _, matrix in values.groups if dtype.kind == "f")
    floats = [v for v in values.values() if v.dtype.kind == "f"]
    return absent_in_rows(np.stack(floats)) if floats else 0


def absent_in_rows(values: np.ndarray) -> int:
    """NaN elements of a float column, or of a matrix whose rows are columns (what :func:`absent_samples` counts).
    A row's min is NaN when it holds any (numpy propagates NaN): only such rows are searched, cheaper than isnan."""
    if values.dtype.kind != "f" or not values.size:
        return 0
    rows = values.reshape(-1, values.shape[-1])
    holding = np.flatnonzero(np.isnan(rows.min(axis=1)))
    return int(np.count_nonzero(np.isnan(rows[holding]))) if holding.size else 0


@dataclass(frozen=True)
class UndefinedPackets:
    """Well-framed packets of an APID the dictionary does not define, kept raw (octets in order, lengths)."""

    apid: int
    packets: np.ndarray
    packet_lengths: np.ndarray
    sequence_count: np.ndarray


@dataclass(frozen=True)
class DecodeResult:
    """Decoded, validated batches, raw packets of undefined APIDs, and the report of one input."""

    batches: list[SampleBatch]
    report: IngestReport
    undefined: list[UndefinedPackets] = field(default_factory=list)
    consumed: int = 0
