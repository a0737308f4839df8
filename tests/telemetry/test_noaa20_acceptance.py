"""Real-data acceptance: 7,200 NOAA-20 APID-11 packets through the XTCE and the ccsdspy CSV layouts.

Truths: the decoded CSV shipped beside the packets (space-packet-parser's test data), the
ccsdspy and space-packet-parser libraries themselves, and geometry (body +z points at nadir).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from sim_core import quaternion
from telemetry.decoding import decode_stream, quaternion_of
from telemetry.dictionary import load_dictionary

NOAA = "real/noaa20_jpss1_apid11"
PACKETS = "J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
N_PACKETS = 7200
US = 1_000  # ns: the decoded CSV prints times to the microsecond
# NOAA-20 points +z at the geodetic nadir; geocentric and geodetic verticals differ by up to 0.19°
# at mid-latitudes, and GCRS→ITRS from skyfield (IAU 2000) leaves no other error of that size.
NADIR_TOLERANCE_DEG = 0.25
SPP_SUBSET = 300  # space-packet-parser decodes packet by packet: a subset keeps the test fast


@pytest.fixture(scope="module")
def truth(shared_data: Path) -> dict[str, np.ndarray]:
    """Columns of the decoded CSV: times as int64 UTC ns, the rest float64."""
    with (shared_data / NOAA / "jpss1_apid11_decoded.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    cols = {k: [r[k] for r in rows] for k in rows[0]}
    out = {}
    for k, v in cols.items():
        if k.endswith("time") or k.endswith("cds"):
            out[k] = np.array(v, dtype="datetime64[us]").astype("datetime64[ns]").astype(np.int64)
        else:
            out[k] = np.array(v, dtype=np.float64)
    return out


@pytest.fixture(scope="module")
def raw_bytes(shared_data: Path) -> bytes:
    """The 511,200-octet packet file."""
    return (shared_data / NOAA / PACKETS).read_bytes()


@pytest.mark.parametrize("dictionary", ["noaa20_apid11_xtce.yaml", "noaa20_apid11_ccsdspy.yaml"])
def test_noaa20_decodes_identically_to_published_csv(dictionary: str, raw_bytes: bytes, truth: dict) -> None:
    result = decode_stream(raw_bytes, load_dictionary(dictionary))
    assert result.report.packets_accepted == N_PACKETS
    assert result.report.quarantined == [] and result.report.duplicates == 0
    (batch,) = result.batches
    v = batch.values
    for ours, theirs in [
        ("ADGPSPOSX", "pos_x_m"),
        ("ADGPSPOSY", "pos_y_m"),
        ("ADGPSPOSZ", "pos_z_m"),
        ("ADGPSVELX", "vel_x_mps"),
        ("ADGPSVELY", "vel_y_mps"),
        ("ADGPSVELZ", "vel_z_mps"),
        ("ADCFAQ1", "q1"),
        ("ADCFAQ2", "q2"),
        ("ADCFAQ3", "q3"),
        ("ADCFAQ4", "q4"),
    ]:
        np.testing.assert_array_equal(v[ours], truth[theirs], err_msg=ours)
    for ours, theirs in [
        (batch.t_utc_ns, "pkt_time_utc_cds"),
        (v["ephem_time_utc_ns"], "ephem_time"),
        (v["att_time_utc_ns"], "att_time"),
    ]:
        np.testing.assert_array_equal(ours // US, truth[theirs] // US, err_msg=theirs)


def test_noaa20_quaternion_in_our_convention_is_scalar_first(raw_bytes: bytes, truth: dict) -> None:
    (batch,) = decode_stream(raw_bytes, load_dictionary("noaa20_apid11_xtce.yaml")).batches
    q_ib = quaternion_of(batch.values, "q_ib")
    expected = np.stack([truth["q4"], truth["q1"], truth["q2"], truth["q3"]], axis=-1)
    np.testing.assert_array_equal(q_ib, expected)


def test_noaa20_body_z_points_at_nadir_through_q_ib(raw_bytes: bytes) -> None:
    """q_ib rotates body +z onto −r̂ in GCRS (ECEF GPS fix rotated by skyfield's ITRS frame)."""
    from skyfield.api import load
    from skyfield.framelib import itrs

    (batch,) = decode_stream(raw_bytes, load_dictionary("noaa20_apid11_xtce.yaml")).batches
    v = batch.values
    r_ecef_m = np.stack([v["ADGPSPOSX"], v["ADGPSPOSY"], v["ADGPSPOSZ"]], axis=-1)
    ts = load.timescale(builtin=True)
    t = ts.utc(1970, 1, 1, 0, 0, v["att_time_utc_ns"] / 1e9)
    gcrs_to_itrs = itrs.rotation_at(t)  # (3, 3, n)
    r_gcrs_m = np.einsum("jin,nj->ni", gcrs_to_itrs, r_ecef_m)
    nadir = -r_gcrs_m / np.linalg.norm(r_gcrs_m, axis=-1, keepdims=True)
    z_gcrs = quaternion.rotate(quaternion_of(v, "q_ib"), np.array([0.0, 0.0, 1.0]))
    off_deg = np.degrees(np.arccos(np.clip(np.sum(z_gcrs * nadir, axis=-1), -1.0, 1.0)))
    assert off_deg.max() < NADIR_TOLERANCE_DEG


def test_noaa20_matches_ccsdspy_library_decode(raw_bytes: bytes, shared_data: Path) -> None:
    from io import BytesIO

    import ccsdspy

    definition = ccsdspy.FixedLength.from_file(str(shared_data / NOAA / "ccsdspy_jpss1_geolocation.csv"))
    theirs = definition.load(BytesIO(raw_bytes), include_primary_header=True)
    (batch,) = decode_stream(raw_bytes, load_dictionary("noaa20_apid11_ccsdspy.yaml")).batches
    for name, values in batch.values.items():
        if name in theirs:
            np.testing.assert_array_equal(values, theirs[name], err_msg=name)
    np.testing.assert_array_equal(batch.sequence_count, theirs["CCSDS_SEQUENCE_COUNT"])


def test_noaa20_matches_space_packet_parser_per_packet_decode(raw_bytes: bytes) -> None:
    import space_packet_parser as spp

    xtce = Path(__file__).parents[2] / "telemetry" / "dictionaries" / "jpss1_geolocation_xtce_v1.xml"
    definition = spp.load_xtce(xtce)
    (batch,) = decode_stream(raw_bytes, load_dictionary("noaa20_apid11_xtce.yaml")).batches
    packets = list(spp.ccsds_generator(raw_bytes[: SPP_SUBSET * 71]))
    for i, raw_packet in enumerate(packets):
        parsed = definition.parse_bytes(raw_packet)
        for name in ("ADGPSPOSX", "ADGPSVELZ", "ADCFAQ4", "ADAET1MS", "USEC"):
            assert batch.values[name][i] == parsed[name], (i, name)


def test_acs_twin_ingest_command_stores_noaa20_once(shared_data: Path, tmp_path: Path, capsys) -> None:
    """The CLI prints the joined JSON report; the same file again is a reported no-op."""
    import json

    from backend.cli import main

    url = f"sqlite:///{tmp_path / 'archive.sqlite'}"
    argv = [
        "ingest",
        str(shared_data / NOAA / PACKETS),
        "--dictionary",
        "noaa20_apid11_xtce.yaml",
        "--db",
        url,
        "--user",
        "tester",
    ]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["decode"]["packets_accepted"] == N_PACKETS
    assert first["archive"]["packets_accepted"] == N_PACKETS and not first["archive"]["duplicate_upload"]
    assert main(argv) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["archive"]["duplicate_upload"] and again["archive"]["packets_accepted"] == 0


def test_acs_twin_ingest_command_reports_bad_input_as_json(capsys) -> None:
    import json

    from backend.cli import main

    assert main(["ingest", "/no/such/file", "--dictionary", "noaa20_apid11_xtce.yaml", "--dry-run"]) == 2
    assert "path" in json.loads(capsys.readouterr().out)["error"]


def test_noaa20_packet_with_impossible_cds_time_is_quarantined(raw_bytes: bytes) -> None:
    """Packet 100 given ms-of-day 90,000,000 (> one day): quarantined as time_out_of_range, neighbours kept."""
    data = bytearray(raw_bytes[: 200 * 71])
    data[100 * 71 + 8 : 100 * 71 + 12] = (90_000_000).to_bytes(4, "big")
    result = decode_stream(bytes(data), load_dictionary("noaa20_apid11_xtce.yaml"))
    assert [(q.reason, q.offset, q.detail) for q in result.report.quarantined] == [
        ("invalid_time", 100 * 71, "invalid time code field")
    ]
    assert result.report.packets_accepted == 199
