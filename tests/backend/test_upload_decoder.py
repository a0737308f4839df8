"""Large packet uploads decoded in the server's own decoder process: same report as a one-shot decode, nothing lost
or half-written when the process is killed mid-file, gone with the server."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.core.settings import Settings
from backend.ingest.upload_decoder import NICENESS
from telemetry.decoding import decode_stream
from telemetry.packet_files import CHUNK_OCTETS
from tests.backend.conftest import bearer
from tests.telemetry.packet_streams import packets, reference

HK_PER_GPS = 4  # ACS_HK at 4 Hz, GPS_NAV at 1 Hz
N_GPS = 16_000  # 16,000 × (4 × 126 + 62) octets ≈ 9 MB: four chunks and more
KILL_WAIT_S = 600.0  # the decoder's start (spawn + imports) on a loaded 2-core machine


def mixed_stream(n_gps: int) -> bytes:
    """ACS_HK and GPS_NAV packets of the reference satellite interleaved in time order (4 HK then 1 GPS)."""
    d = reference()
    hk = packets(d.packets[256], HK_PER_GPS * n_gps).reshape(n_gps, -1)
    gps = packets(d.packets[257], n_gps, seed=1)
    return np.hstack([hk, gps]).tobytes()


@pytest.fixture(scope="module")
def stream() -> bytes:
    data = mixed_stream(N_GPS)
    assert len(data) > 4 * CHUNK_OCTETS
    return data


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def _upload(client: TestClient, token: str, data: bytes, out: dict) -> None:
    answer = client.post(
        "/api/v1/telemetry/uploads?satellite=REFSAT&dictionary=reference_satellite.yaml&source=big",
        content=data,
        headers=bearer(token),
    )
    out["status"], out["body"] = answer.status_code, answer.json()


def _kill_when_decoding(decoder: object, after_pid: int | None, deadline: float) -> int:
    """SIGKILL the decoder (a process other than after_pid) once it has decoded its first chunk; its pid."""
    while time.monotonic() < deadline:
        pid = getattr(decoder, "pid", None)
        if pid is not None and pid != after_pid and getattr(decoder, "octets_decoded", 0) > 0:
            os.kill(pid, signal.SIGKILL)
            return pid
        time.sleep(0.005)
    raise AssertionError("the decoder never started decoding")


def _upload_killing_the_decoder(client: TestClient, token: str, data: bytes, kills: int) -> tuple[dict, list[int]]:
    """Upload ``data`` while the decoder is SIGKILLed ``kills`` times mid-file (each time a fresh process); the
    answer and the killed pids."""
    decoder = client.app.state.services.telemetry.upload_decoder
    out: dict = {}
    uploader = threading.Thread(target=_upload, args=(client, token, data, out))
    uploader.start()
    deadline, killed = time.monotonic() + KILL_WAIT_S, []
    for _ in range(kills):
        killed.append(_kill_when_decoding(decoder, killed[-1] if killed else None, deadline))
    uploader.join()
    return out, killed


def _archived_packets(client: TestClient) -> int:
    archive = client.app.state.services.telemetry.archive
    keys = archive.packet_keys("REFSAT", -(2**62), 2**62)
    return sum(len(t) for t, _ in keys.values())


def test_large_upload_is_decoded_in_another_process_with_the_one_shot_report(
    client: TestClient, tokens: dict[str, str], stream: bytes
) -> None:
    truth = decode_stream(stream, reference(), source="big").report
    out: dict = {}
    _upload(client, tokens["operator"], stream, out)
    assert out["status"] == 200, out["body"]
    decoder = client.app.state.services.telemetry.upload_decoder
    assert decoder.pid is not None and decoder.pid != os.getpid()
    niceness = os.getpriority(os.PRIO_PROCESS, decoder.pid) - os.getpriority(os.PRIO_PROCESS, 0)
    assert niceness == NICENESS  # bulk work below the server's requests, as the kernel schedules it
    decoding, archive = out["body"]["decoding"], out["body"]["archive"]
    assert decoding["packets_accepted"] == truth.packets_accepted == 5 * N_GPS
    assert decoding["samples_accepted"] == truth.samples_accepted
    assert {a: s["accepted"] for a, s in decoding["apids"].items()} == {"256": 4 * N_GPS, "257": N_GPS}
    assert decoding["quarantined_count"] == 0 and archive["packets_accepted"] == 5 * N_GPS
    assert _archived_packets(client) == 5 * N_GPS
    again: dict = {}
    _upload(client, tokens["operator"], stream, again)  # a re-upload: a reported no-op, per APID
    assert again["body"]["archive"]["duplicate_upload"] is True and again["body"]["archive"]["packets_accepted"] == 0
    assert again["body"]["archive"]["duplicates_by_apid"] == {"256": 4 * N_GPS, "257": N_GPS}
    assert _archived_packets(client) == 5 * N_GPS


def test_decoder_killed_mid_file_loses_nothing_and_writes_nothing_twice(
    client: TestClient, tokens: dict[str, str], stream: bytes
) -> None:
    out, killed = _upload_killing_the_decoder(client, tokens["operator"], stream, kills=1)
    assert out["status"] == 200, out["body"]
    assert client.app.state.services.telemetry.upload_decoder.pid not in (None, *killed)  # a fresh one took it again
    assert out["body"]["archive"]["packets_accepted"] == 5 * N_GPS
    uploads = client.get("/api/v1/telemetry/uploads?satellite=REFSAT", headers=bearer(tokens["viewer"])).json()
    assert [u["packets_accepted"] for u in uploads] == [5 * N_GPS]
    assert _archived_packets(client) == 5 * N_GPS


def test_decoder_dying_twice_refuses_the_upload_with_nothing_archived(
    client: TestClient, tokens: dict[str, str], stream: bytes
) -> None:
    out, _ = _upload_killing_the_decoder(client, tokens["operator"], stream, kills=2)
    assert out["status"] == 503 and out["body"]["field"] == "body", out["body"]
    assert "nothing of it was archived" in out["body"]["message"]
    assert client.get("/api/v1/telemetry/uploads?satellite=REFSAT", headers=bearer(tokens["viewer"])).json() == []
    again: dict = {}
    _upload(client, tokens["operator"], stream, again)  # sent again: archived whole
    assert again["status"] == 200 and again["body"]["archive"]["packets_accepted"] == 5 * N_GPS


def test_decoder_stops_with_the_server(settings: Settings) -> None:
    with TestClient(create_app(settings)) as client:
        token = client.app.state.services.auth.issue("test-operator", Role.operator)[1]
        out: dict = {}
        _upload(client, token, mixed_stream(N_GPS // 2), out)
        assert out["status"] == 200, out["body"]
        pid = client.app.state.services.telemetry.upload_decoder.pid
        assert pid is not None
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_one_chunk_upload_is_decoded_in_the_server(client: TestClient, tokens: dict[str, str]) -> None:
    out: dict = {}
    small = mixed_stream(100)
    assert len(small) <= CHUNK_OCTETS
    _upload(client, tokens["operator"], small, out)
    assert out["status"] == 200 and out["body"]["published"] is True
    assert client.app.state.services.telemetry.upload_decoder.pid is None


def test_large_upload_tells_archive_subscribers_to_reload(client: TestClient, tokens: dict[str, str]) -> None:
    """A file of several chunks is not replayed sample by sample: "archive" subscribers (the dashboard) hear of the
    commit with its span and reload plots and latest values from the archive."""
    data = mixed_stream(N_GPS // 2)
    with client.websocket_connect("/api/v1/ws", headers=bearer(tokens["viewer"])) as ws:
        ws.send_json({"op": "subscribe", "topics": ["archive"]})
        hub = client.app.state.services.hub
        deadline = time.monotonic() + 10.0
        while not hub.wants_any("archive"):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        out: dict = {}
        _upload(client, tokens["operator"], data, out)
        item = ws.receive_json()["items"][0]
    assert out["status"] == 200 and out["body"]["published"] is False
    assert item["topic"] == "archive"
    commit = item["data"]
    assert commit["satellite"] == "REFSAT" and commit["published"] is False
    assert commit["upload_id"] == out["body"]["archive"]["upload_id"]
    assert commit["packets_accepted"] == 5 * (N_GPS // 2)
    decoded = decode_stream(data, reference()).batches
    assert commit["t_last_utc_ns"] == max(int(b.t_utc_ns.max()) for b in decoded)
