"""Passes from data: real NOAA-20 packets uploaded with and without predicted passes become passes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

from tests.backend.conftest import bearer
from tests.backend.test_passes_api import DAY, DIARY, STATION, _noaa20_tle

N_PACKETS = 7200  # two hours at 1 Hz, no sequence gaps (data README)
PACKET_OCTETS = 71  # APID 11 packets are fixed length


def _diary_times(client: TestClient) -> np.ndarray:
    t, _ = client.app.state.services.telemetry.archive.packet_keys("NOAA-20", 0, 2**62)[11]
    return t


def _upload(client: TestClient, token: str, data: bytes) -> dict:
    answer = client.post(
        "/api/v1/telemetry/uploads?satellite=NOAA-20&dictionary=noaa20_apid11_xtce.yaml",
        content=data,
        headers=bearer(token),
    )
    assert answer.status_code == 200, answer.json()
    return answer.json()


def test_upload_no_predicted_pass_covers_becomes_one_complete_pass_from_data(
    client: TestClient, tokens: dict[str, str], shared_data: Path
) -> None:
    report = _upload(client, tokens["operator"], (shared_data / DIARY).read_bytes())
    t = _diary_times(client)
    [made] = report["passes"]
    assert made["origin"] == "data" and made["station"] is None and made["max_elevation_deg"] is None
    assert (made["aos_ns"], made["los_ns"]) == (int(t[0]), int(t[-1]))  # first and last sample
    assert made["packets_received"] == N_PACKETS and made["completeness"] == 1.0
    listed = client.get(
        f"/api/v1/passes?satellite=NOAA-20&start={DAY[0]}&end={DAY[1]}", headers=bearer(tokens["viewer"])
    ).json()
    assert [p["id"] for p in listed] == [made["id"]]  # the pass list is not empty once data arrived


def test_data_continuing_a_pass_from_data_widens_it(
    client: TestClient, tokens: dict[str, str], shared_data: Path
) -> None:
    data, half = (shared_data / DIARY).read_bytes(), N_PACKETS // 2 * PACKET_OCTETS
    first = _upload(client, tokens["operator"], data[:half])["passes"]
    second = _upload(client, tokens["operator"], data[half:])["passes"]
    assert [p["id"] for p in second] == [p["id"] for p in first]
    t = _diary_times(client)
    assert (second[0]["aos_ns"], second[0]["los_ns"], second[0]["packets_received"]) == (
        int(t[0]),
        int(t[-1]),
        N_PACKETS,
    )


def test_upload_attaches_to_predicted_passes_and_only_the_rest_becomes_passes_from_data(
    client: TestClient, tokens: dict[str, str], shared_data: Path
) -> None:
    operator = bearer(tokens["operator"])
    line1, line2 = _noaa20_tle(shared_data)
    client.post("/api/v1/ground-stations", json=STATION, headers=operator)
    client.post("/api/v1/satellites/NOAA-20/tles", content=f"{line1}\n{line2}\n", headers=operator)
    client.post(
        f"/api/v1/satellites/NOAA-20/passes/predict?station=Fairbanks&start={DAY[0]}&end={DAY[1]}", headers=operator
    )
    passes = _upload(client, tokens["operator"], (shared_data / DIARY).read_bytes())["passes"]
    origins = {p["origin"] for p in passes}
    assert origins == {"predicted", "data"}
    assert sum(p["packets_received"] for p in passes) == N_PACKETS  # every packet in exactly one pass
    for p in passes:
        if p["origin"] == "predicted":
            assert p["station"] == "Fairbanks" and p["packets_received"] > 0
