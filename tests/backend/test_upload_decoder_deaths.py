"""The upload decoder killed mid-file (SIGKILL of the real process, once and twice): nothing lost or half-written,
the file decoded again by a fresh process or refused with nothing archived. The rest of the decoder's behaviour:
tests/backend/test_upload_decoder.py."""

from __future__ import annotations

import os
import signal
import threading
import time

from fastapi.testclient import TestClient

from tests.backend.conftest import bearer
from tests.backend.packet_uploads import N_GPS, archived_packets, stream, upload  # noqa: F401  (fixture: stream)

KILL_WAIT_S = 600.0  # the decoder's start (spawn + imports) on a loaded 2-core machine


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
    uploader = threading.Thread(target=upload, args=(client, token, data, out))
    uploader.start()
    deadline, killed = time.monotonic() + KILL_WAIT_S, []
    for _ in range(kills):
        killed.append(_kill_when_decoding(decoder, killed[-1] if killed else None, deadline))
    uploader.join()
    return out, killed


def test_decoder_killed_mid_file_loses_nothing_and_writes_nothing_twice(
    client: TestClient, tokens: dict[str, str], stream: bytes
) -> None:
    out, killed = _upload_killing_the_decoder(client, tokens["operator"], stream, kills=1)
    assert out["status"] == 200, out["body"]
    assert client.app.state.services.telemetry.upload_decoder.pid not in (None, *killed)  # a fresh one took it again
    assert out["body"]["archive"]["packets_accepted"] == 5 * N_GPS
    uploads = client.get("/api/v1/telemetry/uploads?satellite=REFSAT", headers=bearer(tokens["viewer"])).json()
    assert [u["packets_accepted"] for u in uploads] == [5 * N_GPS]
    assert archived_packets(client) == 5 * N_GPS


def test_decoder_dying_twice_refuses_the_upload_with_nothing_archived(
    client: TestClient, tokens: dict[str, str], stream: bytes
) -> None:
    out, _ = _upload_killing_the_decoder(client, tokens["operator"], stream, kills=2)
    assert out["status"] == 503 and out["body"]["field"] == "body", out["body"]
    assert "nothing of it was archived" in out["body"]["message"]
    listing = client.get("/api/v1/telemetry/uploads?satellite=REFSAT", headers=bearer(tokens["viewer"]))
    # no upload; the satellite itself is unknown when the decoder died before the archive registered it (it decodes
    # the file's first chunks while the file is hashed, before it opens the upload's transaction)
    assert listing.json() == [] if listing.status_code == 200 else "nothing archived" in listing.json()["message"]
    again: dict = {}
    upload(client, tokens["operator"], stream, again)  # sent again: archived whole
    assert again["status"] == 200 and again["body"]["archive"]["packets_accepted"] == 5 * N_GPS
