"""Pass prediction, reception and summaries through the API, against skyfield and the real diary."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient
from skyfield.api import EarthSatellite, load, wgs84

from tests.backend.conftest import bearer

TLE_FILE = "tle/real_sso_smallsats.tle"
DIARY = "real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
STATION = {"name": "Fairbanks", "lat_deg": 64.86, "lon_deg": -147.85, "alt_m": 200.0, "min_elevation_deg": 5.0}
EVENT_TOLERANCE_S = 5.0  # skyfield's frames (full IAU 2000A, polar motion off) vs ours; ~1 s seen
DAY = ("2021-04-09T00:00:00Z", "2021-04-10T00:00:00Z")


def _noaa20_tle(shared_data: Path) -> tuple[str, str]:
    lines = (shared_data / TLE_FILE).read_text().splitlines()
    at = lines.index("NOAA 20 (JPSS-1)")  # the March 2021 element set, closest to the diary
    return lines[at + 1], lines[at + 2]


def _skyfield_passes(line1: str, line2: str) -> tuple[np.ndarray, np.ndarray]:
    ts = load.timescale(builtin=True)
    satellite = EarthSatellite(line1, line2, ts=ts)
    site = wgs84.latlon(STATION["lat_deg"], STATION["lon_deg"], STATION["alt_m"])
    t, kinds = satellite.find_events(site, ts.utc(2021, 4, 9), ts.utc(2021, 4, 10), STATION["min_elevation_deg"])
    unix = np.array([moment.timestamp() for moment in t.utc_datetime()])
    return unix[kinds == 0], unix[kinds == 2]


def test_predicted_passes_match_skyfield_and_reception_uses_the_diary(
    client: TestClient, tokens: dict[str, str], shared_data: Path
) -> None:
    operator, viewer = bearer(tokens["operator"]), bearer(tokens["viewer"])
    line1, line2 = _noaa20_tle(shared_data)
    assert client.post("/api/v1/ground-stations", json=STATION, headers=operator).status_code == 201
    tle = client.post("/api/v1/satellites/NOAA-20/tles", content=f"{line1}\n{line2}\n", headers=operator)
    assert tle.status_code == 201
    audit = client.get("/api/v1/audit?action=tle.upload", headers=bearer(tokens["admin"])).json()
    assert [(e["target"], e["detail"]["tle_id"]) for e in audit] == [("satellite/NOAA-20", tle.json()["id"])]
    predicted = client.post(
        f"/api/v1/satellites/NOAA-20/passes/predict?station=Fairbanks&start={DAY[0]}&end={DAY[1]}", headers=operator
    )
    assert predicted.status_code == 200, predicted.json()
    aos_truth, los_truth = _skyfield_passes(line1, line2)
    complete = min(len(aos_truth), len(los_truth))
    aos = np.array([p["aos_ns"] for p in predicted.json()]) / 1e9
    los = np.array([p["los_ns"] for p in predicted.json()]) / 1e9
    assert len(aos) >= complete - 1 and len(aos) > 3
    nearest = np.abs(aos[:, None] - aos_truth[None, :]).min(axis=1)
    assert np.all(nearest < EVENT_TOLERANCE_S)
    assert np.all(np.abs(los[:, None] - los_truth[None, :]).min(axis=1) < EVENT_TOLERANCE_S)

    client.post("/api/v1/telemetry/uploads", content=(shared_data / DIARY).read_bytes(), headers=operator)
    recounted = client.post(
        f"/api/v1/satellites/NOAA-20/passes/reception?start={DAY[0]}&end={DAY[1]}", headers=operator
    ).json()
    received = [p for p in recounted if p["packets_received"] > 0]
    assert received, "the two-hour diary overlaps at least one Fairbanks pass"
    first = received[0]
    assert first["completeness"] == 1.0  # the diary has no sequence gaps
    assert first["packets_received"] <= (first["los_ns"] - first["aos_ns"]) / 1e9 + 1  # 1 Hz packets
    one = client.get(f"/api/v1/passes/{first['id']}?satellite=NOAA-20", headers=viewer).json()
    assert one["packets_received"] == first["packets_received"]
    summary = client.get(f"/api/v1/passes/{first['id']}/summary?satellite=NOAA-20", headers=viewer).json()
    assert summary["parameters"]["q_ib_0"]["count"] == first["packets_received"]


GROUND_CSV = "t_utc,ADCFAQ4\n2021-04-09T00:00:00Z,0.5\n2021-04-09T00:00:01Z,0.25\nnot-a-time,1\n"


def test_ground_csv_upload_is_archived_and_bad_rows_quarantined(client: TestClient, tokens: dict[str, str]) -> None:
    operator = bearer(tokens["operator"])
    report = client.post(
        "/api/v1/telemetry/uploads?format=csv&satellite=GROUND", content=GROUND_CSV, headers=operator
    ).json()
    assert report["archive"]["packets_accepted"] == 2
    assert report["decoding"]["quarantine_reasons"] == {"bad_row": 1}
    samples = client.get("/api/v1/parameters/ADCFAQ4/samples?satellite=GROUND", headers=operator).json()
    assert samples["values"] == [0.5, 0.25]
