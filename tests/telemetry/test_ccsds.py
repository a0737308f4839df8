"""CCSDS packet layer: primary header (133.0-B-2 §4.1.3), time codes (301.0-B-4 §3.2–3.3), CRC, framing.

Truths: byte-level vectors worked from the clauses, the independent libraries ccsdspy and
spacepackets, the published CRC-16/CCITT-FALSE check value, and exact rational arithmetic.
"""

from __future__ import annotations

import datetime as dt
from fractions import Fraction
from io import BytesIO
from pathlib import Path

import ccsdspy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from spacepackets.ccsds import PacketType, SpacePacketHeader
from spacepackets.ccsds.time import CdsShortTimestamp

from telemetry import ccsds
from telemetry.ccsds import FrameCode, TimeCode

NOAA = Path("real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1")
NOAA_LEN = 71
CRC_CHECK_123456789 = 0x29B1  # CRC-16/CCITT-FALSE check value (Greg Cook's CRC catalogue)
HALF_NS = 0.5  # decode rounds a CUC fraction to the nearest nanosecond
ROUNDING_NS = 1  # encode rounds to the nearest tick, decode to the nearest ns: at most half a tick + 1 ns
UNIX_EPOCH = dt.datetime(1970, 1, 1, tzinfo=dt.UTC)
CCSDS_EPOCH = dt.datetime(1958, 1, 1, tzinfo=dt.UTC)


def test_primary_header_clause_4_1_3_byte_vector() -> None:
    """First NOAA-20 header 08 0B CA 2E 00 40, worked by hand from the clause's bit layout."""
    h = ccsds.parse_primary_headers(np.array([[0x08, 0x0B, 0xCA, 0x2E, 0x00, 0x40]], dtype=np.uint8))
    assert (h.version[0], h.packet_type[0], h.secondary_header_flag[0]) == (0, 0, 1)
    assert (h.apid[0], h.sequence_flags[0], h.sequence_count[0], h.packet_octets[0]) == (11, 3, 0x0A2E, 0x40 + 7)


def test_primary_headers_match_ccsdspy_on_noaa20(shared_data: Path) -> None:
    raw = (shared_data / NOAA).read_bytes()
    theirs = ccsdspy.utils.read_primary_headers(BytesIO(raw))
    h = ccsds.parse_primary_headers(np.frombuffer(raw, dtype=np.uint8).reshape(-1, NOAA_LEN))
    np.testing.assert_array_equal(h.apid, theirs["CCSDS_APID"])
    np.testing.assert_array_equal(h.sequence_count, theirs["CCSDS_SEQUENCE_COUNT"])
    np.testing.assert_array_equal(h.packet_octets - 7, theirs["CCSDS_PACKET_LENGTH"])
    np.testing.assert_array_equal(h.sequence_flags, theirs["CCSDS_SEQUENCE_FLAG"])


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2046), st.integers(0, 16383), st.integers(7, 65542))
def test_encoded_header_matches_spacepackets(apid: int, count: int, octets: int) -> None:
    ours = ccsds.encode_primary_headers(apid, np.array([count]), octets)[0].tobytes()
    theirs = SpacePacketHeader(PacketType.TM, apid, count, data_len=octets - 7, sec_header_flag=True).pack()
    assert ours == bytes(theirs)
    back = SpacePacketHeader.unpack(ours)
    assert (back.apid, back.seq_count, back.packet_len) == (apid, count, octets)


def test_encode_header_rejects_bad_apid_naming_field() -> None:
    with pytest.raises(ValueError, match="apid"):
        ccsds.encode_primary_headers(2048, np.array([0]), 10)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**16 - 1), st.integers(0, 86_399_999))
def test_cds_decode_matches_calendar_arithmetic(day: int, ms_of_day: int) -> None:
    """Days since 1958-01-01 and ms of day, counted with the standard library's exact calendar."""
    code = TimeCode("CDS", submillisecond_octets=0)
    t_field = day.to_bytes(2, "big") + ms_of_day.to_bytes(4, "big")
    ours = int(ccsds.decode_time(np.frombuffer(t_field, np.uint8)[None, :], code)[0])
    theirs = CCSDS_EPOCH + dt.timedelta(days=day, milliseconds=ms_of_day)
    assert ours == (theirs - UNIX_EPOCH) // dt.timedelta(microseconds=1) * 1_000


def test_cds_short_timestamp_of_spacepackets_parses_our_t_field() -> None:
    """spacepackets reads our CDS 2+4 T-field (with its P-field 0x40) back to the same day and ms."""
    code = TimeCode("CDS", submillisecond_octets=0)
    t_ns = np.array([1_617_926_400_007_000_000])  # 2021-04-09T00:00:00.007Z
    stamp = CdsShortTimestamp.unpack(bytes([0x40]) + ccsds.encode_time(t_ns, code)[0].tobytes())
    assert (stamp.ccsds_days, stamp.ms_of_day) == (23_109, 7)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 2**16 - 1))
def test_cuc_4_2_decode_is_exact_binary_fraction(coarse: int, fine: int) -> None:
    code = TimeCode("CUC", 4, 2, epoch_ns=946_684_800 * 10**9)
    t_field = np.frombuffer(coarse.to_bytes(4, "big") + fine.to_bytes(2, "big"), np.uint8)[None, :]
    ours = int(ccsds.decode_time(t_field, code)[0])
    exact_ns = Fraction(code.epoch_ns) + (coarse + Fraction(fine, 2**16)) * 10**9
    assert abs(ours - exact_ns) <= HALF_NS


@pytest.mark.parametrize(
    "code",
    [
        TimeCode("CUC", 4, 2),
        TimeCode("CUC", 2, 3),
        TimeCode("CDS"),
        TimeCode("CDS", day_octets=3, submillisecond_octets=4),
    ],
)
def test_time_code_round_trip_within_half_a_tick(code: TimeCode) -> None:
    rng = np.random.default_rng(7)
    span_ns = (2**16 - 1) * 10**9 if code.format == "CUC" and code.coarse_octets == 2 else 60 * 365 * 86_400 * 10**9
    t = code.epoch_ns + rng.integers(0, span_ns, 1000)
    back = ccsds.decode_time(ccsds.encode_time(t, code), code)
    tick_ns = {("CUC", 2): 10**9 / 2**16, ("CUC", 3): 10**9 / 2**24}.get((code.format, code.fine_octets))
    if code.format == "CDS":
        tick_ns = {0: 10**6, 2: 10**3, 4: 1}[code.submillisecond_octets]
        assert np.all((t - back >= 0) & (t - back < tick_ns))  # CDS truncates to its unit
    else:
        assert np.max(np.abs(back - t)) <= tick_ns / 2 + ROUNDING_NS


def test_time_code_rejects_bad_layout_naming_field() -> None:
    with pytest.raises(ValueError, match="time_code"):
        TimeCode("CUC", coarse_octets=5)
    with pytest.raises(ValueError, match="time_code.format"):
        TimeCode("GPS")


def test_crc16_published_check_value_and_fastcrc() -> None:
    from fastcrc import crc16

    assert ccsds.crc16_ccitt(b"123456789") == CRC_CHECK_123456789
    rows = np.random.default_rng(3).integers(0, 256, (50, 40), dtype=np.uint8)
    np.testing.assert_array_equal(ccsds.crc16_ccitt(rows), [crc16.ibm_3740(r.tobytes()) for r in rows])


def _packet(apid: int, count: int, size: int, fill: int) -> bytes:
    """A packet of the given APID and length whose data field is one repeated octet."""
    return ccsds.encode_primary_headers(apid, np.array([count]), size)[0].tobytes() + bytes([fill]) * (size - 6)


def test_mixed_apid_stream_splits_like_ccsdspy() -> None:
    rng = np.random.default_rng(5)
    sizes = {100: 20, 200: 33, 300: 9}
    apids = rng.choice(list(sizes), 500)
    stream = b"".join(_packet(int(a), i, sizes[int(a)], i % 256) for i, a in enumerate(apids))
    frames = ccsds.frame_stream(stream, sizes)
    assert np.all(frames.code == FrameCode.OK)
    by_apid = ccsdspy.utils.split_by_apid(BytesIO(stream))
    for apid, size in sizes.items():
        ours = b"".join(stream[o : o + size] for o in frames.offset[apids == apid])
        assert ours == by_apid[apid].read()


def test_framing_quarantines_damage_and_recovers_neighbours() -> None:
    sizes = {100: 20}
    good = [_packet(100, i, 20, i) for i in range(6)]
    bad_length = bytearray(good[2])
    bad_length[5] += 3
    stream = good[0] + good[1] + bytes(bad_length) + good[3] + b"\xff\x00\x13" + good[4] + good[5][:11]
    frames = ccsds.frame_stream(stream, sizes, crc_apids=frozenset())
    codes = [FrameCode.NAMES[c] for c in frames.code]
    assert codes == ["ok", "ok", "bad_length", "ok", "bad_header", "ok", "truncated"]
    assert frames.offset.tolist() == [0, 20, 40, 60, 80, 83, 103]


def test_framing_with_crc_quarantines_corrupt_payload() -> None:
    from telemetry.dictionary import load_dictionary
    from telemetry.encoding import encode_packets

    hk = load_dictionary("reference_satellite.yaml").packets[256]
    values = {p.name: np.zeros(3) for p in hk.parameters}
    packets = encode_packets(hk, 1_700_000_000 * 10**9 + np.arange(3) * 250_000_000, np.arange(3), values)
    packets[1, 50] ^= 0x10
    frames = ccsds.frame_stream(packets.tobytes(), {256: hk.packet_octets}, frozenset({256}))
    assert [FrameCode.NAMES[c] for c in frames.code] == ["ok", "crc_failure", "ok"]


def test_unknown_apid_is_quarantined_and_idle_packet_counted() -> None:
    stream = (
        _packet(100, 0, 20, 1)
        + _packet(555, 0, 14, 2)
        + _packet(100, 1, 20, 3)
        + _packet(ccsds.IDLE_APID, 0, 10, 0)
        + _packet(100, 2, 20, 3)
    )
    frames = ccsds.frame_stream(stream, {100: 20})
    assert [FrameCode.NAMES[c] for c in frames.code] == ["ok", "unknown_apid", "ok", "idle", "ok"]


def test_frame_stream_rejects_bad_dictionary_naming_field() -> None:
    with pytest.raises(ValueError, match="packet_octets_by_apid"):
        ccsds.frame_stream(b"", {2047: 10})


def test_framing_a_chunk_gives_the_segments_of_the_whole_stream() -> None:
    """Real Europa Clipper ECM stream (1227 fixed, 1223 any length, four APIDs undefined) four times over with
    damage (flipped octets, a garbage stretch, a cut packet), cut at many points: framing the chunk with
    final=False gives exactly the whole stream's segments up to where it stops, and stops less than a chain of
    maximal packets before the cut."""
    ecm = (Path(__file__).parents[1] / "data" / "europa_clipper_ecm" / "ecm_raw2.bin").read_bytes()
    rng = np.random.default_rng(12)
    stream = bytearray(ecm * 2 + rng.integers(0, 256, 3_000, dtype=np.uint8).tobytes() + ecm[:-700] + ecm)
    for at in rng.integers(0, len(stream), 40).tolist():
        stream[at] ^= 0x5A
    lengths = {1227: 1508, 1223: 0}
    whole = ccsds.frame_stream(bytes(stream), lengths, keep_undefined=True)
    assert {FrameCode.NAMES[c] for c in whole.code} >= {"ok", "undefined_apid", "bad_header"}
    assert whole.end == len(stream)
    buf = np.frombuffer(bytes(stream), np.uint8)
    cuts = rng.integers(0, len(stream), 60).tolist() + (whole.offset[-40:] + 1).tolist()
    for cut in cuts:
        chunk = ccsds.frame_stream(buf[:cut], lengths, keep_undefined=True, final=False)
        k = int(np.searchsorted(whole.offset, chunk.end))
        assert chunk.end == (whole.offset[k] if k < whole.offset.size else len(stream)), f"cut {cut}"
        for name in ("offset", "length", "code"):
            np.testing.assert_array_equal(getattr(chunk, name), getattr(whole, name)[:k], err_msg=f"cut {cut}: {name}")
        assert chunk.end >= cut - (ccsds.UNDEFINED_CHAIN + 1) * ccsds.MAX_PACKET_OCTETS


@pytest.mark.parametrize("scale", ["TAI", "GPS"])
def test_tai_and_gps_time_codes_follow_skyfield_leap_seconds(scale: str) -> None:
    """CUC counted in TAI (level-1 epoch 1958) or GPS (epoch 1980-01-06) decodes to the UTC skyfield gives."""
    from skyfield.api import load

    ts = load.timescale(builtin=True)
    epoch = {"TAI": ccsds.CCSDS_EPOCH_NS, "GPS": 3_657 * 86_400 * 10**9}[scale]
    code = TimeCode("CUC", 4, 0, epoch_ns=epoch, time_scale=scale)
    utc = [(1999, 1, 1, 0, 0, 0), (2016, 12, 31, 23, 59, 59), (2017, 1, 1, 0, 0, 0), (2021, 4, 9, 12, 0, 0)]
    t = ts.utc(*np.array(utc).T)
    tai_label_s = [
        (dt.datetime(*map(int, c[:5]), tzinfo=dt.UTC) - UNIX_EPOCH).total_seconds() + c[5]
        for c in zip(*t.tai_calendar())
    ]
    coarse = np.rint(np.array(tai_label_s) - epoch / 1e9 + (-19 if scale == "GPS" else 0)).astype(np.int64)
    t_field = np.stack([(coarse >> s) & 0xFF for s in (24, 16, 8, 0)], axis=1).astype(np.uint8)
    expected = np.array([(dt.datetime(*c, tzinfo=dt.UTC) - UNIX_EPOCH).total_seconds() for c in utc])
    np.testing.assert_array_equal(ccsds.decode_time(t_field, code), expected.astype(np.int64) * 10**9)
    np.testing.assert_array_equal(ccsds.encode_time(expected.astype(np.int64) * 10**9, code), t_field)


def test_gps_minus_utc_is_18_s_since_2017() -> None:
    """Published GPS − UTC = 18 s from 2017-01-01 (IERS Bulletin C 52 / GPS ICD)."""
    gps = TimeCode("CUC", 4, 0, epoch_ns=0, time_scale="GPS")
    utc = TimeCode("CUC", 4, 0, epoch_ns=0, time_scale="UTC")
    t = np.array([1_700_000_000 * 10**9])
    assert int(_coarse(ccsds.encode_time(t, gps)) - _coarse(ccsds.encode_time(t, utc))) == 18


def _coarse(t_field: np.ndarray) -> int:
    """The 4-octet coarse time of the first row."""
    return int.from_bytes(t_field[0, :4].tobytes(), "big")


def test_cds_sub_fields_beyond_their_range_are_invalid() -> None:
    """ms of day ≤ 86,400,999 (a leap-second day) and µs of ms < 1,000 (CCSDS 301.0-B-4 §3.3.1)."""
    code = TimeCode("CDS")
    rows = [(23_109, 86_400_999, 999), (23_109, 86_401_000, 0), (23_109, 5, 1_000)]
    fields = np.array(
        [list(d.to_bytes(2, "big") + m.to_bytes(4, "big") + u.to_bytes(2, "big")) for d, m, u in rows], dtype=np.uint8
    )
    assert ccsds.time_fields_valid(fields, code).tolist() == [True, False, False]
