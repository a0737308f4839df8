"""Large packet uploads for the upload decoder tests (tests/backend/test_upload_decoder*.py): a mixed stream of the
reference satellite (tests.telemetry.packet_streams.mixed_stream) several decode chunks long, the upload as the API
answers it."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from telemetry.packet_files import CHUNK_OCTETS
from tests.backend.conftest import bearer
from tests.telemetry.packet_streams import HK_PER_GPS, mixed_stream

__all__ = ["HK_PER_GPS", "N_GPS", "archived_packets", "mixed_stream", "stream", "upload"]

N_GPS = 16_000  # 16,000 × (4 × 126 + 62) octets ≈ 9 MB: four chunks and more


@pytest.fixture(scope="module")
def stream() -> bytes:
    """N_GPS seconds of the mixed stream, more than four decode chunks."""
    data = mixed_stream(N_GPS)
    assert len(data) > 4 * CHUNK_OCTETS
    return data


def upload(client: TestClient, token: str, data: bytes, out: dict) -> None:
    """POST ``data`` as a REFSAT packet file; its status and body into ``out`` (also from a thread)."""
    answer = client.post(
        "/api/v1/telemetry/uploads?satellite=REFSAT&dictionary=reference_satellite.yaml&source=big",
        content=data,
        headers=bearer(token),
    )
    out["status"], out["body"] = answer.status_code, answer.json()


def archived_packets(client: TestClient) -> int:
    """Packets of REFSAT in the app's archive."""
    archive = client.app.state.services.telemetry.archive
    keys = archive.packet_keys("REFSAT", -(2**62), 2**62)
    return sum(len(t) for t, _ in keys.values())
