"""Telemetry dictionary: shipped YAML, ccsdspy CSV and XTCE loaders, and their errors.

Truths: the independent layouts of the same NOAA-20 packet (XTCE vs ccsdspy CSV), ccsdspy decoding
packets from a layout we export, space-packet-parser's own calibration of an XTCE file, and the
requirements of issue 5 / seed 000 (T_q = 0.25 s, MD moment ≤ 25 A·m²).
"""

from __future__ import annotations

from io import BytesIO
from pathlib import Path

import ccsdspy
import numpy as np
import pytest
import yaml

from telemetry.ccsds import TimeCode
from telemetry.decoding import decode_raw
from telemetry.dictionary import Limits, Parameter, load_ccsdspy_csv, load_dictionary, load_xtce, parse_time_code
from telemetry.encoding import encode_packets

SHIPPED = Path(__file__).parents[2] / "telemetry" / "dictionaries"
T_Q_S = 0.25  # seed 000 §5: quaternion sampling period
MD_MOMENT_MAX_AM2 = 25.0  # seed 000 §5: magnetic-driver moment bound
HORNER_VS_POWERS_REL = 1e-15  # our Horner sum vs space-packet-parser's sum of powers: a few ulp of float64


def test_xtce_and_ccsdspy_csv_give_the_same_noaa20_layout() -> None:
    xtce = load_xtce(SHIPPED / "jpss1_geolocation_xtce_v1.xml").packets[11]
    csv_layout = load_ccsdspy_csv(SHIPPED / "ccsdspy_jpss1_geolocation.csv", apid=11).packets[11]
    assert xtce.packet_octets == csv_layout.packet_octets == 71
    assert [(p.name, p.bit_offset, p.bit_length, p.data_type) for p in xtce.parameters] == [
        (p.name, p.bit_offset, p.bit_length, p.data_type) for p in csv_layout.parameters
    ]
    assert xtce.parameters[0].units == "day"


def _ccsdspy_layout(parameters: tuple[Parameter, ...]) -> ccsdspy.FixedLength:
    """A ccsdspy definition with our bit offsets (both count from the first octet of the packet)."""
    return ccsdspy.FixedLength(
        [
            ccsdspy.PacketField(name=p.name, data_type=p.data_type, bit_length=p.bit_length, bit_offset=p.bit_offset)
            for p in parameters
        ]
    )


def test_reference_layout_decodes_identically_in_ccsdspy() -> None:
    """Our offsets for every field (including the 1-bit fault flags) read the same raw values in ccsdspy."""
    dictionary = load_dictionary("reference_satellite.yaml")
    rng = np.random.default_rng(11)
    for packet in dictionary.packets.values():
        n = 300
        values = {}
        for p in packet.parameters:
            if p.data_type == "float":
                values[p.name] = rng.normal(size=n)
            elif p.polynomial:
                values[p.name] = rng.integers(-2000, 2000, n) * p.polynomial[1]
            else:
                values[p.name] = rng.integers(0, 1 << min(p.bit_length, 8), n)
        packets = encode_packets(packet, 1_700_000_000 * 10**9 + np.arange(n) * 10**9, np.arange(n), values)
        theirs = _ccsdspy_layout(packet.parameters).load(BytesIO(packets.tobytes()))
        ours = decode_raw(packets, packet)
        for p in packet.parameters:
            np.testing.assert_array_equal(ours[p.name], theirs[p.name], err_msg=p.name)


def test_reference_dictionary_carries_the_acs_housekeeping_of_issue_5() -> None:
    d = load_dictionary("reference_satellite.yaml")
    hk, gps = d.packets[256], d.packets[257]
    names = {p.name for p in hk.parameters} | {x.name for x in hk.derived}
    required = (
        [f"q_st_ib_{k}" for k in range(4)]
        + [f"q_est_ib_{k}" for k in range(4)]
        + [f"q_prog_ib_{k}" for k in range(4)]
        + [f"omega_est_b_rad_s_{a}" for a in "xyz"]
        + [f"omega_gyro_b_rad_s_{a}" for a in "xyz"]
        + [f"wheel_speed_rad_s_{k}" for k in range(1, 5)]
        + [f"wheel_torque_cmd_nm_{k}" for k in range(1, 5)]
        + [f"wheel_current_a_{k}" for k in range(1, 5)]
        + [f"md_dipole_am2_{a}" for a in "xyz"]
        + [f"b_mag_b_t_{a}" for a in "xyz"]
        + ["mode", "fdir_event", "fault_wheel_1", "attitude_error_rad"]
    )
    assert set(required) <= names
    assert hk.period_s == T_Q_S and hk.crc and hk.time_code == TimeCode("CUC", 4, 2, epoch_ns=946_684_800 * 10**9)
    assert {"r_ecef_m_x", "v_ecef_m_s_z", "gps_week", "gps_seconds_of_week"} <= {p.name for p in gps.parameters}
    _, md = d.parameter("md_dipole_am2_x")
    assert md.limits.red_high == MD_MOMENT_MAX_AM2 and md.limits.red_low == -MD_MOMENT_MAX_AM2
    _, mode = d.parameter("mode")
    assert mode.enumeration[4] == "PROGRAM_TURN"


def test_every_shipped_yaml_loads() -> None:
    for path in SHIPPED.glob("*.yaml"):
        if not path.name.endswith(".attitude.yaml"):  # attitude mappings beside dictionaries (issue 11)
            assert load_dictionary(path).packets, path.name


XTCE_WITH_CALIBRATION = """<?xml version='1.0' encoding='UTF-8'?>
<xtce:SpaceSystem name="Cal" xmlns:xtce="http://www.omg.org/spec/XTCE/20180204">
 <xtce:TelemetryMetaData>
  <xtce:ParameterTypeSet>
   <xtce:IntegerParameterType name="U3" signed="false"><xtce:IntegerDataEncoding sizeInBits="3" encoding="unsigned"/></xtce:IntegerParameterType>
   <xtce:IntegerParameterType name="U1" signed="false"><xtce:IntegerDataEncoding sizeInBits="1" encoding="unsigned"/></xtce:IntegerParameterType>
   <xtce:IntegerParameterType name="U11" signed="false"><xtce:IntegerDataEncoding sizeInBits="11" encoding="unsigned"/></xtce:IntegerParameterType>
   <xtce:IntegerParameterType name="U2" signed="false"><xtce:IntegerDataEncoding sizeInBits="2" encoding="unsigned"/></xtce:IntegerParameterType>
   <xtce:IntegerParameterType name="U14" signed="false"><xtce:IntegerDataEncoding sizeInBits="14" encoding="unsigned"/></xtce:IntegerParameterType>
   <xtce:IntegerParameterType name="U16" signed="false"><xtce:IntegerDataEncoding sizeInBits="16" encoding="unsigned"/></xtce:IntegerParameterType>
   <xtce:FloatParameterType name="TEMP_Type"><xtce:UnitSet><xtce:Unit>K</xtce:Unit></xtce:UnitSet>
    <xtce:IntegerDataEncoding sizeInBits="12" encoding="twosComplement">
     <xtce:DefaultCalibrator><xtce:PolynomialCalibrator>
      <xtce:Term coefficient="273.15" exponent="0"/><xtce:Term coefficient="0.125" exponent="1"/><xtce:Term coefficient="0.001" exponent="2"/>
     </xtce:PolynomialCalibrator></xtce:DefaultCalibrator>
    </xtce:IntegerDataEncoding></xtce:FloatParameterType>
   <xtce:EnumeratedParameterType name="MODE_Type"><xtce:IntegerDataEncoding sizeInBits="4" encoding="unsigned"/>
    <xtce:EnumerationList><xtce:Enumeration value="0" label="SAFE"/><xtce:Enumeration value="3" label="FINE"/></xtce:EnumerationList>
   </xtce:EnumeratedParameterType>
  </xtce:ParameterTypeSet>
  <xtce:ParameterSet>
   <xtce:Parameter name="VERSION" parameterTypeRef="U3"/><xtce:Parameter name="TYPE" parameterTypeRef="U1"/>
   <xtce:Parameter name="SEC_HDR_FLG" parameterTypeRef="U1"/><xtce:Parameter name="PKT_APID" parameterTypeRef="U11"/>
   <xtce:Parameter name="SEQ_FLGS" parameterTypeRef="U2"/><xtce:Parameter name="SRC_SEQ_CTR" parameterTypeRef="U14"/>
   <xtce:Parameter name="PKT_LEN" parameterTypeRef="U16"/>
   <xtce:Parameter name="TEMP" parameterTypeRef="TEMP_Type"/><xtce:Parameter name="MODE" parameterTypeRef="MODE_Type"/>
  </xtce:ParameterSet>
  <xtce:ContainerSet>
   <xtce:SequenceContainer name="CCSDSPacket" abstract="true"><xtce:EntryList>
    <xtce:ParameterRefEntry parameterRef="VERSION"/><xtce:ParameterRefEntry parameterRef="TYPE"/>
    <xtce:ParameterRefEntry parameterRef="SEC_HDR_FLG"/><xtce:ParameterRefEntry parameterRef="PKT_APID"/>
    <xtce:ParameterRefEntry parameterRef="SEQ_FLGS"/><xtce:ParameterRefEntry parameterRef="SRC_SEQ_CTR"/>
    <xtce:ParameterRefEntry parameterRef="PKT_LEN"/></xtce:EntryList></xtce:SequenceContainer>
   <xtce:SequenceContainer name="THERMAL"><xtce:EntryList>
    <xtce:ParameterRefEntry parameterRef="TEMP"/><xtce:ParameterRefEntry parameterRef="MODE"/></xtce:EntryList>
    <xtce:BaseContainer containerRef="CCSDSPacket"><xtce:RestrictionCriteria><xtce:ComparisonList>
     <xtce:Comparison parameterRef="PKT_APID" value="42" useCalibratedValue="false"/>
    </xtce:ComparisonList></xtce:RestrictionCriteria></xtce:BaseContainer></xtce:SequenceContainer>
  </xtce:ContainerSet>
 </xtce:TelemetryMetaData>
</xtce:SpaceSystem>
"""


def test_xtce_polynomial_and_enumeration_match_space_packet_parser(tmp_path: Path) -> None:
    import space_packet_parser as spp

    from telemetry.decoding import decode_packets

    path = tmp_path / "cal.xml"
    path.write_text(XTCE_WITH_CALIBRATION)
    packet = load_xtce(path).packets[42]
    temp = next(p for p in packet.parameters if p.name == "TEMP")
    assert temp.polynomial == (273.15, 0.125, 0.001) and temp.bit_length == 12 and temp.data_type == "int"
    assert next(p for p in packet.parameters if p.name == "MODE").enumeration == {0: "SAFE", 3: "FINE"}
    header = bytes([0x08, 42, 0xC0, 0x00, 0x00, 0x01])
    raw_rows = [header + ((t & 0xFFF) << 4 | 3).to_bytes(2, "big") for t in (-2048, -1, 0, 5, 2047)]
    ours = decode_packets(np.frombuffer(b"".join(raw_rows), np.uint8).reshape(5, 8), packet)
    definition = spp.load_xtce(path)
    for i, row in enumerate(raw_rows):
        parsed = definition.parse_bytes(row)
        assert ours["TEMP"][i] == pytest.approx(float(parsed["TEMP"]), rel=HORNER_VS_POWERS_REL)
        assert packet.parameters[1].enumeration[int(ours["MODE"][i])] == str(parsed["MODE"])


def _write_yaml(tmp_path: Path, packet: dict) -> Path:
    path = tmp_path / "d.yaml"
    path.write_text(yaml.safe_dump({"name": "t", "packets": [packet]}))
    return path


BASE_PACKET = {
    "name": "P",
    "apid": 5,
    "time_code": "CUC-4-2",
    "parameters": [{"name": "a", "type": "uint", "bits": 16}],
}


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"parameters": [{"name": "a", "type": "complex", "bits": 16}]}, "a.data_type"),
        ({"parameters": [{"name": "a", "type": "uint", "bits": 12}]}, "octet boundary"),
        ({"parameters": [{"name": "a", "type": "float", "bits": 16}]}, "a.bit_length"),
        ({"packet_octets": 99}, "P.packet_octets"),
        ({"apid": 2047}, "P.apid"),
        ({"time_code": "CUC-9-9"}, "time_code"),
        ({"derived": [{"name": "e", "kind": "alias", "inputs": ["zz"]}]}, "e.inputs"),
        ({"derived": [{"name": "e", "kind": "spline", "inputs": ["a"]}]}, "e.kind"),
        ({"parameters": [{"name": "a\x00b", "type": "uint", "bits": 16}]}, "x00b.name"),  # PostgreSQL: no NUL
        ({"parameters": [{"name": "p" * 129, "type": "uint", "bits": 16}]}, "1 to 128 characters"),  # varchar(128)
        ({"derived": [{"name": "e\nf", "kind": "alias", "inputs": ["a"]}]}, "nf.name"),
        (
            {"parameters": [{"name": "a", "type": "uint", "bits": 16, "limits": {"red_low": 5, "yellow_low": 1}}]},
            "limits",
        ),
    ],
)
def test_bad_yaml_raises_value_error_naming_the_field(tmp_path: Path, change: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        load_dictionary(_write_yaml(tmp_path, {**BASE_PACKET, **change}))


def test_limits_order_and_time_code_short_names() -> None:
    with pytest.raises(ValueError, match="limits"):
        Limits(red_low=1.0, yellow_low=0.0)
    assert parse_time_code("CDS") == TimeCode("CDS")
    assert parse_time_code("CDS-ms").octets == 6
    assert parse_time_code("CUC-4-2").octets == 6


def test_csv_dictionary_needs_an_apid() -> None:
    with pytest.raises(ValueError, match="apid"):
        load_dictionary(SHIPPED / "ccsdspy_jpss1_geolocation.csv")
    with pytest.raises(ValueError, match="dictionary"):
        load_dictionary("no_such_dictionary.yaml")


def test_ccsdspy_csv_fill_arrays_and_offsets_decode_like_ccsdspy(tmp_path: Path) -> None:
    """ccsdspy's own reading of a CSV with padding, a 1-D array and explicit offsets is the truth."""
    path = tmp_path / "layout.csv"
    path.write_text(
        "name,data_type,bit_length,bit_offset\nA,uint,4,48\nPAD,fill,4,52\nV,int(3),12,56\n"
        "F,float,32,96\nB,uint,8,136\n"
    )
    packet = load_ccsdspy_csv(path, apid=3).packets[3]
    assert [p.name for p in packet.parameters] == ["A", "V_0", "V_1", "V_2", "F", "B"]
    assert packet.packet_octets == 18  # bits 128..135 are an implicit gap before B
    rows = np.random.default_rng(8).integers(0, 256, (64, 18), dtype=np.uint8)
    from telemetry import ccsds

    rows[:, :6] = ccsds.encode_primary_headers(3, np.arange(64), 18)
    theirs = ccsdspy.FixedLength.from_file(str(path)).load(BytesIO(rows.tobytes()))
    ours = decode_raw(rows, packet)
    for name in ("A", "F", "B"):
        np.testing.assert_array_equal(ours[name], theirs[name], err_msg=name)
    for k in range(3):
        np.testing.assert_array_equal(ours[f"V_{k}"], theirs["V"][:, k], err_msg=f"V_{k}")


def test_xtce_with_two_layouts_for_one_apid_is_refused(tmp_path: Path) -> None:
    second = XTCE_WITH_CALIBRATION.replace(
        "  </xtce:ContainerSet>",
        '   <xtce:SequenceContainer name="THERMAL_B"><xtce:EntryList><xtce:ParameterRefEntry parameterRef="TEMP"/>'
        '<xtce:ParameterRefEntry parameterRef="MODE"/>'
        '</xtce:EntryList><xtce:BaseContainer containerRef="CCSDSPacket"><xtce:RestrictionCriteria>'
        '<xtce:ComparisonList><xtce:Comparison parameterRef="PKT_APID" value="42" useCalibratedValue="false"/>'
        "</xtce:ComparisonList></xtce:RestrictionCriteria></xtce:BaseContainer></xtce:SequenceContainer>\n"
        "  </xtce:ContainerSet>",
    )
    path = tmp_path / "two.xml"
    path.write_text(second)
    with pytest.raises(ValueError, match="APID 42 already belongs to THERMAL"):
        load_xtce(path)


def test_both_noaa20_layouts_name_the_same_satellite() -> None:
    """Archive key: one spacecraft whichever layout file decoded its packets."""
    names = {load_dictionary(n).satellite_name for n in ("noaa20_apid11_xtce.yaml", "noaa20_apid11_ccsdspy.yaml")}
    assert names == {"NOAA-20"}
    assert load_xtce(SHIPPED / "jpss1_geolocation_xtce_v1.xml").satellite_name == "JPSS_Geolocation_Packets"


def test_time_code_epoch_utc_key_still_reads_as_a_utc_epoch() -> None:
    assert parse_time_code({"format": "CDS", "epoch_utc": "1958-01-01T00:00:00Z"}) == TimeCode("CDS")
    with pytest.raises(ValueError, match="time_code.epoch_utc"):
        parse_time_code({"format": "CUC", "epoch_utc": "1958-01-01", "time_scale": "TAI"})
