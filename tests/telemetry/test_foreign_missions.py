"""Real packets of other missions (tests/data/README.md) through their own definitions: counts and values as
ccsdspy reads them, time from the mission's calendar fields or clock counter, undefined APIDs kept raw.

Truths: ccsdspy 2.0.1 (its CSV reader, FixedLength/VariableLength decoding, split_by_apid and
read_primary_headers on the same bytes) and Python's datetime for the calendar; never this code.
"""

from __future__ import annotations

import datetime as dt
import io
import json
import logging
from collections import Counter
from pathlib import Path

import ccsdspy
import numpy as np
import pytest
from ccsdspy.utils import read_primary_headers, split_by_apid

from telemetry.decoding import decode_packets, decode_stream
from telemetry.dictionary import FieldSpec, PacketDefinition, lay_out, load_ccsdspy_csv, load_dictionary
from telemetry.packet_files import decode_chunks

DATA = Path(__file__).parents[1] / "data"
CYGNSS = DATA / "cygnss_f7"
CYGNSS_STREAM = CYGNSS / "CYGNSS_F7_L0_2022_086_10_15_V01_F__first101pkts.tlm"
CYGNSS_TIME = "year=*_HDR_YEAR,doy=*_HDR_DAY,hour=*_HDR_HOUR,minute=*_HDR_MIN,second=*_HDR_SEC,microsecond=*_HDR_USEC"
ECM = DATA / "europa_clipper_ecm"
ECM_STREAM = ECM / "ecm_raw2.bin"
ECM_TIME = "coarse=*SCLK Time second,fine=*SCLK Time subsec,fine_bits=16,epoch=2000-01-01T11:58:55.816Z"
J2000_UTC = dt.datetime(2000, 1, 1, 11, 58, 55, 816000)
logging.getLogger("ccsdspy").setLevel(logging.ERROR)  # it warns of every sequence gap of these real streams


def _ccsdspy_load(definition: Path, data: io.BytesIO) -> dict[str, np.ndarray]:
    """ccsdspy's reading of one APID's packets with a CSV definition, arrays flattened to name_i[_j] columns."""
    try:
        packet = ccsdspy.FixedLength.from_file(str(definition))
    except ValueError:
        packet = ccsdspy.VariableLength.from_file(str(definition))
    fill = {f._name for f in packet._fields if f._data_type == "fill"}
    flat = {}
    for name, column in packet.load(data).items():
        if name in fill:
            continue
        column = np.stack(column) if column.dtype == object else column
        if column.ndim == 1:
            flat[name] = column
            continue
        for index in np.ndindex(column.shape[1:]):
            flat[name + "".join(f"_{i}" for i in index)] = column[(slice(None), *index)]
    return flat


def _apid_counts(path: Path) -> Counter:
    """Packets per APID as ccsdspy's primary-header reader counts them."""
    return Counter(read_primary_headers(str(path))["CCSDS_APID"].tolist())


def _assert_same_values(ours: dict[str, np.ndarray], theirs: dict[str, np.ndarray]) -> None:
    """Equal values; integers also as wide as ccsdspy gives them."""
    assert set(ours) == set(theirs)
    different = [k for k in theirs if not np.array_equal(np.asarray(ours[k]), theirs[k], equal_nan=True)]
    assert different == []
    integer = [k for k in theirs if theirs[k].dtype.kind in "iu"]
    assert {k: ours[k].dtype.itemsize for k in integer} == {k: theirs[k].dtype.itemsize for k in integer}


@pytest.fixture(scope="module")
def cygnss() -> tuple[bytes, object]:
    data = CYGNSS_STREAM.read_bytes()
    return data, decode_stream(data, load_dictionary(CYGNSS / "ccsdspy", time_fields=CYGNSS_TIME))


def test_cygnss_mixed_stream_decodes_every_apid_as_ccsdspy_reads_its_team_definition(cygnss) -> None:
    """7 interleaved APIDs: per-APID counts and every value of the 6 defined ones as ccsdspy gives them;
    ENG_FILL (391, no definition) counted and kept byte-exact, nothing quarantined."""
    data, result = cygnss
    counts = _apid_counts(CYGNSS_STREAM)
    assert {a: s.accepted for a, s in result.report.apids.items()} == {a: n for a, n in counts.items() if a != 391}
    assert result.report.undefined_apids == {391: counts[391]} and result.report.quarantined == []
    split = split_by_apid(io.BytesIO(data))
    assert [u.packets.tobytes() for u in result.undefined] == [split[391].getvalue()]
    for batch in result.batches:
        _assert_same_values(
            batch.values, _ccsdspy_load(CYGNSS / "ccsdspy" / f"apid{batch.apid:05d}.csv", split[batch.apid])
        )


def test_cygnss_packet_time_is_the_calendar_of_its_header_fields(cygnss) -> None:
    """UTC from year, day of year (from 1), hour, minute, second, µs fields = Python's calendar on ccsdspy's values."""
    data, result = cygnss
    split = split_by_apid(io.BytesIO(data))
    for batch in result.batches:
        theirs = _ccsdspy_load(CYGNSS / "ccsdspy" / f"apid{batch.apid:05d}.csv", split[batch.apid])
        prefix = next(k for k in theirs if k.endswith("_HDR_YEAR"))[: -len("YEAR")]
        expected = [
            int(
                (
                    dt.datetime(int(y), 1, 1)
                    + dt.timedelta(days=int(d) - 1, hours=int(h), minutes=int(m), seconds=int(s), microseconds=int(us))
                    - dt.datetime(1970, 1, 1)
                )
                / dt.timedelta(microseconds=1)
            )
            * 1_000
            for y, d, h, m, s, us in zip(*(theirs[prefix + k] for k in ("YEAR", "DAY", "HOUR", "MIN", "SEC", "USEC")))
        ]
        assert batch.t_utc_ns.tolist() == sorted(expected)
    first_day = np.datetime64(int(result.batches[0].t_utc_ns[0]), "ns").astype("datetime64[D]")
    assert first_day == np.datetime64("2022-03-25")


def test_cygnss_sequence_gaps_per_apid_match_the_counters(cygnss) -> None:
    """Every 10th packet was kept in this extract: 9 missing between neighbours, per APID, from ccsdspy's counts."""
    _, result = cygnss
    headers = read_primary_headers(str(CYGNSS_STREAM))
    for apid, summary in result.report.apids.items():
        seq = np.sort(headers["CCSDS_SEQUENCE_COUNT"][headers["CCSDS_APID"] == apid].astype(np.int64))
        assert summary.missing == int(np.sum((np.diff(seq) - 1) % 16384))


def test_europa_clipper_mixed_stream_with_variable_length_expand_and_24_bit_signed_fields() -> None:
    """ECM ground stream, 6 APIDs: 1223 (expand array + footer) and 1227 (24-bit two's complement) decode as
    ccsdspy; 1216/1217/1219/1232 (no definition; 1232 of three lengths) are counted and kept byte-exact."""
    data = ECM_STREAM.read_bytes()
    result = decode_stream(data, load_dictionary(ECM / "defs", time_fields=ECM_TIME))
    counts = _apid_counts(ECM_STREAM)
    assert {a: s.accepted for a, s in result.report.apids.items()} == {1223: counts[1223], 1227: counts[1227]}
    assert result.report.undefined_apids == {a: n for a, n in counts.items() if a not in (1223, 1227)}
    assert result.report.quarantined == []
    split = split_by_apid(io.BytesIO(data))
    assert {u.apid: u.packets.tobytes() for u in result.undefined} == {
        a: split[a].getvalue() for a in counts if a not in (1223, 1227)
    }
    for batch in result.batches:
        _assert_same_values(batch.values, _ccsdspy_load(ECM / "defs" / f"apid{batch.apid:05d}.csv", split[batch.apid]))
    by_apid = {b.apid: b for b in result.batches}
    assert sum(k.startswith("HF1223_FGX_CHANNELS_") for k in by_apid[1223].values) == 1440
    assert np.all(by_apid[1227].values["FGx_CH_134_2"] == -88)  # ccsdspy issue #76's signed 24-bit value
    sclk = by_apid[1227].values
    expected = [
        int(
            (J2000_UTC + dt.timedelta(seconds=int(c) + int(f) / 65536) - dt.datetime(1970, 1, 1))
            / dt.timedelta(microseconds=1)
        )
        for c, f in zip(sclk["Instrument SCLK Time second"], sclk["Instrument SCLK Time subsec"])
    ]
    assert np.all(np.abs(by_apid[1227].t_utc_ns // 1_000 - np.array(expected)) <= 1)


def test_chunked_decode_frames_the_same_packets_as_one_pass() -> None:
    """Chunks of 1,000 octets (packets of 1,508 cross every boundary): same per-APID tallies and values."""
    dictionary = load_dictionary(ECM / "defs", time_fields=ECM_TIME)
    whole = decode_stream(ECM_STREAM.read_bytes(), dictionary)
    with ECM_STREAM.open("rb") as f:
        parts = [r for _, r in decode_chunks(f, dictionary, chunk_octets=1_000)]
    assert sum(r.consumed for r in parts) == ECM_STREAM.stat().st_size
    assert all(not r.report.quarantined for r in parts)
    undefined = Counter()
    for r in parts:
        undefined.update(r.report.undefined_apids)
    assert dict(undefined) == whole.report.undefined_apids
    for batch in whole.batches:
        mine = [b for r in parts for b in r.batches if b.apid == batch.apid]
        assert np.array_equal(np.concatenate([b.t_utc_ns for b in mine]), batch.t_utc_ns)
        for name in ("Accountability ID", "FGx_CH_0_0", "HF1223_FGX_CHANNELS_7", "HF1223_PEC (CRC-16-CCITT)"):
            if name in batch.values:
                assert np.array_equal(np.concatenate([b.values[name] for b in mine]), batch.values[name])


def test_small_decode_chunks_archive_the_same_series_in_full_archive_chunks(tmp_path: Path) -> None:
    """ECM in 1,000-octet decode chunks: every archived series, time and undefined packet equals the one-pass
    ingest's, and each APID's packets are committed as one archive chunk (not one per decode chunk)."""
    from telemetry.archive import Archive
    from telemetry.packet_files import ingest_packet_file

    dictionary = load_dictionary(ECM / "defs", time_fields=ECM_TIME)
    stored = {}
    for chunk_octets in (1_000, 1 << 20):
        with Archive(f"sqlite:///{tmp_path / f'{chunk_octets}.db'}") as archive:
            report, result = ingest_packet_file(
                archive, ECM_STREAM, dictionary, satellite="ECM", uploaded_by="ops", chunk_octets=chunk_octets
            )
            names = archive.parameters("ECM")
            series = {n: archive.read_parameter("ECM", n, 0, 2**62) for n in names}
            stored[chunk_octets] = (result.packets_accepted, series, archive.undefined_packets("ECM"))
            chunks = archive.replay("ECM", 0, 2**62)
            with archive.engine.connect() as conn:
                n_chunks = conn.exec_driver_sql("SELECT COUNT(*) FROM packet_chunk").scalar_one()
        assert len(chunks) == report.packets_accepted == sum(_apid_counts(ECM_STREAM)[a] for a in (1223, 1227))
        assert n_chunks == 2
    (n_small, small, undefined_small), (n_whole, whole, undefined_whole) = stored.values()
    assert n_small == n_whole and undefined_small == undefined_whole and small.keys() == whole.keys()
    for name, (t, v) in whole.items():
        assert np.array_equal(small[name][0], t) and np.array_equal(small[name][1], v), name
    assert {v.dtype for _, v in whole.values()} <= {np.dtype(np.int64), np.dtype(np.float64)}  # read back wide


def _set_bits(packet: bytearray, offset: int, length: int, value: int) -> None:
    """Write value into a big-endian bit field of a packet."""
    first, last = offset // 8, (offset + length - 1) // 8
    word = int.from_bytes(packet[first : last + 1], "big")
    shift = 8 * (last + 1) - offset - length
    word = (word & ~(((1 << length) - 1) << shift)) | (value << shift)
    packet[first : last + 1] = word.to_bytes(last - first + 1, "big")


@pytest.mark.parametrize(
    ("field", "value", "reason", "detail"),
    [
        ("ENG_ADCSIO_HDR_DAY", 400, "invalid_time", "day of year outside the year"),
        ("ENG_ADCSIO_HDR_DAY", 0, "invalid_time", "day of year outside the year"),
        ("ENG_ADCSIO_HDR_YEAR", 0, "invalid_time", "year outside 1..9999"),
        ("ENG_ADCSIO_HDR_HOUR", 24, "invalid_time", "hour outside 0..23"),
        ("ENG_ADCSIO_HDR_USEC", 1_000_000, "invalid_time", "microsecond outside 0..999999"),
        ("ENG_ADCSIO_HDR_YEAR", 1970, "time_out_of_range", None),
    ],
)
def test_impossible_or_unset_packet_time_is_quarantined_with_its_reason(field, value, reason, detail) -> None:
    """One ENG_ADCSIO packet's time field spoiled: quarantined naming the field's problem (a 1970 stamp is out of
    the mission window), never rolled over; its 39 neighbours and the other APIDs all kept."""
    dictionary = load_dictionary(CYGNSS / "ccsdspy", time_fields=CYGNSS_TIME)
    param = next(p for p in dictionary.packets[393].parameters if p.name == field)
    data = bytearray(CYGNSS_STREAM.read_bytes())
    offsets = [o for o, a in _offsets(bytes(data)) if a == 393]
    packet = bytearray(data[offsets[5] : offsets[5] + 140])
    _set_bits(packet, param.bit_offset, param.bit_length, value)
    data[offsets[5] : offsets[5] + 140] = packet
    result = decode_stream(bytes(data), dictionary)
    [q] = result.report.quarantined
    assert (q.reason, q.apid, q.offset) == (reason, 393, offsets[5])
    assert detail is None or q.detail == detail
    assert result.report.apids[393].accepted == 39 and result.report.packets_accepted == 99


def _offsets(data: bytes) -> list[tuple[int, int]]:
    """(offset, APID) of every packet, walking the length fields."""
    out, p = [], 0
    while p < len(data):
        out.append((p, ((data[p] & 7) << 8) | data[p + 1]))
        p += ((data[p + 4] << 8) | data[p + 5]) + 7
    return out


def test_definition_shorter_than_its_packets_decodes_them_and_says_so(tmp_path: Path) -> None:
    """ENG_PVT (394) described without its last 10 fields: its 39 packets decode (those fields' values as ccsdspy
    reads the team's full definition) and the report counts 39 packets longer than the definition; a definition
    longer than the packets quarantines them as bad_length, per APID, the other APIDs kept."""
    rows = (CYGNSS / "ccsdspy" / "apid00394.csv").read_text().splitlines()
    short = tmp_path / "apid00394.csv"
    short.write_text("\n".join(rows[:-10]) + "\n")
    data = CYGNSS_STREAM.read_bytes()
    result = decode_stream(data, load_ccsdspy_csv(short, apid=394, time_fields=_time()))
    summary = result.report.apids[394]
    assert (summary.accepted, summary.longer_than_definition, summary.packet_octets) == (39, 39, {76: 39})
    assert summary.definition_octets is not None and summary.definition_octets < 76
    full = _ccsdspy_load(CYGNSS / "ccsdspy" / "apid00394.csv", split_by_apid(io.BytesIO(data))[394])
    ours = result.batches[0].values
    assert len(ours) == len(full) - 10
    _assert_same_values(ours, {k: full[k] for k in ours})
    long = tmp_path / "long" / "apid00394.csv"
    long.parent.mkdir()
    long.write_text("\n".join([*rows, "EXTRA,uint,32,608,big"]) + "\n")
    result = decode_stream(data, load_dictionary(long.parent, time_fields=CYGNSS_TIME))
    assert result.report.reason_counts() == {"bad_length": 39}
    assert {q.detail for q in result.report.quarantined} == {"packet has 76 octets, the definition needs 80"}
    assert result.report.apids[394].shorter_than_definition == 39 and result.report.undefined_apids[393] == 40


def _time():
    from telemetry.packet_time import parse_time_fields

    return parse_time_fields(CYGNSS_TIME)


@pytest.mark.parametrize("order", ["little", "4321", "3412", "2143", "21"])
def test_byte_orders_read_as_ccsdspy_reads_them(order: str) -> None:
    """Real ENG_ADCS packets read with the team's byte orders (little for F4321/U21 fields) and custom digit
    orders on every 32-bit (16-bit for "21") field: the values ccsdspy's PacketField(byte_order=...) gives."""
    rows = [r.split(",") for r in (CYGNSS / "ccsdspy" / "apid00392.csv").read_text().splitlines()[1:]]
    data = CYGNSS_STREAM.read_bytes()
    packets = b"".join(data[o : o + 168] for o, a in _offsets(data) if a == 392)
    width = 16 if order == "21" else 32
    specs = []
    for name, kind, bits, offset, team_order in rows:
        chosen = order if int(bits) == width and int(offset) % 8 == 0 and kind != "fill" else team_order
        specs.append(FieldSpec(name, kind, int(bits), int(offset), chosen))
    params, _ = lay_out(tuple(specs), 0, {})
    definition = PacketDefinition("ENG_ADCS", 392, 168, params)
    ours = decode_packets(np.frombuffer(packets, np.uint8).reshape(-1, 168), definition)
    fields = [
        ccsdspy.PacketField(
            name=s.name,
            data_type=s.data_type,
            bit_length=s.bit_length,
            bit_offset=s.bit_offset,
            byte_order=s.byte_order,
        )
        for s in specs
    ]
    theirs = ccsdspy.FixedLength(fields).load(io.BytesIO(packets))
    assert any(s.byte_order != "big" for s in specs)
    _assert_same_values(ours, {k: v for k, v in theirs.items() if not k.startswith("FILL") and k in ours})


def test_acs_twin_ingest_of_a_foreign_mission_then_reingest_adds_nothing(tmp_path: Path, capsys) -> None:
    """The CLI with a folder of ccsdspy CSVs and --time-fields: archived values = ccsdspy's, the undefined APID's
    packet retrievable byte-exact; the same file again reports its duplicates per APID and stores nothing."""
    from backend.cli import main
    from telemetry.archive import Archive

    url = f"sqlite:///{tmp_path / 'archive.db'}"
    argv = [
        "ingest",
        str(CYGNSS_STREAM),
        "--dictionary",
        str(CYGNSS / "ccsdspy"),
        "--time-fields",
        CYGNSS_TIME,
        "--satellite",
        "CYGNSS-FM07",
        "--db",
        url,
        "--user",
        "ops",
    ]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)
    counts = _apid_counts(CYGNSS_STREAM)
    defined = {str(a): n for a, n in counts.items() if a != 391}
    assert {a: s["accepted"] for a, s in first["decode"]["apids"].items()} == defined
    assert first["archive"]["packets_accepted"] == sum(defined.values())
    assert any("byte_order" in note for note in first["notes"])
    split = split_by_apid(io.BytesIO(CYGNSS_STREAM.read_bytes()))
    theirs = _ccsdspy_load(CYGNSS / "ccsdspy" / "apid00393.csv", split[393])
    with Archive(url) as archive:
        for name in ("ADCS_NST_Q1", "ADCS_NST_Q4", "ENG_ADCSIO_HDR_USEC"):
            t, v = archive.read_parameter("CYGNSS-FM07", name, 0, 2**62)
            assert np.array_equal(v, theirs[name]) and len(t) == counts[393]
        assert archive.undefined_packets("CYGNSS-FM07") == {391: [split[391].getvalue()]}
        t, _ = archive.read_parameter("CYGNSS-FM07", "CDS_FSW_STAT_TIMEQ", 0, 2**62)  # in ENG_HI and ENG_PVT
        assert len(t) == counts[386] + counts[394] and np.all(np.diff(t) >= 0)
        before = archive.upload_contents(first["archive"]["upload_id"])
    assert main(argv) == 0
    again = json.loads(capsys.readouterr().out)["archive"]
    assert again["duplicate_upload"] is True and again["packets_accepted"] == 0
    assert again["duplicates_by_apid"] == defined
    with Archive(url) as archive:
        assert archive.upload_contents(first["archive"]["upload_id"]) == before
        assert len(archive.uploads("CYGNSS-FM07")) == 1


IMAP = DATA / "imap_idex_suda"
IMAP_XTCE = IMAP / "suda_combined_science_definition.xml"
IMAP_TIME = "coarse=SHCOARSE,fine=SHFINE,fine_bits=16,epoch=2010-01-01T00:00:00Z"


# The XTCE parameters of the primary header: the packet's own (sequence count and raw octets archived), not series
PRIMARY_HEADER = ("VERSION", "TYPE", "SEC_HDR_FLG", "PKT_APID", "SEQ_FLGS", "SRC_SEQ_CTR", "PKT_LEN")


def _spp_columns(data: bytes, skip: int = 0, xtce: Path = IMAP_XTCE) -> tuple[Counter, dict[str, list]]:
    """space_packet_parser's own reading: packets per APID and, per parameter, the value of each packet (None where
    its container has no such parameter); enumerations as their raw codes, as we archive them; the primary header's
    parameters left out. Packets no container of the XTCE matches (space_packet_parser refuses them) are not
    counted."""
    import space_packet_parser as spp

    definition = spp.load_xtce(xtce)
    packets = []
    for raw in spp.ccsds_generator(data, skip_header_bytes=skip):
        try:
            packets.append(definition.parse_bytes(raw))
        except spp.exceptions.UnrecognizedPacketTypeError:
            continue
    counts = Counter(int(p["PKT_APID"].raw_value) for p in packets)
    names = dict.fromkeys(
        k for p in packets for k, v in p.items() if not isinstance(v.raw_value, bytes) and k not in PRIMARY_HEADER
    )
    columns = {
        n: [(p[n] if isinstance(p[n], (int, float)) else p[n].raw_value) if n in p else None for p in packets]
        for n in names
    }
    return counts, columns


def _same(ours: np.ndarray, theirs: list) -> bool:
    expected = np.array([np.nan if v is None else float(v) for v in theirs])
    return bool(np.array_equal(np.asarray(ours, dtype=np.float64), expected, equal_nan=True))


def _no_packet_by_packet_parsing(*_: object) -> None:
    raise AssertionError("space_packet_parser was called packet by packet: the bulk container walk was not taken")


def test_imap_idex_polymorphic_xtce_decodes_as_space_packet_parser_reads_it(monkeypatch) -> None:
    """IDEX science packets (APID 1424, 4 lengths, containers chosen by IDX__SCI0TYPE, a dynamically sized waveform):
    78 packets, every numeric parameter of every container as space_packet_parser gives it, one series per name,
    decoded in bulk per container (telemetry.xtce_bulk), never packet by packet."""
    monkeypatch.setattr("telemetry.decoding._xtce_one_by_one", _no_packet_by_packet_parsing)
    data = (IMAP / "sciData_2023_052_14_45_05").read_bytes()
    result = decode_stream(data, load_dictionary(IMAP_XTCE, time_fields=IMAP_TIME))
    counts, theirs = _spp_columns(data)
    assert {a: s.accepted for a, s in result.report.apids.items()} == dict(counts) == {1424: 78}
    assert result.report.quarantined == [] and result.report.apids[1424].packet_octets == {
        304: 6,
        1072: 18,
        2908: 18,
        4080: 36,
    }
    [batch] = result.batches
    assert np.all(np.diff(batch.t_utc_ns) > 0)  # time order is file order here: rows line up with spp's
    assert set(batch.values) == set(theirs)
    assert [n for n, column in theirs.items() if not _same(batch.values[n], column)] == []
    assert batch.packets.tobytes() == data  # byte-exact packets of four lengths


def test_idex_packet_no_container_matches_is_quarantined_as_space_packet_parser_refuses_it(monkeypatch) -> None:
    """IDX__SCI0TYPE (octet 16) set to 0 in one packet: neither inheritor of the abstract IDX_SCI0 matches, so
    space_packet_parser refuses it; the bulk walk quarantines that packet with the reason and keeps the other 77
    with space_packet_parser's values."""
    import space_packet_parser as spp

    monkeypatch.setattr("telemetry.decoding._xtce_one_by_one", _no_packet_by_packet_parsing)
    data = bytearray((IMAP / "sciData_2023_052_14_45_05").read_bytes())
    offsets = [o for o, _ in _offsets(bytes(data))]
    data[offsets[10] + 16] = 0
    with pytest.raises(spp.exceptions.UnrecognizedPacketTypeError):
        spp.load_xtce(IMAP_XTCE).parse_bytes(bytes(data[offsets[10] : offsets[11]]))
    result = decode_stream(bytes(data), load_dictionary(IMAP_XTCE, time_fields=IMAP_TIME))
    [record] = result.report.quarantined
    assert record.offset == offsets[10] and "no container inheriting IDX_SCI0 matches" in record.detail
    kept = bytes(data[: offsets[10]] + data[offsets[11] :])
    _, theirs = _spp_columns(kept)
    [batch] = result.batches
    assert len(batch.t_utc_ns) == 77
    assert [n for n, column in theirs.items() if not _same(batch.values[n], column)] == []


def test_suda_packets_behind_a_4_octet_header_through_acs_twin_ingest(tmp_path: Path, capsys) -> None:
    """SUDA's 13 packets each follow a 4-octet ground header (space_packet_parser's skip_header_bytes=4):
    --packet-prefix 4 strips it; counts and values as space_packet_parser reads them, archived under XTCE names."""
    from backend.cli import main
    from telemetry.archive import Archive

    path = IMAP / "sciData_2022_130_17_41_53.spl"
    url = f"sqlite:///{tmp_path / 'suda.db'}"
    assert (
        main(
            [
                "ingest",
                str(path),
                "--dictionary",
                str(IMAP_XTCE),
                "--time-fields",
                IMAP_TIME,
                "--packet-prefix",
                "4",
                "--satellite",
                "SUDA",
                "--db",
                url,
                "--user",
                "ops",
            ]
        )
        == 0
    )
    report = json.loads(capsys.readouterr().out)
    counts, theirs = _spp_columns(path.read_bytes(), skip=4)
    assert {int(a): s["accepted"] for a, s in report["decode"]["apids"].items()} == dict(counts) == {1425: 13}
    assert report["decode"]["quarantined_count"] == 0 and report["archive"]["packets_accepted"] == 13
    with Archive(url) as archive:
        for name in ("IDX__SCIFETCHTYPE", "IDX__SCIFETCHEVTNUM", "IDX__CRCSCIFETCHPKT", "SHFINE"):
            _, v = archive.read_parameter("SUDA", name, 0, 2**62)
            assert _same(v, theirs[name]), name
