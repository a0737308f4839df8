"""Packets kept raw for want of a definition (issue 12 item 2) decoded once a definition arrives: through the API
(POST /telemetry/redecode, in the upload decoder process) and ``acs-twin ingest --redecode``; values as ccsdspy
reads them, nothing decoded twice, packets a wrong definition quarantines kept for the next one."""

from __future__ import annotations

import io
import json
from pathlib import Path

import ccsdspy
from ccsdspy.utils import split_by_apid
from fastapi.testclient import TestClient

from backend.cli import main
from tests.backend.conftest import bearer

CYGNSS = Path(__file__).resolve().parents[1] / "data" / "cygnss_f7"
STREAM = CYGNSS / "CYGNSS_F7_L0_2022_086_10_15_V01_F__first101pkts.tlm"
TIME = "year=*_HDR_YEAR,doy=*_HDR_DAY,hour=*_HDR_HOUR,minute=*_HDR_MIN,second=*_HDR_SEC,microsecond=*_HDR_USEC"
KEPT = {"384": 4, "386": 4, "391": 1, "392": 4, "394": 39, "1313": 9}  # the stream's APIDs but 393 (data README)


def _define(client: TestClient, token: str, name: str, layout_apid: int, apid: int) -> None:
    layout = (CYGNSS / "ccsdspy" / f"apid{layout_apid:05d}.csv").read_bytes()
    made = client.post(
        f"/api/v1/dictionaries/{name}",
        params={"apid": apid, "time_fields": TIME},
        content=layout,
        headers=bearer(token),
    )
    assert made.status_code == 201, made.json()


def _redecode(client: TestClient, token: str, dictionary: str) -> dict:
    answer = client.post(
        "/api/v1/telemetry/redecode",
        params={"satellite": "CYGNSS-FM07", "dictionary": dictionary},
        headers=bearer(token),
    )
    assert answer.status_code == 200, answer.json()
    return answer.json()


def _kept(client: TestClient, token: str) -> dict[str, int]:
    return client.get("/api/v1/telemetry/undefined?satellite=CYGNSS-FM07", headers=bearer(token)).json()


def test_kept_packets_decode_when_their_definition_arrives_as_ccsdspy_reads_them(
    client: TestClient, tokens: dict[str, str]
) -> None:
    operator, viewer = tokens["operator"], tokens["viewer"]
    _define(client, operator, "cygnss_adcsio.csv", 393, 393)
    stream = STREAM.read_bytes()
    url = "/api/v1/telemetry/uploads?satellite=CYGNSS-FM07&dictionary=cygnss_adcsio.csv"
    assert client.post(url, content=stream, headers=bearer(operator)).json()["archive"]["packets_accepted"] == 40
    assert _kept(client, viewer) == KEPT

    _define(client, operator, "cygnss_pvt.csv", 394, 394)
    report = _redecode(client, operator, "cygnss_pvt.csv")
    assert report["apids"] == [394] and report["archive"]["packets_accepted"] == 39
    assert report["decoding"]["apids"]["394"]["accepted"] == 39 and report["decoding"]["quarantined_count"] == 0
    theirs = ccsdspy.FixedLength.from_file(str(CYGNSS / "ccsdspy" / "apid00394.csv")).load(
        split_by_apid(io.BytesIO(stream))[394]
    )
    samples = client.get(
        "/api/v1/parameters/CDS_FSW_STAT_TIMEQ/samples?satellite=CYGNSS-FM07&max_points=1000", headers=bearer(viewer)
    ).json()
    assert samples["values"] == theirs["CDS_FSW_STAT_TIMEQ"].astype(float).tolist()
    assert _kept(client, viewer) == {a: n for a, n in KEPT.items() if a != "394"}

    assert _redecode(client, operator, "cygnss_pvt.csv")["archive"] is None  # nothing kept: a no-op
    again = client.post(url, content=stream, headers=bearer(operator)).json()["archive"]
    assert again["duplicate_upload"] is True and again["packets_accepted"] == 0
    assert _kept(client, viewer) == {a: n for a, n in KEPT.items() if a != "394"}


def test_packets_a_wrong_definition_quarantines_stay_kept_for_the_right_one(
    client: TestClient, tokens: dict[str, str]
) -> None:
    operator, viewer = tokens["operator"], tokens["viewer"]
    _define(client, operator, "cygnss_adcsio.csv", 393, 393)
    url = "/api/v1/telemetry/uploads?satellite=CYGNSS-FM07&dictionary=cygnss_adcsio.csv"
    client.post(url, content=STREAM.read_bytes(), headers=bearer(operator))
    _define(client, operator, "wrong_386.csv", 384, 386)  # a 260-octet layout for 104-octet packets
    wrong = _redecode(client, operator, "wrong_386.csv")
    assert wrong["archive"]["packets_accepted"] == 0
    assert wrong["decoding"]["quarantine_reasons"] == {"bad_length": 4}
    assert wrong["decoding"]["undefined_apids"] == {"386": 4}
    assert _kept(client, viewer) == KEPT
    _define(client, operator, "cygnss_hi.csv", 386, 386)
    right = _redecode(client, operator, "cygnss_hi.csv")
    assert right["archive"]["packets_accepted"] == 4 and right["decoding"]["undefined_apids"] == {}
    assert "386" not in _kept(client, viewer)


def test_redecode_refuses_an_apid_the_dictionary_does_not_define(client: TestClient, tokens: dict[str, str]) -> None:
    _define(client, tokens["operator"], "cygnss_adcsio.csv", 393, 393)
    url = "/api/v1/telemetry/uploads?satellite=CYGNSS-FM07&dictionary=cygnss_adcsio.csv"
    client.post(url, content=STREAM.read_bytes(), headers=bearer(tokens["operator"]))
    answer = client.post(
        "/api/v1/telemetry/redecode",
        params={"satellite": "CYGNSS-FM07", "dictionary": "cygnss_adcsio.csv", "apid": 394},
        headers=bearer(tokens["operator"]),
    )
    assert answer.status_code == 422 and answer.json()["field"] == "apid"
    assert _kept(client, tokens["viewer"]) == KEPT


def test_redecode_names_the_repeated_apid_past_the_11_bit_field(client: TestClient, tokens: dict[str, str]) -> None:
    """CCSDS 133.0-B-2 §4.1.3.3.4: the APID is 11 bits, 0..2047; the second of ?apid=393&apid=2048 is named."""
    answer = client.post(
        "/api/v1/telemetry/redecode",
        params={"satellite": "CYGNSS-FM07", "dictionary": "cygnss_adcsio.csv", "apid": [393, 2048]},
        headers=bearer(tokens["operator"]),
    )
    assert answer.status_code == 422 and answer.json()["field"] == "apid", answer.json()
    assert answer.json()["message"].startswith("apid: 2048 (value 2 of the repeated apid): "), answer.json()
    assert "2047" in answer.json()["message"]


def test_cli_redecode_archives_the_kept_packets_once(tmp_path: Path, capsys) -> None:
    db = f"sqlite:///{tmp_path / 'archive.sqlite'}"
    adcsio, pvt = str(CYGNSS / "ccsdspy" / "apid00393.csv"), str(CYGNSS / "ccsdspy" / "apid00394.csv")
    common = ["--db", db, "--satellite", "CYGNSS-FM07", "--time-fields", TIME, "--user", "test"]
    assert main(["ingest", str(STREAM), "--dictionary", adcsio, "--apid", "393", *common]) == 0
    capsys.readouterr()
    assert main(["ingest", "--redecode", "--dictionary", pvt, "--apid", "394", *common]) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["apids"] == [394] and first["archive"]["packets_accepted"] == 39
    assert main(["ingest", "--redecode", "--dictionary", pvt, "--apid", "394", *common]) == 0
    assert json.loads(capsys.readouterr().out)["archive"] is None
