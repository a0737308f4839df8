"""Large packet uploads decoded in the server's own decoder process: same report as a one-shot decode, a re-upload
a no-op, gone with the server, archive subscribers told to reload. Killed mid-file: tests/backend/
test_upload_decoder_deaths.py."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.core.processes import BULK_NICENESS
from backend.core.settings import Settings
from telemetry.decoding import decode_stream
from telemetry.packet_files import CHUNK_OCTETS
from tests.backend.conftest import bearer
from tests.backend.packet_uploads import (  # noqa: F401  (fixture: stream)
    N_GPS,
    archived_packets,
    mixed_stream,
    stream,
    upload,
)
from tests.telemetry.packet_streams import reference


def test_large_upload_is_decoded_in_another_process_with_the_one_shot_report(
    client: TestClient, tokens: dict[str, str], stream: bytes
) -> None:
    truth = decode_stream(stream, reference(), source="big").report
    out: dict = {}
    upload(client, tokens["operator"], stream, out)
    assert out["status"] == 200, out["body"]
    decoder = client.app.state.services.telemetry.upload_decoder
    assert decoder.pid is not None and decoder.pid != os.getpid()
    fork_server = int(Path(f"/proc/{decoder.pid}/stat").read_text().rsplit(")", 1)[1].split()[1])  # its parent
    assert fork_server != os.getpid()
    for pid in (decoder.pid, fork_server):  # the fork server's imports and warm-up too: bulk work
        niceness = os.getpriority(os.PRIO_PROCESS, pid) - os.getpriority(os.PRIO_PROCESS, 0)
        assert niceness == BULK_NICENESS  # below the server's requests, as the kernel schedules it
    decoding, archive = out["body"]["decoding"], out["body"]["archive"]
    assert decoding["packets_accepted"] == truth.packets_accepted == 5 * N_GPS
    assert decoding["samples_accepted"] == truth.samples_accepted
    assert {a: s["accepted"] for a, s in decoding["apids"].items()} == {"256": 4 * N_GPS, "257": N_GPS}
    assert decoding["quarantined_count"] == 0 and archive["packets_accepted"] == 5 * N_GPS
    assert archived_packets(client) == 5 * N_GPS
    again: dict = {}
    upload(client, tokens["operator"], stream, again)  # a re-upload: a reported no-op, per APID
    assert again["body"]["archive"]["duplicate_upload"] is True and again["body"]["archive"]["packets_accepted"] == 0
    assert again["body"]["archive"]["duplicates_by_apid"] == {"256": 4 * N_GPS, "257": N_GPS}
    assert archived_packets(client) == 5 * N_GPS


def test_decoder_stops_with_the_server(settings: Settings) -> None:
    with TestClient(create_app(settings)) as client:
        token = client.app.state.services.auth.issue("test-operator", Role.operator)[1]
        out: dict = {}
        upload(client, token, mixed_stream(N_GPS // 2), out)
        assert out["status"] == 200, out["body"]
        pid = client.app.state.services.telemetry.upload_decoder.pid
        assert pid is not None
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_one_chunk_upload_is_decoded_in_the_server(client: TestClient, tokens: dict[str, str]) -> None:
    out: dict = {}
    small = mixed_stream(100)
    assert len(small) <= CHUNK_OCTETS
    upload(client, tokens["operator"], small, out)
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
        upload(client, tokens["operator"], data, out)
        item = ws.receive_json()["items"][0]
    assert out["status"] == 200 and out["body"]["published"] is False
    assert item["topic"] == "archive"
    commit = item["data"]
    assert commit["satellite"] == "REFSAT" and commit["published"] is False
    assert commit["upload_id"] == out["body"]["archive"]["upload_id"]
    assert commit["packets_accepted"] == 5 * (N_GPS // 2)
    decoded = decode_stream(data, reference()).batches
    assert commit["t_last_utc_ns"] == max(int(b.t_utc_ns.max()) for b in decoded)
