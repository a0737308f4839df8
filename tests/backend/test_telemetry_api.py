"""Telemetry through the API with the real NOAA-20 diary: upload, samples, exports, dictionaries, alarms."""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from tests.backend.conftest import bearer, make_settings

NOAA20 = Path("real/noaa20_jpss1_apid11")
PACKETS = NOAA20 / "J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
FLOAT32_REL = 1e-7  # the diary's quaternion is float32 on board; the CSV prints it to float64
N_PACKETS = 7200  # two hours at 1 Hz (data README)


@pytest.fixture
def uploaded(client: TestClient, tokens: dict[str, str], shared_data: Path) -> dict:
    """The NOAA-20 packet file uploaded once by an operator; the ingest report."""
    answer = client.post(
        "/api/v1/telemetry/uploads?satellite=NOAA-20&source=DAT1",
        content=(shared_data / PACKETS).read_bytes(),
        headers=bearer(tokens["operator"]),
    )
    assert answer.status_code == 200, answer.json()
    return answer.json()


def _csv_q0(shared_data: Path) -> np.ndarray:
    with (shared_data / NOAA20 / "jpss1_apid11_decoded.csv").open() as f:
        return np.array([float(row["q4"]) for row in csv.DictReader(f)])


def test_uploaded_diary_samples_match_the_independently_decoded_csv(
    client: TestClient, tokens: dict[str, str], uploaded: dict, shared_data: Path
) -> None:
    assert uploaded["archive"]["packets_accepted"] == N_PACKETS
    assert uploaded["decoding"]["quarantined_count"] == 0
    body = client.get(
        f"/api/v1/parameters/q_ib_0/samples?max_points={N_PACKETS}", headers=bearer(tokens["viewer"])
    ).json()
    assert body["total_points"] == N_PACKETS
    assert np.allclose(body["values"], _csv_q0(shared_data), rtol=FLOAT32_REL, atol=0)
    assert np.all(np.diff(body["t_utc_ns"]) > 0)


def test_downsampled_samples_keep_the_extremes_and_respect_max_points(
    client: TestClient, tokens: dict[str, str], uploaded: dict, shared_data: Path
) -> None:
    body = client.get("/api/v1/parameters/q_ib_0/samples?max_points=100", headers=bearer(tokens["viewer"])).json()
    truth = _csv_q0(shared_data)
    assert len(body["values"]) <= 100
    assert max(body["values"]) == pytest.approx(truth.max(), rel=FLOAT32_REL)
    assert min(body["values"]) == pytest.approx(truth.min(), rel=FLOAT32_REL)
    window = client.get(
        "/api/v1/parameters/q_ib_0/samples?start=2021-04-09T00:00:00Z&end=2021-04-09T00:00:59.5Z",
        headers=bearer(tokens["viewer"]),
    ).json()
    assert window["total_points"] == 60


def test_repeated_upload_is_a_reported_no_op_and_uploads_are_audited(
    client: TestClient, tokens: dict[str, str], uploaded: dict, shared_data: Path
) -> None:
    again = client.post(
        "/api/v1/telemetry/uploads", content=(shared_data / PACKETS).read_bytes(), headers=bearer(tokens["operator"])
    ).json()
    assert again["archive"]["duplicate_upload"] is True and again["archive"]["packets_accepted"] == 0
    audit = client.get("/api/v1/audit?action=telemetry.upload", headers=bearer(tokens["admin"])).json()
    assert len(audit) == 2 and audit[-1]["detail"]["packets_accepted"] == N_PACKETS
    uploads = client.get("/api/v1/telemetry/uploads?satellite=NOAA-20", headers=bearer(tokens["viewer"])).json()
    assert [u["packets_accepted"] for u in uploads] == [N_PACKETS]  # the repeat stored nothing
    assert uploads[0]["uploaded_by"] == "test-operator" and uploads[0]["source"] == "DAT1"


def test_parquet_and_csv_exports_round_trip(
    client: TestClient, tokens: dict[str, str], uploaded: dict, shared_data: Path
) -> None:
    viewer = bearer(tokens["viewer"])
    parquet = client.get("/api/v1/exports/samples?names=q_ib_0,q_ib_1&format=parquet", headers=viewer)
    table = pq.read_table(io.BytesIO(parquet.content)).to_pydict()
    assert len(table["t_utc"]) == N_PACKETS
    assert np.allclose(table["q_ib_0"], _csv_q0(shared_data), rtol=FLOAT32_REL, atol=0)
    text = client.get("/api/v1/exports/samples?names=q_ib_0", headers=viewer).text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) == N_PACKETS and float(rows[0]["q_ib_0"]) == pytest.approx(table["q_ib_0"][0])
    assert re.fullmatch(r"2021-04-09T\d\d:\d\d:\d\d\.\d{9}Z", rows[0]["t_utc"])


def test_rest_export_and_acs_twin_export_give_the_same_full_resolution_rows(
    client: TestClient, tokens: dict[str, str], uploaded: dict, settings, tmp_path: Path, capsysbinary
) -> None:
    """Every one of the 7,200 samples (never downsampled), the same bytes through REST and the CLI, window given
    in ISO 8601 with Z and fractional seconds."""
    from backend.cli import main

    window = "start=2021-04-09T00:10:00.5Z&end=2021-04-09T01:10:00.5Z"
    rest = client.get(
        f"/api/v1/exports/samples?satellite=NOAA-20&names=q_ib_0,q_ib_3&{window}", headers=bearer(tokens["viewer"])
    ).content
    assert (
        main(
            [
                "export",
                "--db",
                str(settings.database_url),
                "--satellite",
                "NOAA-20",
                "--parameters",
                "q_ib_0,q_ib_3",
                "--start",
                "2021-04-09T00:10:00.5Z",
                "--end",
                "2021-04-09T01:10:00.5Z",
            ]
        )
        == 0
    )
    cli = capsysbinary.readouterr().out
    assert cli == rest
    rows = list(csv.DictReader(io.StringIO(rest.decode())))
    assert len(rows) == 3600 and list(rows[0]) == ["t_utc", "q_ib_0", "q_ib_3"]
    assert rows[0]["t_utc"] > "2021-04-09T00:10:00.5" and rows[-1]["t_utc"] < "2021-04-09T01:10:00.5"
    out = tmp_path / "all.parquet"
    assert (
        main(
            [
                "export",
                "--db",
                str(settings.database_url),
                "--satellite",
                "NOAA-20",
                "--parameters",
                "q_ib_0",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert pq.read_table(out).num_rows == N_PACKETS


def test_unknown_parameter_and_oversized_upload_name_the_field(tmp_path: Path, database_url: str) -> None:
    with TestClient(create_app(make_settings(tmp_path, database_url, max_upload_mb=0.001))) as client:
        operator = bearer(client.app.state.services.auth.issue("op", Role.operator)[1])
        too_big = client.post("/api/v1/telemetry/uploads", content=b"\0" * 2000, headers=operator)
        assert too_big.status_code == 413 and too_big.json()["field"] == "max_upload_mb"
        client.post("/api/v1/satellites", json={"name": "NOAA-20"}, headers=operator)
        unknown = client.get("/api/v1/parameters/nope/samples", headers=operator)
        assert unknown.status_code == 422 and unknown.json()["field"] == "name"


def test_a_streamed_upload_past_the_limit_is_413_and_leaves_no_spooled_file(tmp_path: Path, database_url: str) -> None:
    """Without a content-length the limit is found while spooling: the partial file is deleted."""
    with TestClient(create_app(make_settings(tmp_path, database_url, max_upload_mb=0.001))) as client:
        operator = bearer(client.app.state.services.auth.issue("op", Role.operator)[1])
        chunks = (b"\0" * 600 for _ in range(4))  # a generator: sent chunked, no content-length
        too_big = client.post("/api/v1/telemetry/uploads", content=chunks, headers=operator)
        assert too_big.status_code == 413 and too_big.json()["field"] == "max_upload_mb"
        assert list((tmp_path / "data" / "uploads").iterdir()) == []


LIMITED_DICTIONARY = """
name: NOAA-20 with a limit on the attitude scalar
packets:
  - name: JPSS_ATT_EPHEM
    apid: 11
    layout_from: {ccsdspy_csv: jpss1_geolocation_layout.csv}
    time_code: {format: CDS, day_octets: 2, submillisecond_octets: 2, epoch_utc: "1958-01-01T00:00:00Z"}
    derived:
      - {name: q0_watch, kind: alias, inputs: [ADCFAQ4], limits: {yellow_high: 0.9, red_high: 0.99}}
"""


def test_uploaded_dictionary_with_limits_raises_alarms_that_operators_acknowledge_and_shelve(
    client: TestClient, tokens: dict[str, str], shared_data: Path
) -> None:
    operator, viewer = bearer(tokens["operator"]), bearer(tokens["viewer"])
    layout = (shared_data / NOAA20 / "ccsdspy_jpss1_geolocation.csv").read_bytes()
    shipped = client.post(
        "/api/v1/dictionaries/ccsdspy_jpss1_geolocation.csv?apid=11", content=layout, headers=operator
    )
    assert shipped.status_code == 409 and shipped.json()["field"] == "name"  # shipped dictionaries are read-only
    assert (
        client.post(
            "/api/v1/dictionaries/jpss1_geolocation_layout.csv?apid=11", content=layout, headers=operator
        ).status_code
        == 201
    )
    made = client.post("/api/v1/dictionaries/limited.yaml", content=LIMITED_DICTIONARY.encode(), headers=operator)
    assert made.status_code == 201 and made.json()["packets"] == {"11": "JPSS_ATT_EPHEM"}
    assert "limited.yaml" in client.get("/api/v1/dictionaries", headers=viewer).json()
    report = client.post(
        "/api/v1/telemetry/uploads?satellite=NOAA-20L&dictionary=limited.yaml",
        content=(shared_data / PACKETS).read_bytes(),
        headers=operator,
    ).json()
    assert report["archive"]["alarm_events"] > 0
    alarms = client.get("/api/v1/alarms?satellite=NOAA-20L", headers=viewer).json()
    assert [a["parameter"] for a in alarms] == ["q0_watch"]
    alarm_id = alarms[0]["id"]
    assert client.post(f"/api/v1/alarms/{alarm_id}/shelve", json={"duration_s": 600}, headers=viewer).status_code == 403
    shelved = client.post(f"/api/v1/alarms/{alarm_id}/shelve", json={"duration_s": 600}, headers=operator)
    assert shelved.status_code == 200
    kinds = [e["kind"] for e in client.get(f"/api/v1/alarms/{alarm_id}/events", headers=viewer).json()]
    assert kinds[-1] == "shelve"
    actions = {e["action"] for e in client.get("/api/v1/audit", headers=bearer(tokens["admin"])).json()}
    assert {"dictionary.upload", "telemetry.upload", "alarm.shelve"} <= actions


def test_bad_dictionary_is_rejected_naming_the_body(client: TestClient, tokens: dict[str, str]) -> None:
    answer = client.post("/api/v1/dictionaries/broken.xml", content=b"<not xtce", headers=bearer(tokens["operator"]))
    assert answer.status_code == 422 and answer.json()["field"] == "body"
    assert "broken.xml" not in client.get("/api/v1/dictionaries", headers=bearer(tokens["viewer"])).json()


@pytest.mark.parametrize(
    ("name", "params", "body"),
    [("binary.yaml", {}, b"\x89PNG\r\n"), ("binary.csv", {"apid": 7}, b"\x89PNG\r\n"), ("plain.yaml", {}, b"a: 1\n")],
)
def test_unloadable_dictionary_names_the_body_not_the_server_file(
    client: TestClient, tokens: dict[str, str], name: str, params: dict[str, int], body: bytes
) -> None:
    """Not UTF-8 (was a 422 whose field was the decoder's message) or refused by a loader that names the file it
    read (was the server's path to it, as message and field)."""
    answer = client.post(
        f"/api/v1/dictionaries/{name}", params=params, content=body, headers=bearer(tokens["operator"])
    )
    assert answer.status_code == 422 and answer.json()["field"] == "body", answer.json()
    assert "dictionaries/" not in answer.json()["message"], answer.json()


@pytest.mark.parametrize(
    ("method", "url", "field"),
    [
        ("post", "/api/v1/telemetry/uploads?satellite=S&dictionary=../secret.yaml", "dictionary"),
        ("post", "/api/v1/dictionaries/ops.txt", "name"),
        ("post", "/api/v1/telemetry/redecode?satellite=S&dictionary=.hidden.csv&apid=7", "dictionary"),
    ],
)
def test_a_bad_dictionary_name_is_said_in_words_not_as_its_pattern(
    client: TestClient, tokens: dict[str, str], method: str, url: str, field: str
) -> None:
    """The name's rule is declared in the OpenAPI document as a pattern; the 422 says what it means."""
    answer = client.request(method.upper(), url, content=b"x", headers=bearer(tokens["operator"]))
    body = answer.json()
    assert answer.status_code == 422 and body["field"] == field, body
    assert body["message"] == (
        f"{field}: must be a plain file name (a letter or digit, then letters, digits, '_', '.', '-') ending in "
        ".yaml, .yml, .xml, .csv"
    ), body


VALLADO_TLE = (
    "1 00005U 58002B   00179.78495062  .00000023  00000-0  28098-4 0  4753\n"
    "2 00005  34.2682 348.7242 1859667 331.7664  19.3264 10.82419157413667\n"
)


def test_stations_tles_and_passes(client: TestClient, tokens: dict[str, str]) -> None:
    operator, viewer = bearer(tokens["operator"]), bearer(tokens["viewer"])
    station = {"name": "Svalbard", "lat_deg": 78.23, "lon_deg": 15.39, "alt_m": 500.0, "min_elevation_deg": 5.0}
    assert client.post("/api/v1/ground-stations", json=station, headers=operator).status_code == 201
    assert client.get("/api/v1/ground-stations/Svalbard", headers=viewer).json()["lat_deg"] == 78.23
    tle = client.post("/api/v1/satellites/VANGUARD/tles", content=VALLADO_TLE, headers=operator).json()
    # epoch 2000 day 179.78495062 (Vallado's SGP4-VER case 00005) = 2000-06-27T18:50:19.733568Z
    assert tle["epoch_utc_ns"] == pytest.approx(962131819733568000, abs=1e3)
    assert client.get("/api/v1/satellites/VANGUARD/tle", headers=viewer).json()["line1"] == VALLADO_TLE.splitlines()[0]
    assert client.get("/api/v1/passes?satellite=VANGUARD", headers=viewer).json() == []
    missing = client.get("/api/v1/passes/77?satellite=VANGUARD", headers=viewer)
    assert missing.status_code == 404 and missing.json()["field"] == "pass_id"
    bad = client.post("/api/v1/satellites/VANGUARD/tles", content="1 garbage", headers=operator)
    assert bad.status_code == 422 and bad.json()["field"] == "body"


CYGNSS = Path(__file__).parents[1] / "data" / "cygnss_f7"
CYGNSS_TIME = "year=*_HDR_YEAR,doy=*_HDR_DAY,hour=*_HDR_HOUR,minute=*_HDR_MIN,second=*_HDR_SEC,microsecond=*_HDR_USEC"


def test_foreign_mission_through_the_api_time_fields_and_undefined_apids(
    client: TestClient, tokens: dict[str, str]
) -> None:
    """A CYGNSS ccsdspy CSV uploaded with its APID and time fields; the mixed L0 stream uploaded against it:
    APID 393's 40 packets archived with the values ccsdspy reads, the 6 other APIDs counted and kept raw,
    the same upload again is a no-op reporting its duplicates per APID."""
    import ccsdspy
    from ccsdspy.utils import split_by_apid

    operator, viewer = bearer(tokens["operator"]), bearer(tokens["viewer"])
    layout = (CYGNSS / "ccsdspy" / "apid00393.csv").read_bytes()
    made = client.post(
        "/api/v1/dictionaries/cygnss_adcsio.csv",
        params={"apid": 393, "time_fields": CYGNSS_TIME},
        content=layout,
        headers=operator,
    )
    assert made.status_code == 201, made.json()
    stream = (CYGNSS / "CYGNSS_F7_L0_2022_086_10_15_V01_F__first101pkts.tlm").read_bytes()
    url = "/api/v1/telemetry/uploads?satellite=CYGNSS-FM07&dictionary=cygnss_adcsio.csv"
    report = client.post(url, content=stream, headers=operator).json()
    assert report["archive"]["packets_accepted"] == 40 and report["published"] is True
    assert report["decoding"]["undefined_apids"] == {"384": 4, "386": 4, "391": 1, "392": 4, "394": 39, "1313": 9}
    theirs = ccsdspy.FixedLength.from_file(str(CYGNSS / "ccsdspy" / "apid00393.csv")).load(
        split_by_apid(io.BytesIO(stream))[393]
    )
    samples = client.get("/api/v1/parameters/ADCS_NST_Q1/samples?satellite=CYGNSS-FM07", headers=viewer).json()
    assert samples["values"] == theirs["ADCS_NST_Q1"].astype(float).tolist()
    again = client.post(url, content=stream, headers=operator).json()["archive"]
    assert again["duplicate_upload"] is True and again["duplicates_by_apid"] == {"393": 40}
