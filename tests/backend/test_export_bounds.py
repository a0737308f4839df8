"""The REST export's bounds (issue 16 item 1): a window over max_export_rows is a 422 naming ``end`` before anything
is read; windows read rows × parameters near WINDOW_SAMPLES whatever the span; Parquet streamed as written equals the
file written at once."""

from __future__ import annotations

import io
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.auth import Role
from backend.core.settings import Settings
from telemetry import export
from telemetry.archive import Archive
from telemetry.decoding import decode_stream
from telemetry.encoding import encode_packets
from tests.backend.conftest import bearer, make_settings
from tests.telemetry.packet_streams import NOW_UTC_NS, T0_UTC_NS, engineering_values, reference

NOAA20_PACKETS = Path("real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1")
N_PACKETS = 7200  # the diary: 2 h at 1 Hz, one archive chunk


@pytest.fixture
def capped(tmp_path: Path, database_url: str) -> Iterator[TestClient]:
    """An app whose exports hold at most 1,000 rows."""
    with TestClient(create_app(make_settings(tmp_path, database_url, max_export_rows=1000))) as client:
        yield client


def test_export_over_max_export_rows_is_refused_naming_end_and_a_window_under_it_is_whole(
    capped: TestClient, shared_data: Path
) -> None:
    auth = capped.app.state.services.auth
    operator, viewer = (bearer(auth.issue(f"t-{r.name}", r)[1]) for r in (Role.operator, Role.viewer))
    data = (shared_data / NOAA20_PACKETS).read_bytes()
    assert capped.post("/api/v1/telemetry/uploads?satellite=NOAA-20", content=data, headers=operator).status_code == 200
    whole = capped.get("/api/v1/exports/samples?names=q_ib_0,q_ib_1", headers=viewer)
    assert whole.status_code == 422 and whole.json()["field"] == "end"
    assert "max_export_rows = 1,000" in whole.json()["message"] and "7,200" in whole.json()["message"]
    window = "start=2021-04-09T00:00:00Z&end=2021-04-09T00:09:59.9Z"  # 600 of the 1 Hz samples
    part = capped.get(f"/api/v1/exports/samples?names=q_ib_0&{window}&format=parquet", headers=viewer)
    assert part.status_code == 200 and pq.read_table(io.BytesIO(part.content)).num_rows == 600


def test_export_names_over_their_limit_are_refused_naming_names(client: TestClient, tokens: dict[str, str]) -> None:
    names = ",".join(f"p{i}" for i in range(201))
    answer = client.get(f"/api/v1/exports/samples?names={names}", headers=bearer(tokens["viewer"]))
    assert answer.status_code == 422 and answer.json()["field"] == "names"


@pytest.fixture
def three_chunks(tmp_path: Path) -> Iterator[Archive]:
    """The reference satellite's ACS_HK archived by three uploads of 4,000 packets following on in time (three
    archive chunks)."""
    d = reference()
    with Archive(f"sqlite:///{tmp_path / 'a.sqlite'}") as archive:
        hk = d.packets[256]
        for k in range(3):
            n = np.arange(4000 * k, 4000 * (k + 1))
            t = T0_UTC_NS + n * int(hk.period_s * 1e9)
            stream = encode_packets(hk, t, n % 16384, engineering_values(hk, 4000, seed=k)).tobytes()
            decoded = decode_stream(stream, d, now_utc_ns=NOW_UTC_NS)
            archive.ingest_decoded("REFSAT", decoded, uploaded_by="test", sha256=f"{k:064d}")
        yield archive


def test_windows_keep_rows_times_parameters_bounded_and_every_sample(
    three_chunks: Archive, monkeypatch: pytest.MonkeyPatch
) -> None:
    names = sorted(three_chunks.parameters("REFSAT"))[:6]
    schema, one = export.export_batches(three_chunks, "REFSAT", names, -(2**62), 2**62)
    whole = list(one)
    monkeypatch.setattr(export, "WINDOW_SAMPLES", 6 * 100)  # 100 rows a window: one archive chunk each
    _, cut = export.export_batches(three_chunks, "REFSAT", names, -(2**62), 2**62)
    parts = list(cut)
    assert len(whole) == 1 and len(parts) == 3
    assert max(b.num_rows for b in parts) == 4000  # a window holds one chunk, not the whole span
    for name in ["t_utc", *names]:
        joined = np.concatenate([b.column(name).to_numpy(zero_copy_only=False) for b in parts])
        assert np.array_equal(joined, whole[0].column(name).to_numpy(zero_copy_only=False))


def test_parquet_streamed_as_written_is_the_file_written_at_once(three_chunks: Archive, tmp_path: Path) -> None:
    names = sorted(three_chunks.parameters("REFSAT"))[:4]
    streamed = b"".join(export.parquet_chunks(*export.export_batches(three_chunks, "REFSAT", names, 0, 2**62)))
    path = tmp_path / "at_once.parquet"
    export.write_export(*export.export_batches(three_chunks, "REFSAT", names, 0, 2**62), path, "parquet")
    assert pq.read_table(io.BytesIO(streamed)).equals(pq.read_table(path))
    assert pq.read_table(path).num_rows == 3 * 4000


def test_rows_about_counts_the_part_of_each_chunk_inside_the_window() -> None:
    spans = np.array([[0, 999, 1000], [1000, 1999, 1000]], dtype=np.int64)
    assert export.rows_about(spans, 0, 1999) == 2000
    assert export.rows_about(spans, 500, 1499) == 1000
    assert export.rows_about(spans, 3000, 4000) == 0


def test_settings_refuse_a_non_positive_export_cap(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="max_export_rows"):
        Settings(data_dir=tmp_path, max_export_rows=0)
