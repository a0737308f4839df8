"""Per-packet validation of one APID: time window, duplicates, sequence-count order and gaps.

Framing problems (bad header, unknown APID, bad length, truncation, CRC) are found by
:func:`telemetry.ccsds.frame_stream`; this module judges the framed packets of one APID: a
telecommand type, segmented sequence flags (where the definition does not accept segments) or a
wrong secondary header flag is ``bad_header``;
times outside the mission window are quarantined, exact repeats (same sequence count and time)
are counted as duplicates and dropped, and in time order the 14-bit source sequence count
(CCSDS 133.0-B-2 §4.1.3.4.3, modulo 16384) must advance by 1..8191 from the last accepted packet:
a repeat or a step back is ``non_monotonic_sequence`` unless the next packet continues from it
(a counter restart, accepted and reported as a gap of unknown size) or its count lies inside the
latest gap (its time stamped a little after the next packet's, as CTIM's clock does now and then:
accepted, the gap one packet smaller); a step of d > 1 is a gap of d − 1 packets. When the
packet period is known and the time step spans half the count range or more (an outage between
passes), the count alone is ambiguous: the step is the d + k·16384 nearest to Δt / period,
accepted if within PERIOD_TOLERANCE of it, else a restart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from telemetry.ccsds import SEQUENCE_COUNT_MODULUS, SEQUENCE_FLAGS_UNSEGMENTED, PrimaryHeaders
from telemetry.ingest_report import QuarantineRecord, SequenceGap

__all__ = [
    "PacketVerdict",
    "SequenceState",
    "validate_packets",
    "header_mismatch",
    "HEADER_PROBLEMS",
    "ACCEPTED",
    "NON_MONOTONIC",
    "RESTART",
    "INVALID_TIME",
]

ACCEPTED = 0
NON_MONOTONIC = 1
RESTART = -1
HALF_RANGE = SEQUENCE_COUNT_MODULUS // 2
INVALID_TIME = np.iinfo(np.int64).min  # stamp of a packet whose time code fields are out of range
RECENT_PACKETS = 65_536  # keys per APID remembered across chunks (1 MiB): repeats within them are duplicates
PERIOD_TOLERANCE = 0.05  # on-board periods drift by far less than 5 % (plus 2 packets of jitter)
HEADER_PROBLEMS = ("", "secondary header flag", "sequence flags (segmented)", "packet type (telecommand)")


@dataclass(frozen=True)
class PacketVerdict:
    """Indices (into the input arrays) of accepted packets in time order, and what was rejected."""

    accepted: np.ndarray
    quarantined: list[QuarantineRecord]
    duplicates: int
    gaps: list[SequenceGap]
    # the accepted packet the step to the next one is judged from (its count the furthest on: a packet kept inside a
    # gap behind it is not), an index into the input arrays; -1 when none of them (``previous`` stays it)
    ahead: int = -1


@njit(cache=True)
def _forward(a: int, b: int) -> int:
    """Steps from count a forward to count b, modulo 2^14."""
    return (b - a) % SEQUENCE_COUNT_MODULUS


@njit(cache=True)
def _sequence_kernel(count: np.ndarray, t_ns: np.ndarray, period_ns: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Status (ACCEPTED / NON_MONOTONIC) and missing-before count (RESTART = −1) of time-ordered counts, and the
    index of the packet the last step was judged from (-1 when there is none).

    period_ns ≤ 0: the packet period is unknown and long outages cannot be sized.
    """
    n = count.shape[0]
    status = np.zeros(n, dtype=np.int8)
    missing = np.zeros(n, dtype=np.int64)
    last = -1
    t_last = 0
    gap_at, gap_filled = -1, 0  # the packet after the latest gap; the count before it, or the latest kept inside
    ahead = -1  # the packet whose count and time are last, t_last
    for i in range(n):
        if last < 0:
            last, t_last, ahead = count[i], t_ns[i], i
            continue
        d = _forward(last, count[i])
        expected = (t_ns[i] - t_last) / period_ns if period_ns > 0 else 0.0
        if expected >= HALF_RANGE:
            steps = d + SEQUENCE_COUNT_MODULUS * round((expected - d) / SEQUENCE_COUNT_MODULUS)
            ok = steps >= 1 and abs(steps - expected) <= PERIOD_TOLERANCE * expected + 2
            missing[i] = steps - 1 if ok else RESTART
            last, t_last, gap_at, ahead = count[i], t_ns[i], -1, i
            continue
        if 1 <= d < HALF_RANGE:
            missing[i] = d - 1
            if d > 1:
                gap_at, gap_filled = i, last
            last, t_last, ahead = count[i], t_ns[i], i
            continue
        inside = gap_at >= 0 and 1 <= _forward(gap_filled, count[i]) < _forward(gap_filled, count[gap_at])
        if inside and missing[gap_at] > 0:  # inside the gap's unfilled part: not a count accepted already
            missing[gap_at] -= 1  # a packet of the latest gap, its time a little after the next one's: kept
            gap_filled = count[i]
            continue
        follows = i + 1 < n and 1 <= _forward(count[i], count[i + 1]) < HALF_RANGE
        resumes = i + 1 < n and 1 <= _forward(last, count[i + 1]) < HALF_RANGE
        if follows and not resumes:
            missing[i] = RESTART
            last, t_last, gap_at, ahead = count[i], t_ns[i], -1, i
        else:
            status[i] = NON_MONOTONIC
    return status, missing, ahead


def header_mismatch(headers: PrimaryHeaders, secondary_header: bool, segments: bool = False) -> np.ndarray:
    """Per packet, an index into HEADER_PROBLEMS of what contradicts a fixed-length telemetry packet (0 = nothing).

    Expected: packet type 0 = telemetry (CCSDS 133.0-B-2 §4.1.3.3.2), sequence flags 3 =
    unsegmented (§4.1.3.4.2.2) unless ``segments`` (the definition reads each segment on its own),
    secondary header flag set when the packet carries a time code (§4.1.3.3.3).
    """
    problems = np.zeros(headers.apid.shape, dtype=np.int8)
    problems[headers.secondary_header_flag != int(secondary_header)] = 1
    if not segments:
        problems[headers.sequence_flags != SEQUENCE_FLAGS_UNSEGMENTED] = 2
    problems[headers.packet_type != 0] = 3
    return problems


def validate_packets(
    apid: int,
    offset: np.ndarray,
    sequence_count: np.ndarray,
    t_utc_ns: np.ndarray,
    packet_octets: int,
    valid_from_utc_ns: int | None,
    valid_until_utc_ns: int | None,
    period_s: float | None = None,
    previous: SequenceState | None = None,
) -> PacketVerdict:
    """Judge the framed packets of one APID (CCSDS 133.0-B-2 §4.1.3.4.3 sequence counts), vectorised.

    ``previous`` holds the packets of this APID accepted before these (the earlier chunks of a file decoded in
    chunks): the step to the first packet is judged from the last of them, and a repeat of any of its recent
    keys is a duplicate, as one pass over the whole file judges them. Other packets older than its last are
    judged among themselves (late arrivals; the archive drops those it already holds).
    """
    offset = np.asarray(offset, dtype=np.int64)
    count = np.asarray(sequence_count, dtype=np.int64)
    t = np.asarray(t_utc_ns, dtype=np.int64)
    if not offset.shape == count.shape == t.shape:
        raise ValueError("offset, sequence_count, t_utc_ns: expected arrays of one length")
    low = np.iinfo(np.int64).min if valid_from_utc_ns is None else valid_from_utc_ns
    high = np.iinfo(np.int64).max if valid_until_utc_ns is None else valid_until_utc_ns
    in_window = (t >= low) & (t <= high)
    quarantined = [
        QuarantineRecord(
            int(offset[i]),
            packet_octets,
            "time_out_of_range",
            apid,
            int(count[i]),
            detail=f"t_utc_ns={int(t[i])}" if t[i] != INVALID_TIME else "invalid time code field",
        )
        for i in np.flatnonzero(~in_window)
    ]
    idx = np.flatnonzero(in_window)
    t_in = t[idx]
    if t_in.size > 1 and not bool(np.all(t_in[1:] > t_in[:-1])):  # else already in (time, count) order
        idx = idx[np.lexsort((count[idx], t_in))]
    period_ns = int(round(period_s * 1e9)) if period_s else 0
    if previous is None:
        return _judged(apid, offset, count, t, idx, period_ns, packet_octets, quarantined)
    older = t[idx] < previous.t_ns
    if older.any():
        seen = older & previous.holds(count[idx], t[idx])
        early = _judged(apid, offset, count, t, idx[older & ~seen], period_ns, packet_octets, quarantined)
    else:  # the usual case: every packet follows the previous ones
        seen, early = older, PacketVerdict(idx[:0], sorted(quarantined, key=lambda q: q.offset), 0, [])
    lead = offset.size  # the previous packet, appended: it leads the rest in time order
    count, t = np.append(count, previous.count), np.append(t, previous.t_ns)
    later = _judged(apid, offset, count, t, np.concatenate(([lead], idx[~older])), period_ns, packet_octets, [])
    return PacketVerdict(
        accepted=np.concatenate((early.accepted, later.accepted[1:])),
        quarantined=sorted(early.quarantined + later.quarantined, key=lambda q: q.offset),
        duplicates=int(seen.sum()) + early.duplicates + later.duplicates,
        gaps=early.gaps + later.gaps,
        ahead=-1 if later.ahead == lead else later.ahead,
    )


@dataclass(frozen=True)
class SequenceState:
    """The packets of one APID accepted so far in a stream decoded in chunks: the last one (sequence count and
    time) and the keys of the newest RECENT_PACKETS (bounded memory), time-ordered."""

    count: int
    t_ns: int
    recent_count: np.ndarray
    recent_t_ns: np.ndarray

    @classmethod
    def after(
        cls,
        previous: SequenceState | None,
        count: np.ndarray,
        t_ns: np.ndarray,
        ahead: tuple[int, int] | None = None,
    ) -> SequenceState | None:
        """The state once the time-ordered accepted packets (count, t_ns) follow ``previous``; its count and time
        are ``ahead`` (the packet PacketVerdict.ahead names) when given, else the newest packet's."""
        if count.size == 0:
            return previous
        in_order = t_ns.size < 2 or bool(np.all(t_ns[1:] >= t_ns[:-1]))
        if previous is not None and in_order and t_ns[0] >= previous.recent_t_ns[-1]:  # the usual case: they follow
            kept = RECENT_PACKETS - min(count.size, RECENT_PACKETS)  # of the previous keys, the newest
            count = np.concatenate((previous.recent_count[previous.recent_count.size - kept :], count))
            t_ns = np.concatenate((previous.recent_t_ns[previous.recent_t_ns.size - kept :], t_ns))
        elif previous is not None:
            count = np.concatenate((previous.recent_count, count))
            t_ns = np.concatenate((previous.recent_t_ns, t_ns))
            if t_ns.size > 1 and np.any(t_ns[1:] < t_ns[:-1]):  # late arrivals among them
                order = np.argsort(t_ns, kind="stable")
                count, t_ns = count[order], t_ns[order]
        count, t_ns = count[-RECENT_PACKETS:].astype(np.int64), t_ns[-RECENT_PACKETS:].astype(np.int64)
        last_count, last_t_ns = (int(count[-1]), int(t_ns[-1])) if ahead is None else ahead
        return cls(last_count, last_t_ns, count, t_ns)

    def holds(self, count: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
        """Per packet, whether (count, t_ns) is one of the recent keys."""
        at = np.searchsorted(self.recent_t_ns, t_ns, side="left")
        found = np.zeros(t_ns.shape, dtype=bool)
        for i in np.flatnonzero(at < self.recent_t_ns.size):
            j = at[i]
            while j < self.recent_t_ns.size and self.recent_t_ns[j] == t_ns[i]:
                found[i] |= self.recent_count[j] == count[i]
                j += 1
        return found


def _judged(
    apid: int,
    offset: np.ndarray,
    count: np.ndarray,
    t: np.ndarray,
    idx: np.ndarray,
    period_ns: int,
    packet_octets: int,
    quarantined: list[QuarantineRecord],
) -> PacketVerdict:
    """Verdict on the in-window packets ``idx`` in time order: exact repeats dropped, then the sequence kernel
    (a packet at idx[0] is never a repeat nor quarantined: the first one sets the count)."""
    repeat = np.zeros(idx.shape, dtype=bool)
    repeat[1:] = (t[idx[1:]] == t[idx[:-1]]) & (count[idx[1:]] == count[idx[:-1]])
    idx = idx[~repeat]
    status, missing, ahead = _sequence_kernel(count[idx], t[idx], period_ns)
    quarantined = quarantined + [
        QuarantineRecord(int(offset[i]), packet_octets, "non_monotonic_sequence", apid, int(count[i]))
        for i in idx[status == NON_MONOTONIC]
    ]
    kept, missing = idx[status == ACCEPTED], missing[status == ACCEPTED]
    gaps = [
        SequenceGap(
            apid, int(count[kept[j - 1]]), int(count[kept[j]]), int(missing[j]), int(t[kept[j - 1]]), int(t[kept[j]])
        )
        for j in np.flatnonzero(missing != 0)
    ]
    quarantined.sort(key=lambda q: q.offset)
    ahead_at = int(idx[ahead]) if ahead >= 0 else -1
    return PacketVerdict(kept, quarantined, int(repeat.sum()), gaps, ahead_at)
