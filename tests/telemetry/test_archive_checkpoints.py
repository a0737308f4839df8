"""SQLite's WAL checkpoints run on the archive's thread after a commit, never inside it, and keep the WAL bounded.

telemetry.archive.engine.WalCheckpointer: a commit only appends to the WAL and fsyncs it (synchronous=FULL);
copying its pages into the database file is the thread's. Readers that always overlap must not let the WAL grow
without end (SQLite's checkpoint starvation). Crash safety with this scheme: tests/telemetry/test_crash_safety.py.
"""

from __future__ import annotations

import shutil
import sqlite3
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import text

from telemetry.archive import Archive, PacketBatch, engine, upgrade
from telemetry.archive.engine import WalCheckpointer

PACKETS = 1_000
PARAMETERS = 20
UPLOADS = 400  # ~46 WAL pages each: ~18,400 pages in a WAL that never restarts (SQLite's own checkpoint here)
WAL_LIMIT_PAGES = 200  # WAL_RESTART_FRAMES for the test
# the limit, then what commits while a RESTART waits for readers or times out: 1,000-2,500 pages measured at load 3-5,
# 3,859 once in the whole suite's run (the WAL file keeps the largest extent it reached): a third of what it reaches
# without the RESTART says "bounded", not a timing
WAL_BOUND_PAGES = UPLOADS * 46 // 3
T0_NS = 1_750_000_000 * 10**9


def upload(k: int) -> PacketBatch:
    """Upload number k: PACKETS distinct packets, PARAMETERS float columns."""
    i = np.arange(PACKETS, dtype=np.int64) + k * PACKETS
    values = {f"p{j:02d}": np.sin(i * (j + 1.0)) for j in range(PARAMETERS)}
    packets = [int(x).to_bytes(8, "big") * 2 for x in i]
    return PacketBatch.from_packets(300, T0_NS + i * 1_000_000, i % 16_384, packets, values)


def uploads_in_the_file_alone(db: Path, copy: Path) -> int:
    """Uploads found in a copy of the database file without its WAL: what checkpoints have copied into it."""
    shutil.copyfile(db, copy)
    with sqlite3.connect(copy) as conn:
        return int(conn.execute("SELECT count(*) FROM upload").fetchone()[0])


def test_a_commit_leaves_its_pages_in_the_wal_and_the_archive_thread_checkpoints_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    db = tmp_path / "archive.sqlite"
    upgrade(f"sqlite:///{db}")  # its own engine: the schema checkpointed when it closes
    with Archive(f"sqlite:///{db}", migrate=False) as archive:
        raw = archive._writer.raw_connection()
        assert raw.driver_connection.execute("PRAGMA wal_autocheckpoint").fetchone()[0] == 0
        assert raw.driver_connection.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL, unchanged
        raw.close()
        with monkeypatch.context() as patched:  # no thread: what the commit itself leaves behind
            patched.setattr(WalCheckpointer, "committed", lambda self: None)
            archive.ingest("SAT", [upload(0)], source="u0", uploaded_by="test")
            assert uploads_in_the_file_alone(db, tmp_path / "copy0.sqlite") == 0
            assert len(archive.uploads("SAT")) == 1  # committed: in the WAL
        archive.ingest("SAT", [upload(1)], source="u1", uploaded_by="test")
        archive.wait_for_checkpoint()
        assert uploads_in_the_file_alone(db, tmp_path / "copy1.sqlite") == 2


def test_the_wal_stays_bounded_while_readers_always_overlap(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(engine, "WAL_RESTART_FRAMES", WAL_LIMIT_PAGES)
    monkeypatch.setattr(engine, "CHECKPOINT_RETRY_S", 0.01)
    db = tmp_path / "archive.sqlite"
    stop = threading.Event()

    def read(archive: Archive, offset_s: float) -> None:
        """Read transactions of 20 ms, one starting every 20 ms: with two of them a snapshot is always open."""
        time.sleep(offset_s)
        while not stop.is_set():
            with archive.engine.connect() as conn:
                conn.execute(text("SELECT count(*) FROM upload")).scalar()
                time.sleep(0.02)

    with Archive(f"sqlite:///{db}") as archive:
        readers = [threading.Thread(target=read, args=(archive, s)) for s in (0.0, 0.01)]
        for r in readers:
            r.start()
        try:
            for k in range(UPLOADS):
                archive.ingest("SAT", [upload(k)], source=f"u{k}", uploaded_by="test")
        finally:
            stop.set()
            for r in readers:
                r.join()
        wal_pages = Path(f"{db}-wal").stat().st_size // (4096 + 24)  # frame: page + header
        assert len(archive.uploads("SAT")) == UPLOADS
    assert wal_pages <= WAL_BOUND_PAGES
