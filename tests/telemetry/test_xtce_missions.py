"""Real packets of missions whose teams wrote XTCE (tests/data/README.md): four more IMAP instruments and the CTIM
CubeSat. Per-APID counts and every numeric value as space_packet_parser 6.2 reads the same bytes with the same XTCE,
never this code.

IMAP-Ultra selects a container by an ORed list of APIDs; IMAP-HIT science and IMAP-Lo direct events come as
segmented packets; IMAP-Lo's housekeeping carries cubic calibrations; IMAP-SWAPI's housekeeping container is
shorter than its packets; CTIM's root container is not space_packet_parser's default and one of its clocks
stamps a packet just after its successor. Packets space_packet_parser refuses (no container for their APID)
are the ones we keep raw, byte-exact as ccsdspy's split_by_apid gives them.
"""

from __future__ import annotations

import io
import json
import logging
import warnings
from collections import Counter, defaultdict, deque
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from ccsdspy.utils import read_primary_headers, split_by_apid

from telemetry.decoding import decode_stream
from telemetry.dictionary import load_dictionary
from telemetry.ingest_report import DecodeResult

DATA = Path(__file__).parents[1] / "data" / "imap_processing"
ULTRA = DATA / "ultra" / "FM45_40P_Phi28p5_BeamCal_LinearScan_phi28.50_theta-0.00_20240207T102740.CCSDS"
ULTRA_XTCE = DATA / "ultra" / "ULTRA_SCI_COMBINED.xml"
HIT_SCIENCE = DATA / "hit" / "PREFLIGHT_raw_record_2023_256_15_59_04_apid1252__first400pkts.pkts"
HIT_HOUSEKEEPING = DATA / "hit" / "PREFLIGHT_raw_record_2023_256_15_59_04_apid1251__first200pkts.pkts"
HIT_XTCE = DATA / "hit" / "hit_packet_definitions.xml"
LO = DATA / "lo" / "imap_lo_l0_raw_20240627_v001__first4000pkts.pkts"
LO_XTCE = DATA / "lo" / "lo_xtce.xml"
SWAPI = DATA / "swapi" / "imap_swapi_l0_raw_20240924_v001.pkts"
SWAPI_XTCE = DATA / "swapi" / "swapi_packet_definition.xml"
CTIM = DATA.parent / "ctim" / "ccsds_2021_155_14_39_51__first300pkts"
CTIM_XTCE = DATA.parent / "ctim" / "ctim_xtce_v1.xml"
CTIM_ROOT = "CCSDSTelemetryPacket"  # what space_packet_parser's own CTIM test passes as root_container_name
# CTIM's SHCOARSE/SHFINE clock (1/65536 s) has no published epoch: the tests take the GPS epoch
CTIM_TIME = "coarse=SHCOARSE,fine=SHFINE,fine_bits=16,epoch=1980-01-06T00:00:00Z"
# IMAP's mission elapsed time: seconds since 2010-01-01 (the instruments' clock; these are ground runs)
MET = "epoch=2010-01-01T00:00:00Z"
# The XTCE parameters of the primary header: the packet's own (sequence count and raw octets archived), not series
PRIMARY_HEADER = ("VERSION", "TYPE", "SEC_HDR_FLG", "PKT_APID", "SEQ_FLGS", "SRC_SEQ_CTR", "PKT_LEN")
CTIM_HEADER = ("SEC_HDR_FLAG", "SEQ_CTR")  # CTIM's names for two of them
logging.getLogger("ccsdspy").setLevel(logging.ERROR)  # it warns of the several APIDs of these streams


def _spp_read(data: bytes, xtce: Path, root: str | None = None) -> tuple[list[tuple[bytes, dict[str, float]]], Counter]:
    """space_packet_parser's reading: (packet octets, numeric values) of every packet it parses (enumerations as
    raw codes, as archived; header parameters left out), and per APID the packets it refuses (no container)."""
    import space_packet_parser as spp

    definition = (
        spp.load_xtce(xtce) if root is None else spp.XtcePacketDefinition.from_xtce(xtce, root_container_name=root)
    )
    parsed, refused = [], Counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "bits parsed did not match the length": SWAPI's HK
        for raw in spp.ccsds_generator(data):
            try:
                packet = definition.parse_bytes(raw)
            except spp.exceptions.UnrecognizedPacketTypeError:
                refused[((raw[0] & 7) << 8) | raw[1]] += 1
                continue
            values = {
                k: float(v if isinstance(v, (int, float)) else v.raw_value)
                for k, v in packet.items()
                if not isinstance(v.raw_value, bytes) and k not in PRIMARY_HEADER + CTIM_HEADER
            }
            parsed.append((bytes(raw), values))
    return parsed, refused


def _apid(packet: bytes) -> int:
    return ((packet[0] & 7) << 8) | packet[1]


def _rows(batch) -> list[bytes]:
    """The octets of each packet of a batch, in the batch's (time) order."""
    if batch.packet_lengths is None:
        return [row.tobytes() for row in batch.packets]
    ends = np.cumsum(batch.packet_lengths)
    return [batch.packets[e - n : e].tobytes() for e, n in zip(ends.tolist(), batch.packet_lengths.tolist())]


def _assert_as_space_packet_parser(result: DecodeResult, theirs: list[tuple[bytes, dict[str, float]]]) -> None:
    """Every packet space_packet_parser parses was accepted, each with exactly its values (matched by octets);
    a parameter its container lacks is absent (NaN) in ours."""
    assert {a: s.accepted for a, s in result.report.apids.items()} == Counter(_apid(p) for p, _ in theirs)
    by_octets: dict[bytes, deque[dict[str, float]]] = defaultdict(deque)
    for packet, values in theirs:
        by_octets[packet].append(values)
    different, absent = Counter(), Counter()
    for batch in result.batches:
        for i, packet in enumerate(_rows(batch)):
            values = by_octets[packet].popleft()
            for name, column in batch.values.items():
                if name not in values:
                    absent[name] += not np.isnan(column[i])
            for name, value in values.items():
                different[name] += name not in batch.values or float(batch.values[name][i]) != value
    assert +different == Counter() and +absent == Counter()
    assert all(not left for left in by_octets.values())


def _kept_raw_as_ccsdspy_splits_them(data: bytes, result: DecodeResult, apids: Counter) -> None:
    """The packets of APIDs without a definition counted and kept byte-exact, per APID."""
    split = split_by_apid(io.BytesIO(data))
    assert result.report.undefined_apids == dict(apids)
    assert {u.apid: u.packets.tobytes() for u in result.undefined} == {a: split[a].getvalue() for a in apids}


def _no_packet_by_packet_parsing(*_: object) -> None:
    raise AssertionError("space_packet_parser was called packet by packet: the bulk container walk was not taken")


def test_ultra_containers_selected_by_ored_apids_decode_as_space_packet_parser_reads_them(monkeypatch) -> None:
    """IMAP-Ultra (7 APIDs interleaved, 3 of variable length): its containers are selected by
    ``PKT_APID == 880 OR PKT_APID == 994`` (Ultra-45 and Ultra-90); each APID of an OR is defined, the variable
    containers decode in bulk (the walk evaluates the ORed conditions), every value as space_packet_parser's;
    the 3 APIDs it refuses are kept raw."""
    monkeypatch.setattr("telemetry.decoding._xtce_one_by_one", _no_packet_by_packet_parsing)
    dictionary = load_dictionary(ULTRA_XTCE, time_fields=f"coarse=SHCOARSE,{MET}")
    assert {a: p.name for a, p in dictionary.packets.items() if a in (880, 994, 896, 960)} == {
        880: "UltraAuxiliaryPacket",
        994: "UltraAuxiliaryPacket",
        896: "UltraRawEventsPacket",
        960: "UltraRawEventsPacket",
    }
    data = ULTRA.read_bytes()
    result = decode_stream(data, dictionary)
    theirs, refused = _spp_read(data, ULTRA_XTCE)
    assert result.report.quarantined == []
    _assert_as_space_packet_parser(result, theirs)
    assert {a: len(s.packet_octets) for a, s in result.report.apids.items()} == {880: 1, 881: 12, 883: 28, 896: 46}
    _kept_raw_as_ccsdspy_splits_them(data, result, refused)


def test_hit_segmented_science_packets_each_decode_as_space_packet_parser_reads_them() -> None:
    """IMAP-HIT science frames span many packets (sequence flags first, continuation, last: CCSDS 133.0-B-2
    §4.1.3.4.2.2); space_packet_parser (segments not combined) parses each with its container, so do we, and the
    report counts the segments. Its housekeeping (fixed, another file) likewise."""
    dictionary = load_dictionary(HIT_XTCE, time_fields=f"coarse=*SC_TICK,{MET}")
    for path in (HIT_SCIENCE, HIT_HOUSEKEEPING):
        data = path.read_bytes()
        result = decode_stream(data, dictionary)
        theirs, refused = _spp_read(data, HIT_XTCE)
        assert result.report.quarantined == [] and refused == Counter()
        _assert_as_space_packet_parser(result, theirs)
        flags = read_primary_headers(str(path))["CCSDS_SEQUENCE_FLAG"]
        assert [s.segmented for s in result.report.apids.values()] == [int(np.count_nonzero(flags != 3))]
    assert result.report.apids[1251].segmented == 0
    assert decode_stream(HIT_SCIENCE.read_bytes(), dictionary).report.apids[1252].segmented == 400


def test_segmented_packets_of_an_apid_without_definition_are_kept_raw_not_lost_in_framing() -> None:
    """Segmented packets confirm the framing as any telemetry packet does: HIT science with only the housekeeping
    defined, and IMAP-Lo (12 APIDs, direct events segmented) with only its housekeeping 677 defined, keep every
    other packet raw, per APID as ccsdspy counts them (before, the first segment stopped the chain: the rest of
    the file became one unknown_apid stretch)."""
    hit = load_dictionary(HIT_XTCE, time_fields=f"coarse=*SC_TICK,{MET}")
    lo = load_dictionary(LO_XTCE, time_fields=f"coarse=*SHCOARSE,{MET}")
    for path, dictionary, defined in ((HIT_SCIENCE, hit, 1251), (LO, lo, 677)):
        only = replace(dictionary, packets={defined: dictionary.packets[defined]})
        data = path.read_bytes()
        result = decode_stream(data, only)
        counts = Counter(read_primary_headers(str(path))["CCSDS_APID"].tolist())
        assert result.report.quarantined == []
        assert result.report.packets_accepted == counts.pop(defined, 0)
        _kept_raw_as_ccsdspy_splits_them(data, result, counts)


def test_lo_through_acs_twin_ingest_cubic_calibrations_to_the_bit(tmp_path: Path, capsys) -> None:
    """IMAP-Lo, 4,000 packets of 12 APIDs: 5 defined (cubic polynomial calibrations, polymorphic and segmented
    science), 7 that space_packet_parser refuses kept raw. ``acs-twin ingest`` then archives every value of
    every defined APID as space_packet_parser computes it (its term-by-term sum, not Horner's: BHV_DEF_NEG_I
    differed in the last bit); a re-ingest reports its duplicates per APID and adds nothing."""
    from backend.cli import main
    from telemetry.archive import Archive

    data = LO.read_bytes()
    time_fields = f"coarse=*SHCOARSE,{MET}"
    result = decode_stream(data, load_dictionary(LO_XTCE, time_fields=time_fields))
    theirs, refused = _spp_read(data, LO_XTCE)
    assert result.report.quarantined == [] and result.report.apids[706].segmented == 6
    _assert_as_space_packet_parser(result, theirs)
    _kept_raw_as_ccsdspy_splits_them(data, result, refused)

    url = f"sqlite:///{tmp_path / 'lo.db'}"
    argv = ["ingest", str(LO), "--dictionary", str(LO_XTCE), "--time-fields", time_fields]
    argv += ["--satellite", "IMAP-LO", "--db", url, "--user", "ops"]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)
    defined = Counter(_apid(p) for p, _ in theirs)
    assert {int(a): s["accepted"] for a, s in first["decode"]["apids"].items()} == defined
    assert first["archive"]["packets_accepted"] == defined.total()
    series: dict[str, list[tuple[int, float]]] = defaultdict(list)  # (MET s from the packet's SHCOARSE, value)
    for _, values in theirs:
        met_s = int(next(v for k, v in values.items() if k.endswith("SHCOARSE")))
        for name, value in values.items():
            series[name].append((met_s, value))
    with Archive(url) as archive:
        for name in ("ILO_APP_NHK.BHV_DEF_NEG_I", "ILO_APP_NHK.BHV_DEF_POS_I", "ILO_SCI_DE.COUNT"):
            t, v = archive.read_parameter("IMAP-LO", name, 0, 2**62)
            met_s = (t - np.datetime64("2010-01-01T00:00:00", "ns").astype(np.int64)) // 10**9
            assert sorted(zip(met_s.tolist(), np.asarray(v, float).tolist())) == sorted(series[name]), name
        assert {a: len(p) for a, p in archive.undefined_packets("IMAP-LO").items()} == dict(refused)
    assert main(argv) == 0
    again = json.loads(capsys.readouterr().out)["archive"]
    assert again["packets_accepted"] == 0 and again["duplicates_by_apid"] == {str(a): n for a, n in defined.items()}


def test_a_time_field_named_without_its_container_prefix_is_refused_with_the_wildcard_that_fits() -> None:
    """IMAP-Lo prefixes every parameter with its container (ILO_APP_NHK.SHCOARSE …): ``coarse=SHCOARSE`` matches
    none, and the refusal names a parameter it meant and the wildcard spelling that matches in every packet."""
    with pytest.raises(
        ValueError, match=r"no parameter matching 'SHCOARSE' \(but \['ILO_.*\.SHCOARSE'\]: .*'\*SHCOARSE'"
    ):
        load_dictionary(LO_XTCE, time_fields=f"coarse=SHCOARSE,{MET}")


def test_swapi_housekeeping_longer_than_its_container_decodes_and_says_so() -> None:
    """IMAP-SWAPI: the HK container (1184) has 78 octets, its packets 84; space_packet_parser parses the 78 (and
    warns), so do we, the report counting 17 packets longer than the definition. APID 1187 has no container:
    space_packet_parser reads only its header (the root container is concrete), we keep it raw."""
    dictionary = load_dictionary(SWAPI_XTCE, time_fields=f"coarse=SHCOARSE,{MET}")
    data = SWAPI.read_bytes()
    result = decode_stream(data, dictionary)
    theirs, refused = _spp_read(data, SWAPI_XTCE)
    header_only = Counter(_apid(p) for p, values in theirs if not values)
    assert refused == Counter() and header_only == {1187: 140}
    _assert_as_space_packet_parser(result, [(p, v) for p, v in theirs if v])
    summary = result.report.apids[1184]
    assert (summary.definition_octets, summary.longer_than_definition, summary.packet_octets) == (78, 17, {84: 17})
    _kept_raw_as_ccsdspy_splits_them(data, result, header_only)


@pytest.mark.filterwarnings("ignore:Number of bits parsed")  # APIDs 1, 20 (strings): spp parses them, and warns
def test_ctim_with_its_own_root_container_and_a_jittered_clock_through_acs_twin_ingest(tmp_path: Path, capsys) -> None:
    """CTIM (300 packets, 9 APIDs, 3 of them polymorphic or variable): its XTCE roots every container in
    ``CCSDSTelemetryPacket``, which space_packet_parser must be told (we crashed on a KeyError: 'CCSDSPacket');
    the root is the one container without a base that others extend. APID 32's count 4104 is stamped 0.3 ms after
    4105: kept (it was quarantined as non_monotonic_sequence, with a gap of one reported). Every value as
    space_packet_parser's, through acs-twin ingest."""
    from backend.cli import main
    from telemetry.archive import Archive

    data = CTIM.read_bytes()
    dictionary = load_dictionary(CTIM_XTCE, time_fields=CTIM_TIME)
    result = decode_stream(data, dictionary)
    theirs, refused = _spp_read(data, CTIM_XTCE, root=CTIM_ROOT)
    assert refused == Counter() and result.report.quarantined == []
    _assert_as_space_packet_parser(result, theirs)
    assert result.report.apids[32].missing == 0
    url = f"sqlite:///{tmp_path / 'ctim.db'}"
    argv = ["ingest", str(CTIM), "--dictionary", str(CTIM_XTCE), "--time-fields", CTIM_TIME]
    assert main([*argv, "--satellite", "CTIM", "--db", url, "--user", "ops"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert {int(a): s["accepted"] for a, s in report["decode"]["apids"].items()} == Counter(_apid(p) for p, _ in theirs)
    with Archive(url) as archive:
        archived = set(archive.parameters("CTIM"))
    assert archived == {name for _, values in theirs for name in values}


@pytest.mark.parametrize(
    "expression",
    [
        "<xtce:ANDedConditions>{a}{b}</xtce:ANDedConditions>",
        "<xtce:ORedConditions>{a}<xtce:ANDedConditions>{b}{c}</xtce:ANDedConditions></xtce:ORedConditions>",
        "<xtce:ANDedConditions>{b}<xtce:ORedConditions>{a}{c}</xtce:ORedConditions></xtce:ANDedConditions>",
        "{a}",
    ],
)
def test_boolean_restrictions_choose_containers_as_space_packet_parser_does(
    expression: str, tmp_path: Path, monkeypatch
) -> None:
    """A BooleanExpression (a Condition, ANDs, ORs, nested) on two fields chooses the inheritor per packet, over
    every combination of the two fields: the bulk walk accepts the packets space_packet_parser parses with its
    values, and quarantines those it refuses (no inheritor, or several, matching)."""
    import space_packet_parser as spp

    monkeypatch.setattr("telemetry.decoding._xtce_one_by_one", _no_packet_by_packet_parsing)
    conditions = {"a": ("KIND", "==", 1), "b": ("MODE", "&gt;", 2), "c": ("KIND", "!=", 3)}
    xtce = tmp_path / "restricted.xml"
    xtce.write_text(_xtce_choosing_b_by(expression.format(**{k: _condition(*c) for k, c in conditions.items()})))
    rows = [
        bytes([0x08, 100, 0xC0, i, 0, 8, 0, 0, 0, i, kind, mode, 1, 2, 3])
        for i, (kind, mode) in enumerate((k, m) for k in range(5) for m in range(5))
    ]
    definition = spp.load_xtce(xtce)
    theirs, refused = [], 0
    for raw in rows:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # A and B are shorter than the packets: spp warns
                packet = definition.parse_bytes(raw)
        except spp.exceptions.UnrecognizedPacketTypeError:
            refused += 1
            continue
        theirs.append((raw, {k: float(v) for k, v in packet.items() if k not in PRIMARY_HEADER}))
    assert refused and {n for _, v in theirs for n in v} >= {"XA", "XB", "XC"}
    result = decode_stream(b"".join(rows), load_dictionary(xtce, time_fields=f"coarse=MET,{MET}"))
    _assert_as_space_packet_parser(result, theirs)
    assert len(result.report.quarantined) == refused


def _condition(parameter: str, operator: str, value: int) -> str:
    return (
        f'<xtce:Condition><xtce:ParameterInstanceRef parameterRef="{parameter}" useCalibratedValue="false"/>'
        f"<xtce:ComparisonOperator>{operator}</xtce:ComparisonOperator><xtce:Value>{value}</xtce:Value>"
        "</xtce:Condition>"
    )


def _xtce_choosing_b_by(expression: str) -> str:
    """An XTCE of APID 100: after the primary header MET (32 bits), KIND, MODE (8 each), then one of containers
    A (XA, 16 bits: KIND == 0), B (XB, 8 bits: the BooleanExpression), C (XC, 24 bits: MODE == 0)."""
    bits = {"VERSION": 3, "TYPE": 1, "SEC_HDR_FLG": 1, "PKT_APID": 11, "SEQ_FLGS": 2, "SRC_SEQ_CTR": 14}
    bits |= {"PKT_LEN": 16, "MET": 32, "KIND": 8, "MODE": 8, "XA": 16, "XB": 8, "XC": 24}

    def entries(*names: str) -> str:
        return (
            "<xtce:EntryList>"
            + "".join(f'<xtce:ParameterRefEntry parameterRef="{n}"/>' for n in names)
            + ("</xtce:EntryList>")
        )

    def container(name: str, base: str, criteria: str, *names: str, abstract: bool = False) -> str:
        return (
            f'<xtce:SequenceContainer name="{name}" abstract="{str(abstract).lower()}">'
            f'<xtce:BaseContainer containerRef="{base}"><xtce:RestrictionCriteria>{criteria}'
            f"</xtce:RestrictionCriteria></xtce:BaseContainer>{entries(*names)}</xtce:SequenceContainer>"
        )

    def compare(name: str, value: int) -> str:
        return f'<xtce:Comparison parameterRef="{name}" value="{value}" useCalibratedValue="false"/>'

    types = "".join(
        f'<xtce:IntegerParameterType name="U{n}" signed="false"><xtce:IntegerDataEncoding sizeInBits="{n}"/>'
        "</xtce:IntegerParameterType>"
        for n in sorted(set(bits.values()))
    )
    parameters = "".join(f'<xtce:Parameter name="{n}" parameterTypeRef="U{b}"/>' for n, b in bits.items())
    return (
        '<?xml version="1.0" encoding="UTF-8"?>'
        '<xtce:SpaceSystem xmlns:xtce="http://www.omg.org/space/xtce" name="T"><xtce:TelemetryMetaData>'
        f"<xtce:ParameterTypeSet>{types}</xtce:ParameterTypeSet><xtce:ParameterSet>{parameters}</xtce:ParameterSet>"
        '<xtce:ContainerSet><xtce:SequenceContainer name="CCSDSPacket" abstract="true">'
        f"{entries(*list(bits)[:7])}</xtce:SequenceContainer>"
        + container("HK", "CCSDSPacket", compare("PKT_APID", 100), "MET", "KIND", "MODE", abstract=True)
        + container("A", "HK", compare("KIND", 0), "XA")
        + container("B", "HK", f"<xtce:BooleanExpression>{expression}</xtce:BooleanExpression>", "XB")
        + container("C", "HK", compare("MODE", 0), "XC")
        + "</xtce:ContainerSet></xtce:TelemetryMetaData></xtce:SpaceSystem>"
    )
