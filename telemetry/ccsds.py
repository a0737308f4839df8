"""CCSDS space packets: primary header, secondary-header time codes, CRC, and stream framing.

Primary header per CCSDS 133.0-B-2 §4.1.3 (6 octets, big-endian): packet version number (3 bits,
'000', §4.1.3.2), packet type (1 bit, 0 = telemetry, §4.1.3.3.2), secondary header flag (1 bit,
§4.1.3.3.3), APID (11 bits, §4.1.3.3.4; '11111111111' = idle packet, §4.1.3.3.4.4), sequence flags
(2 bits, §4.1.3.4.2: 3 = unsegmented), packet sequence count (14 bits, modulo 16384, §4.1.3.4.3) and
packet data length (16 bits = octets in the data field − 1, §4.1.3.5).
Time codes per CCSDS 301.0-B-4: CUC (§3.2, coarse seconds + binary fraction) and CDS (§3.3, days,
milliseconds of day, optional µs or ps of millisecond). All times leave this module as int64
nanoseconds of UTC since the Unix epoch (DESIGN.md). The packet error control field is
CRC-16/CCITT (poly 0x1021, preset 0xFFFF) over the whole packet but its last two octets
(ECSS-E-ST-70-41C §7.4.1 / CCSDS 132.0-B-3 §4.1.4.2).
Framing a mixed-APID stream is sequential (each length field locates the next packet), so it runs
as a numba kernel; everything after framing is vectorised over packets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = [
    "PRIMARY_HEADER_OCTETS",
    "SEQUENCE_COUNT_MODULUS",
    "IDLE_APID",
    "FrameCode",
    "TimeCode",
    "PrimaryHeaders",
    "parse_primary_headers",
    "encode_primary_headers",
    "decode_time",
    "time_fields_valid",
    "scale_to_utc",
    "encode_time",
    "crc16_ccitt",
    "MAX_PACKET_OCTETS",
    "frame_stream",
    "Frames",
    "unwrap_packets",
]

PRIMARY_HEADER_OCTETS = 6
SEQUENCE_COUNT_MODULUS = 1 << 14
IDLE_APID = 0x7FF
APID_COUNT = 1 << 11
SEQUENCE_FLAGS_UNSEGMENTED = 3
NS_PER_S = 1_000_000_000
NS_PER_DAY = 86_400 * NS_PER_S
CCSDS_EPOCH_NS = -4383 * NS_PER_DAY  # 1958-01-01 (CCSDS 301.0-B-4 §3.2.2.1.1 level 1 epoch)
MS_PER_DAY_WITH_LEAP = 86_401_000  # a UTC day with a positive leap second
TIME_SCALE_OFFSET_S = {"UTC": None, "TAI": 0, "GPS": -19}  # scale − TAI where leap seconds apply


_OK, _BAD_HEADER, _UNKNOWN_APID, _BAD_LENGTH, _TRUNCATED, _CRC_FAILURE, _IDLE, _UNDEFINED = range(8)
UNDEFINED_CHAIN = 4  # well-formed packets of undefined APIDs followed to confirm one's length field
MAX_PACKET_OCTETS = PRIMARY_HEADER_OCTETS + 65_536  # CCSDS 133.0-B-2 §4.1.3.5


class FrameCode:
    """Outcome codes of framing one stretch of a byte stream (0 = a packet to decode)."""

    OK = _OK
    BAD_HEADER = _BAD_HEADER
    UNKNOWN_APID = _UNKNOWN_APID
    BAD_LENGTH = _BAD_LENGTH
    TRUNCATED = _TRUNCATED
    CRC_FAILURE = _CRC_FAILURE
    IDLE = _IDLE
    UNDEFINED = _UNDEFINED
    NAMES = ("ok", "bad_header", "unknown_apid", "bad_length", "truncated", "crc_failure", "idle", "undefined_apid")


@dataclass(frozen=True)
class TimeCode:
    """A CUC or CDS time code layout (CCSDS 301.0-B-4 §3.2, §3.3), its epoch and its time scale.

    The P-field is implicit (agreed in the dictionary, not sent). ``epoch_ns`` is the epoch's
    calendar date-time in the code's own time scale, as ns since
    1970-01-01T00:00:00 of that scale; ``time_scale`` is UTC (elapsed time read as UTC without leap
    seconds, POSIX style), TAI (CCSDS level-1 CUC, 301.0-B-4 §3.2.2.1.1) or GPS (TAI − 19 s).
    """

    format: str
    coarse_octets: int = 4
    fine_octets: int = 2
    day_octets: int = 2
    submillisecond_octets: int = 2
    epoch_ns: int = CCSDS_EPOCH_NS
    time_scale: str = "UTC"

    def __post_init__(self) -> None:
        if self.format not in ("CUC", "CDS"):
            raise ValueError(f"time_code.format: expected 'CUC' or 'CDS', got {self.format!r}")
        if self.time_scale not in TIME_SCALE_OFFSET_S:
            raise ValueError(
                f"time_code.time_scale: expected one of {sorted(TIME_SCALE_OFFSET_S)}, got {self.time_scale!r}"
            )
        if self.format == "CUC" and not (1 <= self.coarse_octets <= 4 and 0 <= self.fine_octets <= 3):
            raise ValueError("time_code: CUC needs 1-4 coarse and 0-3 fine octets (301.0-B-4 §3.2.1)")
        if self.format == "CDS" and (self.day_octets not in (2, 3) or self.submillisecond_octets not in (0, 2, 4)):
            raise ValueError("time_code: CDS needs 2 or 3 day octets and 0, 2 or 4 sub-ms octets (§3.3.1)")

    @property
    def octets(self) -> int:
        """Length of the time code's T-field in octets."""
        if self.format == "CUC":
            return self.coarse_octets + self.fine_octets
        return self.day_octets + 4 + self.submillisecond_octets


@dataclass(frozen=True)
class PrimaryHeaders:
    """Fields of N primary headers as arrays (CCSDS 133.0-B-2 §4.1.3)."""

    version: np.ndarray
    packet_type: np.ndarray
    secondary_header_flag: np.ndarray
    apid: np.ndarray
    sequence_flags: np.ndarray
    sequence_count: np.ndarray
    packet_octets: np.ndarray


def _big_endian_uint(octets: np.ndarray) -> np.ndarray:
    """Unsigned big-endian integers of the rows of an (n, k ≤ 8) uint8 array, as uint64."""
    value = np.zeros(octets.shape[0], dtype=np.uint64)
    for k in range(octets.shape[1]):
        value = (value << np.uint64(8)) | octets[:, k].astype(np.uint64)
    return value


def parse_primary_headers(headers: np.ndarray) -> PrimaryHeaders:
    """Primary header fields of an (n, ≥6) uint8 array of packets (CCSDS 133.0-B-2 §4.1.3)."""
    h = np.asarray(headers)
    if h.dtype != np.uint8 or h.ndim != 2 or h.shape[1] < PRIMARY_HEADER_OCTETS:
        raise ValueError(f"headers: expected (n, >=6) uint8, got {h.dtype} {h.shape}")
    w0 = (h[:, 0].astype(np.uint16) << 8) | h[:, 1]
    w1 = (h[:, 2].astype(np.uint16) << 8) | h[:, 3]
    w2 = (h[:, 4].astype(np.int64) << 8) | h[:, 5]
    return PrimaryHeaders(
        version=(w0 >> 13).astype(np.uint8),
        packet_type=((w0 >> 12) & 1).astype(np.uint8),
        secondary_header_flag=((w0 >> 11) & 1).astype(np.uint8),
        apid=(w0 & 0x7FF).astype(np.uint16),
        sequence_flags=(w1 >> 14).astype(np.uint8),
        sequence_count=(w1 & 0x3FFF).astype(np.uint16),
        packet_octets=w2 + PRIMARY_HEADER_OCTETS + 1,
    )


def encode_primary_headers(
    apid: np.ndarray | int,
    sequence_count: np.ndarray,
    packet_octets: int,
    secondary_header: bool = True,
) -> np.ndarray:
    """(n, 6) uint8 telemetry primary headers, unsegmented (CCSDS 133.0-B-2 §4.1.3)."""
    count = np.asarray(sequence_count, dtype=np.int64)
    apid_arr = np.broadcast_to(np.asarray(apid, dtype=np.int64), count.shape)
    if np.any((apid_arr < 0) | (apid_arr >= APID_COUNT)):
        raise ValueError("apid: must lie in 0..2047 (11 bits)")
    if packet_octets < PRIMARY_HEADER_OCTETS + 1 or packet_octets > PRIMARY_HEADER_OCTETS + 65536:
        raise ValueError(f"packet_octets: must lie in 7..65542, got {packet_octets}")
    w0 = (int(secondary_header) << 11) | apid_arr
    w1 = (SEQUENCE_FLAGS_UNSEGMENTED << 14) | (count % SEQUENCE_COUNT_MODULUS)
    w2 = np.full(count.shape, packet_octets - PRIMARY_HEADER_OCTETS - 1, dtype=np.int64)
    words = np.stack([w0, w1, w2], axis=-1).astype(">u2")
    return words.view(np.uint8).reshape(count.shape + (6,))


def _leap_table() -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """UTC ns where TAI − UTC steps, and TAI − UTC (ns) from then on (IERS Bulletin C, skyfield's builtin table)."""
    from skyfield.api import load

    ts = load.timescale(builtin=True)
    starts_ns = np.rint((np.asarray(ts.leap_dates) - 2_440_587.5) * 86_400).astype(np.int64) * NS_PER_S
    return starts_ns, np.rint(np.asarray(ts.leap_offsets)).astype(np.int64) * NS_PER_S


_LEAPS: list[tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]] = []


def _tai_minus_utc_ns(boundaries: str, t_ns: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """TAI − UTC (ns) at times given in UTC ('utc') or as TAI labels ('tai'); the 1972 value before 1972."""
    if not _LEAPS:
        _LEAPS.append(_leap_table())
    starts_utc, offset = _LEAPS[0]
    starts = starts_utc if boundaries == "utc" else starts_utc + offset
    return offset[np.clip(np.searchsorted(starts, t_ns, side="right") - 1, 0, None)]


def scale_to_utc(t_scale_ns: npt.NDArray[np.int64], scale: str) -> npt.NDArray[np.int64]:
    """UTC ns of times labelled in a time scale (UTC, TAI, GPS)."""
    offset_s = TIME_SCALE_OFFSET_S[scale]
    if offset_s is None:
        return t_scale_ns
    t_tai = t_scale_ns - offset_s * NS_PER_S
    return t_tai - _tai_minus_utc_ns("tai", t_tai)


def _utc_to_scale(t_utc_ns: npt.NDArray[np.int64], scale: str) -> npt.NDArray[np.int64]:
    """Labels in a time scale (UTC, TAI, GPS) of UTC ns times."""
    offset_s = TIME_SCALE_OFFSET_S[scale]
    if offset_s is None:
        return t_utc_ns
    return t_utc_ns + _tai_minus_utc_ns("utc", t_utc_ns) + offset_s * NS_PER_S


def decode_time(octets: np.ndarray, code: TimeCode) -> np.ndarray:
    """UTC ns since the Unix epoch of (n, k) CUC or CDS T-fields (CCSDS 301.0-B-4 §3.2.1, §3.3.1)."""
    t = np.asarray(octets)
    if t.dtype != np.uint8 or t.ndim != 2 or t.shape[1] != code.octets:
        raise ValueError(f"octets: expected (n, {code.octets}) uint8 for {code}, got {t.dtype} {t.shape}")
    if code.format == "CUC":
        coarse = _big_endian_uint(t[:, : code.coarse_octets]).astype(np.int64)
        fine = _big_endian_uint(t[:, code.coarse_octets :]).astype(np.int64)
        bits = 8 * code.fine_octets
        fine_ns = (fine * NS_PER_S + (1 << bits >> 1)) >> bits if bits else 0
        return scale_to_utc(code.epoch_ns + coarse * NS_PER_S + fine_ns, code.time_scale)
    day = _big_endian_uint(t[:, : code.day_octets]).astype(np.int64)
    ms = _big_endian_uint(t[:, code.day_octets : code.day_octets + 4]).astype(np.int64)
    sub = _big_endian_uint(t[:, code.day_octets + 4 :]).astype(np.int64)
    sub_ns_by_octets: dict[int, np.ndarray | int] = {0: 0, 2: sub * 1_000, 4: sub // 1_000}
    sub_ns = sub_ns_by_octets[code.submillisecond_octets]
    return scale_to_utc(code.epoch_ns + day * NS_PER_DAY + ms * 1_000_000 + sub_ns, code.time_scale)


def time_fields_valid(octets: np.ndarray, code: TimeCode) -> np.ndarray:
    """Per T-field: False where a CDS sub-field exceeds its range (ms of day ≤ 86,400,999 with a leap second,
    µs < 1,000, ps < 10⁹; CCSDS 301.0-B-4 §3.3.1); CUC fields are always well formed."""
    t = np.asarray(octets)
    if code.format == "CUC":
        return np.ones(t.shape[0], dtype=bool)
    ms = _big_endian_uint(t[:, code.day_octets : code.day_octets + 4])
    sub = _big_endian_uint(t[:, code.day_octets + 4 :])
    sub_limit = {0: 1, 2: 1_000, 4: 1_000_000_000}[code.submillisecond_octets]
    return (ms < MS_PER_DAY_WITH_LEAP) & (sub < sub_limit)


def _to_octets(value: np.ndarray, n_octets: int) -> np.ndarray:
    """(n, n_octets) big-endian uint8 of non-negative int64 values."""
    shifts = 8 * np.arange(n_octets - 1, -1, -1, dtype=np.int64)
    return ((value[:, None] >> shifts) & 0xFF).astype(np.uint8)


def encode_time(t_utc_ns: np.ndarray, code: TimeCode) -> np.ndarray:
    """(n, k) T-fields of UTC ns times, nearest code tick (CCSDS 301.0-B-4 §3.2.1, §3.3.1)."""
    dt = _utc_to_scale(np.asarray(t_utc_ns, dtype=np.int64).reshape(-1), code.time_scale) - code.epoch_ns
    if np.any(dt < 0):
        raise ValueError("t_utc_ns: times before the time code's epoch cannot be encoded")
    if code.format == "CUC":
        bits = 8 * code.fine_octets
        coarse, ns = np.divmod(dt, NS_PER_S)
        fine = ((ns << bits) + NS_PER_S // 2) // NS_PER_S
        carry = fine >> bits
        coarse, fine = coarse + carry, fine & ((1 << bits) - 1)
        if np.any(coarse >= 1 << (8 * code.coarse_octets)):
            raise ValueError("t_utc_ns: beyond the range of the CUC coarse time")
        return np.concatenate([_to_octets(coarse, code.coarse_octets), _to_octets(fine, code.fine_octets)], axis=1)
    sub_unit = {0: 1_000_000, 2: 1_000, 4: 1}[code.submillisecond_octets]
    day, ns_of_day = np.divmod(dt, NS_PER_DAY)
    ms, sub_ns = np.divmod(ns_of_day, 1_000_000)
    sub = sub_ns // sub_unit if code.submillisecond_octets != 4 else sub_ns * 1_000
    parts = [_to_octets(day, code.day_octets), _to_octets(ms, 4)]
    if code.submillisecond_octets:
        parts.append(_to_octets(sub, code.submillisecond_octets))
    return np.concatenate(parts, axis=1)


def _crc16_tables() -> np.ndarray:
    """(4, 256) slicing tables of CRC-16/CCITT (poly 0x1021, MSB first): row j = CRC of an octet + j zero octets."""
    tables = np.zeros((4, 256), dtype=np.int64)
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
        tables[0, byte] = crc & 0xFFFF
    for j in range(1, 4):
        prev = tables[j - 1]
        tables[j] = ((prev << 8) & 0xFFFF) ^ tables[0, prev >> 8]
    return tables


_CRC_TABLES = _crc16_tables()
_CRC_TABLE = _CRC_TABLES[0].astype(np.uint16)


@njit(cache=True, nogil=True)
def _crc16_1(buf: np.ndarray, start: int, stop: int, tables: np.ndarray) -> int:
    """CRC-16/CCITT (preset 0xFFFF) of buf[start:stop], four octets per step by linearity (compiled kernel)."""
    crc = 0xFFFF
    i = start
    while i + 4 <= stop:
        crc = (
            tables[3, (crc >> 8) ^ buf[i]]
            ^ tables[2, (crc & 0xFF) ^ buf[i + 1]]
            ^ tables[1, buf[i + 2]]
            ^ tables[0, buf[i + 3]]
        )
        i += 4
    while i < stop:
        crc = ((crc << 8) & 0xFFFF) ^ tables[0, ((crc >> 8) ^ buf[i]) & 0xFF]
        i += 1
    return crc


def crc16_ccitt(data: bytes | np.ndarray) -> np.ndarray | int:
    """CRC-16/CCITT-FALSE of a byte string, or of each row of an (n, k) uint8 array (ECSS-E-ST-70-41C §B.1)."""
    arr = np.frombuffer(data, dtype=np.uint8) if isinstance(data, (bytes, bytearray)) else np.asarray(data)
    if arr.dtype != np.uint8:
        raise ValueError(f"data: expected bytes or uint8 array, got {arr.dtype}")
    if arr.ndim == 1:
        return int(_crc16_1(arr, 0, arr.shape[0], _CRC_TABLES))
    crc = np.full(arr.shape[0], 0xFFFF, dtype=np.uint16)
    for k in range(arr.shape[1]):
        crc = (crc << np.uint16(8)) ^ _CRC_TABLE[((crc >> np.uint16(8)) ^ arr[:, k]) & 0xFF]
    return crc


@njit(cache=True, nogil=True)
def _header_fits(buf: np.ndarray, p: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray) -> bool:
    """True when a known, right-length, complete packet (CRC valid where defined) starts at p."""
    n = buf.shape[0]
    if p + PRIMARY_HEADER_OCTETS > n or (buf[p] >> 5) != 0:
        return False
    apid = ((np.int64(buf[p]) & 7) << 8) | buf[p + 1]
    size = ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
    if lengths[apid] == 0 or (lengths[apid] > 0 and size != lengths[apid]) or p + size > n:
        return False
    if crc[apid]:
        crc_ok: bool = _crc16_1(buf, p, p + size - 2, table) == ((np.int64(buf[p + size - 2]) << 8) | buf[p + size - 1])
        return crc_ok
    return True


@njit(cache=True, nogil=True, inline="always")
def _fit(buf: np.ndarray, p: int, lengths: np.ndarray, crc: np.ndarray) -> int:
    """_header_fits before its CRC: 0 (no dictionary packet at p), 1 (one fits), 2 (one fits if its CRC holds).

    A kernel that calls this (inlined, no call of its own) and _header_fits only for 2 frames ~30 % faster than
    one calling _header_fits for every packet (numba calls of a function that makes calls cost ~40 ns here)."""
    n = buf.shape[0]
    if p + PRIMARY_HEADER_OCTETS > n or (buf[p] >> 5) != 0:
        return 0
    apid = ((np.int64(buf[p]) & 7) << 8) | buf[p + 1]
    size = ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
    if lengths[apid] == 0 or (lengths[apid] > 0 and size != lengths[apid]) or p + size > n:
        return 0
    return 2 if crc[apid] else 1


@njit(cache=True, nogil=True, inline="always")
def _well_formed(buf: np.ndarray, p: int) -> bool:
    """A version-0 header at p whose packet ends within buf (any APID); inlined: _bad_link makes no call (see _fit)."""
    n = buf.shape[0]
    if p + PRIMARY_HEADER_OCTETS > n or (buf[p] >> 5) != 0:
        return False
    ends_within: bool = p + ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1 <= n
    return ends_within


@njit(cache=True, nogil=True)
def _classify(buf: np.ndarray, p: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray) -> int:
    """Why no packet of the dictionary starts at p (a FrameCode)."""
    n = buf.shape[0]
    if p + PRIMARY_HEADER_OCTETS > n:
        return _TRUNCATED
    if (buf[p] >> 5) != 0:
        return _BAD_HEADER
    apid = ((np.int64(buf[p]) & 7) << 8) | buf[p + 1]
    size = ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
    if lengths[apid] == 0:
        return _UNKNOWN_APID
    if lengths[apid] > 0 and size != lengths[apid]:
        return _BAD_LENGTH
    if p + size > n:
        return _TRUNCATED
    if crc[apid] and not _header_fits(buf, p, lengths, crc, table):
        return _CRC_FAILURE
    return _TRUNCATED


@njit(cache=True, nogil=True)
def _idle_until(buf: np.ndarray, p: int, q: int) -> bool:
    """True when exactly one idle packet (APID 2047, CCSDS 133.0-B-2 §4.1.3.3.4.4) spans [p, q)."""
    if not _well_formed(buf, p) or (((np.int64(buf[p]) & 7) << 8) | buf[p + 1]) != IDLE_APID:
        return False
    spans: bool = p + ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1 == q
    return spans


@njit(cache=True, nogil=True, inline="always")
def _bad_link(buf: np.ndarray, x: int) -> bool:
    """No link of a confirmation chain at x: not a whole version-0 packet, a telecommand, or idle (segmented
    telemetry packets link: missions send them, e.g. IMAP-HIT science and IMAP-Lo direct events)."""
    if not _well_formed(buf, x) or (buf[x] >> 4) & 1:
        return True
    idle: bool = (((np.int64(buf[x]) & 7) << 8) | buf[x + 1]) == IDLE_APID
    return idle


@njit(cache=True, nogil=True)
def _hides_packet(buf: np.ndarray, x: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray) -> bool:
    """True when a confirmed dictionary packet (its CRC valid, or another one fitting where it ends) starts inside
    the well-formed packet at x: its length field would hide real packets, so it is garbage."""
    n = buf.shape[0]
    end = x + ((np.int64(buf[x + 4]) << 8) | buf[x + 5]) + PRIMARY_HEADER_OCTETS + 1
    for y in range(x + 1, end):
        fit = _fit(buf, y, lengths, crc)
        if fit == 2 and _header_fits(buf, y, lengths, crc, table):
            return True
        if fit == 1:
            q = y + ((np.int64(buf[y + 4]) << 8) | buf[y + 5]) + PRIMARY_HEADER_OCTETS + 1
            fit_q = 0 if q >= n else _fit(buf, q, lengths, crc)
            if fit_q == 1 or (fit_q == 2 and _header_fits(buf, q, lengths, crc, table)):
                return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _doubtful_link(buf: np.ndarray, x: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray) -> bool:
    """A segmented packet at x hiding a confirmed dictionary packet (see _hides_packet). Segmented packets link
    (missions send them), but garbage that reads as one is four times likelier than an unsegmented one: it must
    not swallow the packets it covers (a truncated packet confirmed by one such link did, found by fuzzing)."""
    segmented: bool = buf[x + 2] >> 6 != SEQUENCE_FLAGS_UNSEGMENTED
    return segmented and _hides_packet(buf, x, lengths, crc, table)


@njit(cache=True, nogil=True, inline="always")
def _weak_hiding(
    buf: np.ndarray, p: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray, chain: np.ndarray
) -> bool:
    """The packet at p, its length field just confirmed by the links from its end (``chain``, see _links_confirm),
    hides a confirmed dictionary packet while fewer than UNDEFINED_CHAIN links confirmed it: garbage does form one
    link that ends where a real packet starts (a truncated packet did so, hiding 14, found by fuzzing); a full
    chain is left unscanned (a scan costs ~15-20 ns an octet here)."""
    weak: bool = chain[1] < UNDEFINED_CHAIN and _hides_packet(buf, p, lengths, crc, table)
    return weak


@njit(cache=True, nogil=True, inline="always")
def _links_confirm(
    buf: np.ndarray, q: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray, chain: np.ndarray
) -> bool:
    """True when the data ends at q, a dictionary packet fits at q, or UNDEFINED_CHAIN well-formed
    telemetry packets follow one another from q (each where the previous one's length field ends) before either.

    This confirms a length field that no dictionary definition checks: garbage rarely forms even two links.
    ``chain`` [start, links, end, verdict] remembers the last walk (``links`` good links from start end at
    ``end``, where the walk met the data's end or a fitting packet: verdict 1, a bad link: 0, or stopped: -1),
    so the walk from the next packet of a confirmed run reads one more link, not UNDEFINED_CHAIN.
    """
    n = buf.shape[0]
    start = chain[0]
    if chain[1] > 0 and q == start + ((np.int64(buf[start + 4]) << 8) | buf[start + 5]) + PRIMARY_HEADER_OCTETS + 1:
        chain[0], chain[1] = q, chain[1] - 1  # one link on: the rest of the walk holds
    elif start != q:
        chain[0], chain[1], chain[2], chain[3] = q, 0, q, -1
    while chain[3] == -1 and chain[1] < UNDEFINED_CHAIN:
        x = chain[2]
        fit = 0 if x == n else _fit(buf, x, lengths, crc)  # _header_fits, the CRC checked only where one applies
        if x == n or fit == 1 or (fit == 2 and _header_fits(buf, x, lengths, crc, table)):
            chain[3] = 1
        elif _bad_link(buf, x) or _doubtful_link(buf, x, lengths, crc, table):
            chain[3] = 0
        else:
            chain[1] += 1
            chain[2] = x + ((np.int64(buf[x + 4]) << 8) | buf[x + 5]) + PRIMARY_HEADER_OCTETS + 1
    confirmed: bool = chain[1] >= UNDEFINED_CHAIN or chain[3] == 1
    return confirmed


@njit(cache=True, nogil=True)
def _other_length_confirmed(
    buf: np.ndarray, p: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray, chain: np.ndarray
) -> bool:
    """A well-formed packet of a defined APID whose length differs from its definition, its length field confirmed
    by the links from its end and hiding no confirmed packet; the decoder reports the length mismatch."""
    if not _well_formed(buf, p):
        return False
    apid = ((np.int64(buf[p]) & 7) << 8) | buf[p + 1]
    if lengths[apid] <= 0 or crc[apid] or (buf[p] >> 4) & 1:
        return False
    q = p + ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
    return _links_confirm(buf, q, lengths, crc, table, chain) and not _weak_hiding(buf, p, lengths, crc, table, chain)


@njit(cache=True, nogil=True, inline="always")
def _walk_links(buf: np.ndarray, q: int, links: int, stopped: bool) -> tuple[int, int, bool, bool]:
    """Walk on from q along length fields until UNDEFINED_CHAIN + 1 packets (``links`` walked already) end within
    buf or a header that is not version 0 stops the walk (``stopped``): (where the walk is, links, stopped, and
    False when buf ends first -- what follows buf could then change the segment the walk started at)."""
    n = buf.shape[0]
    while not stopped and links < UNDEFINED_CHAIN + 1:
        if q + PRIMARY_HEADER_OCTETS > n:
            return q, links, stopped, False
        if (buf[q] >> 5) != 0:
            return q, links, True, True
        q += ((np.int64(buf[q + 4]) << 8) | buf[q + 5]) + PRIMARY_HEADER_OCTETS + 1
        if q > n:
            return q, links, stopped, False
        links += 1
    return q, links, stopped, True


@njit(cache=True, nogil=True)
def _next_fit(buf: np.ndarray, start: int, stop: int, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray) -> int:
    """First q in [start, stop) where a dictionary packet fits, else stop."""
    q = start
    while q < stop and not _header_fits(buf, q, lengths, crc, table):
        q += 1
    return q


@njit(cache=True, nogil=True)
def _frame_kernel(
    buf: np.ndarray, lengths: np.ndarray, crc: np.ndarray, table: np.ndarray, keep_undefined: bool, final: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Segments (offset, length, FrameCode) covering buf up to the octet returned: packets, and quarantined
    stretches between them.

    A dictionary packet that fits at p (known APID, its length, CRC where defined) is taken when its
    CRC confirms it or another dictionary packet fits right after it (or the data ends); an
    unconfirmed one is cut short (truncated) at the first packet that fits inside it, else taken. Anything else
    (unknown APIDs included: their length field is never trusted, so garbage cannot hide packets)
    is quarantined up to the next octet where a dictionary packet fits; an idle packet spanning
    exactly that stretch is counted as idle. With keep_undefined, a well-formed packet of an APID
    without definition whose length field is confirmed (see _links_confirm) is its own segment.
    Links that confirm a packet's length field never hide a confirmed dictionary packet inside it (segmented
    links, and any packet confirmed by fewer than UNDEFINED_CHAIN links: see _doubtful_link, _weak_hiding).
    lengths[apid]: 0 = no definition, > 0 = exact length, < 0 = any length (taken from the header).
    Unless final (buf is a chunk of longer data), framing stops at the first segment the octets after buf could
    change (see _walk_links), so the segments are those of the whole data; only a quarantined stretch longer
    than that walk is cut, one packet's length before the end, to bound what the next chunk takes over.
    """
    n = buf.shape[0]
    offsets = np.empty(n // PRIMARY_HEADER_OCTETS + 2, dtype=np.int64)
    sizes = np.empty_like(offsets)
    codes = np.empty(offsets.shape[0], dtype=np.uint8)
    k = 0
    p = 0
    walk_next, walk_q, links, stopped = -1, 0, 0, False  # the length-field walk from the previous segment
    chain = np.array([-1, 0, 0, -1], dtype=np.int64)  # the last confirmation walk (see _links_confirm)
    while p < n:
        if not final:  # decided here when the packets that could confirm it end within buf (see _walk_links)
            if p == walk_next and links > 0:  # one packet on from the last walk: reuse it
                links -= 1
            else:
                walk_q, links, stopped = p, 0, False
            walk_q, links, stopped, decided = _walk_links(buf, walk_q, links, stopped)
            if not decided:
                break
            walk_next = p + ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
        fit = _fit(buf, p, lengths, crc)  # _header_fits(buf, p, ...), the CRC checked only where one applies
        if fit == 2 and not _header_fits(buf, p, lengths, crc, table):
            fit = 0
        if fit:
            apid = ((np.int64(buf[p]) & 7) << 8) | buf[p + 1]
            size = ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
            q = p + size
            confirmed = crc[apid] or q == n
            if not confirmed:  # _header_fits(buf, q, ...)
                fit_q = _fit(buf, q, lengths, crc)
                confirmed = fit_q == 1 or (fit_q == 2 and _header_fits(buf, q, lengths, crc, table))
            if not confirmed and keep_undefined:
                confirmed = _links_confirm(buf, q, lengths, crc, table, chain) and not _weak_hiding(
                    buf, p, lengths, crc, table, chain
                )
            if not confirmed and not final and q + MAX_PACKET_OCTETS > n:
                break  # a packet found inside it might end after buf
            if not confirmed:
                q = _next_fit(buf, p + 1, p + size, lengths, crc, table)
            offsets[k], sizes[k] = p, q - p
            codes[k] = _OK if q == p + size else _TRUNCATED
            k += 1
            p = q
            continue
        # a well-formed packet's APID picks which of the two confirmations can apply (both need it well formed;
        # other length: a defined fixed length, undefined: none), so the other is not called (see _fit)
        defined = -1  # not well formed: neither applies
        if keep_undefined and _well_formed(buf, p):  # a call of a function without calls: cheap
            defined = lengths[((np.int64(buf[p]) & 7) << 8) | buf[p + 1]]
        if defined > 0 and _other_length_confirmed(buf, p, lengths, crc, table, chain):
            offsets[k], sizes[k] = p, ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
            codes[k] = _OK
            p += sizes[k]
            k += 1
            continue
        if defined == 0 and _links_confirm(buf, p, lengths, crc, table, chain):  # undefined, its length confirmed
            offsets[k], sizes[k] = p, ((np.int64(buf[p + 4]) << 8) | buf[p + 5]) + PRIMARY_HEADER_OCTETS + 1
            codes[k] = _UNDEFINED
            p += sizes[k]
            k += 1
            continue
        q = _next_fit(buf, p + 1, n, lengths, crc, table)
        if not final and q + MAX_PACKET_OCTETS > n:  # a packet ending after buf might fit before q
            if p + (UNDEFINED_CHAIN + 1) * MAX_PACKET_OCTETS >= n:
                break
            q = n - MAX_PACKET_OCTETS  # a long stretch: none fits before, the rest is left to the next chunk
        offsets[k], sizes[k] = p, q - p
        codes[k] = _IDLE if _idle_until(buf, p, q) else _classify(buf, p, lengths, crc, table)
        k += 1
        p = q
    return offsets[:k].copy(), sizes[:k].copy(), codes[:k].copy(), min(p, n)  # copies free the n/6-long buffers


@njit(cache=True, nogil=True)
def _unwrap_kernel(buf: np.ndarray, prefix: int, suffix: int) -> tuple[np.ndarray, int]:
    """Packets with their fixed prefix/suffix removed, and the octets of buf consumed (whole wrapped packets)."""
    out = np.empty(buf.shape[0], dtype=np.uint8)
    n, p, k = buf.shape[0], 0, 0
    while p + prefix + PRIMARY_HEADER_OCTETS <= n:
        q = p + prefix
        size = ((np.int64(buf[q + 4]) << 8) | buf[q + 5]) + PRIMARY_HEADER_OCTETS + 1
        if q + size + suffix > n:
            break
        out[k : k + size] = buf[q : q + size]
        k += size
        p = q + size + suffix
    return out[:k], p


def unwrap_packets(data: bytes | np.ndarray, prefix_octets: int, suffix_octets: int) -> tuple[np.ndarray, int]:
    """The packet stream inside fixed-size wrappers (e.g. a 4-octet ground-station header before each packet),
    walking each packet's length field; and how many octets of data that consumed (whole wrapped packets)."""
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else data
    if prefix_octets < 0 or suffix_octets < 0:
        raise ValueError("packet_prefix_octets, packet_suffix_octets: must be >= 0")
    packets, consumed = _unwrap_kernel(buf, prefix_octets, suffix_octets)
    return packets, int(consumed)


@dataclass(frozen=True)
class Frames:
    """Segments of a byte stream: offset and length in octets, and a FrameCode each."""

    offset: np.ndarray
    length: np.ndarray
    code: np.ndarray
    end: int  # octets framed: all of the data, or (final=False) up to the first segment its continuation could change


def frame_stream(
    data: bytes | np.ndarray,
    packet_octets_by_apid: dict[int, int],
    crc_apids: frozenset[int] = frozenset(),
    keep_undefined: bool = False,
    final: bool = True,
) -> Frames:
    """Split a mixed-APID packet stream by its length fields (CCSDS 133.0-B-2 §4.1.3.5), resynchronising on damage.

    A packet is taken when its version is 0, its APID is known, its length is the dictionary's and
    its CRC holds (or, without a CRC, no other packet starts inside it before its end). Damaged
    stretches become quarantined segments and the scan resumes where a dictionary packet fits.
    A length of 0 means any length (variable-length packets, or layouts checked after framing);
    keep_undefined frames confirmed packets of APIDs without definition (FrameCode.UNDEFINED).
    final=False: the data is a chunk of a longer stream; framing stops where the rest could change a segment
    (``Frames.end``), so the segments are those of the whole stream and the next chunk starts at ``end``.
    """
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else data
    if buf.dtype != np.uint8 or buf.ndim != 1:
        raise ValueError("data: expected bytes or a 1-D uint8 array")
    lengths = np.zeros(APID_COUNT, dtype=np.int64)
    crc = np.zeros(APID_COUNT, dtype=np.bool_)
    for apid, size in packet_octets_by_apid.items():
        if not 0 <= apid < IDLE_APID:
            raise ValueError(f"packet_octets_by_apid: APID {apid} outside 0..2046")
        if 0 < size < PRIMARY_HEADER_OCTETS + 1 or size < 0:
            raise ValueError(f"packet_octets_by_apid: APID {apid} length {size} < 7 octets")
        lengths[apid] = size if size else -1
        crc[apid] = apid in crc_apids
    offset, length, code, end = _frame_kernel(buf, lengths, crc, _CRC_TABLES, keep_undefined, final)
    return Frames(offset=offset, length=length, code=code, end=int(end))
