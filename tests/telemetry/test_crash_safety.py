"""kill -9 of an ingesting process at random moments: nothing acknowledged is lost, nothing is half-ingested.

A forked child process commits uploads in a loop and writes ``ACK k`` to a pipe after each
commit returns; the test kills it with SIGKILL at a random moment (seed printed on failure),
forks a new one on the same database, and after all runs audits every upload: each
acknowledged upload is present and every stored upload holds exactly the packets and samples
its report claims, with the values it was given.  SQLite runs in WAL mode with synchronous=FULL (telemetry.archive.engine),
its WAL checkpointed on the archive's thread after each commit; a second test kills the child inside those
checkpoints.
"""

from __future__ import annotations

import os
import signal
import struct
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import text

from telemetry.archive import Archive, PacketBatch, upgrade
from telemetry.archive.engine import WalCheckpointer
from tests.telemetry.archive_databases import archive_url  # noqa: F401  (fixture)

PACKETS_PER_UPLOAD = 4_000
PARAMETERS = 25
T0_NS = 1_750_000_000 * 10**9
PERIOD_NS = 1_000_000
KILL_WINDOW_S = 0.6  # uploads take ~50-100 ms here, so kills land inside transactions most of the time
RUNS = {"sqlite": 20, "postgresql": 8}
CHECKPOINT_KILLS = 12  # kills within the first half of a checkpoint's duration: most land inside one
CHECKPOINT_PAYLOAD = 1_000  # random bytes after each packet there: a checkpoint copies ~1,000 WAL frames (~8 ms)
SATELLITE = "CRASH"


def upload_batch(k: int, payload: int = 0) -> PacketBatch:
    """Deterministic upload number k: distinct times and bytes, PARAMETERS columns; each packet followed by
    ``payload`` random bytes (more WAL frames to checkpoint, little more work to ingest)."""
    i = np.arange(PACKETS_PER_UPLOAD, dtype=np.int64) + k * PACKETS_PER_UPLOAD
    noise = np.random.default_rng(k).bytes(payload * PACKETS_PER_UPLOAD)
    packets = [
        int(x).to_bytes(8, "big") + b"\xa5" * 8 + noise[j * payload : (j + 1) * payload] for j, x in enumerate(i)
    ]
    values = {f"p{j:02d}": (i * (j + 1)).astype(np.float64) for j in range(PARAMETERS)}
    return PacketBatch.from_packets(300, T0_NS + i * PERIOD_NS, i % 16_384, packets, values)


def ingest_forever(url: str, first: int, ack_fd: int) -> None:
    """Child process body: commit uploads first, first+1, ... and acknowledge each on the pipe."""
    store = Archive(url, migrate=False)  # a fresh engine: nothing shared with the parent
    k = first
    while True:
        store.ingest(SATELLITE, [upload_batch(k)], source=f"upload-{k}", uploaded_by="crash-test")
        os.write(ack_fd, f"ACK {k}\n".encode())
        k += 1


def forked(body: Callable[[str, int, int], None], url: str, first: int) -> tuple[int, int]:
    """A child running ``body(url, first, write end of a pipe)`` until it is killed (forked: the runs do not pay an
    interpreter start-up each); its pid and the pipe's read end."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read_fd)
        try:
            body(url, first, write_fd)
        finally:
            os._exit(1)
    os.close(write_fd)
    return pid, read_fd


def run_and_kill(url: str, first: int, delay_s: float) -> list[int]:
    """Fork a child at upload ``first``, SIGKILL it ``delay_s`` after its first ACK; acknowledged k."""
    pid, read_fd = forked(ingest_forever, url, first)
    with os.fdopen(read_fd) as acks:
        acked = [int(acks.readline().split()[1])]
        time.sleep(delay_s)
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        acked += [int(line.split()[1]) for line in acks.read().splitlines() if line.startswith("ACK")]
    return acked


@pytest.mark.slow
def test_kill_9_during_bulk_ingest_loses_nothing_acknowledged(archive_url: str) -> None:
    upgrade(archive_url)
    seed = int.from_bytes(os.urandom(4), "little")
    rng = np.random.default_rng(seed)
    backend = "postgresql" if archive_url.startswith("postgresql") else "sqlite"
    acknowledged: list[int] = []
    next_k = 0
    for _ in range(RUNS[backend]):
        acked = run_and_kill(archive_url, next_k, float(rng.uniform(0.0, KILL_WINDOW_S)))
        acknowledged += acked
        next_k = acked[-1] + 2  # the upload after the last ACK may or may not have committed
    audit(archive_url, acknowledged, seed)


def checkpoint_forever(url: str, first: int, ack_fd: int) -> None:
    """Child process body: commit upload k, acknowledge it, then run the WAL checkpoint after it (the archive's
    thread), saying on the pipe when each checkpoint starts and how long the finished one took."""
    store = Archive(url, migrate=False)
    checkpoint = WalCheckpointer.checkpoint

    def announced(self: WalCheckpointer) -> tuple[int, int, int]:
        os.write(ack_fd, b"CKPT\n")
        t0 = time.perf_counter()
        done = checkpoint(self)
        os.write(ack_fd, f"DONE {time.perf_counter() - t0}\n".encode())
        return done

    WalCheckpointer.checkpoint = announced  # type: ignore[method-assign]  # in this forked child only
    k = first
    while True:
        batch = upload_batch(k, CHECKPOINT_PAYLOAD)
        store.ingest(SATELLITE, [batch], source=f"upload-{k}", uploaded_by="crash-test")
        os.write(ack_fd, f"ACK {k}\n".encode())
        store.wait_for_checkpoint()
        k += 1


def backfill_interrupted(database: Path) -> bool:
    """Whether SQLite's WAL-index says a checkpoint was copying frames when the process died: nBackfillAttempted
    (set before the copy) exceeds nBackfill (set once the copied frames are synced). Both are in the WalCkptInfo
    after the two 48-byte headers of the -shm file, native byte order (sqlite.org/walformat.html, 2.2)."""
    shm = Path(f"{database}-shm").read_bytes()
    backfilled, attempted = struct.unpack_from("=I", shm, 96)[0], struct.unpack_from("=I", shm, 128)[0]
    return bool(attempted > backfilled)


def kill_in_checkpoint(database: Path, first: int, fraction: float) -> tuple[list[int], bool]:
    """Fork a child at upload ``first``; once the checkpoint of an upload has taken d seconds, SIGKILL it
    ``fraction`` x d after the next checkpoint starts. The acknowledged k, and whether the kill interrupted that
    checkpoint's copy."""
    pid, read_fd = forked(checkpoint_forever, f"sqlite:///{database}", first)
    acked, took = [], None
    with os.fdopen(read_fd) as lines:
        for line in lines:
            word, _, value = line.strip().partition(" ")
            if word == "ACK":
                acked.append(int(value))
            elif word == "DONE" and acked:  # not the checkpoint on opening, which finishes the previous child's
                took = float(value)
            elif word == "CKPT" and took is not None:
                time.sleep(fraction * took)
                os.kill(pid, signal.SIGKILL)
                break
        os.waitpid(pid, 0)
        rest = lines.read().split()
    acked += [int(v) for w, v in zip(rest, rest[1:], strict=False) if w == "ACK"]
    return acked, backfill_interrupted(database)


@pytest.mark.slow
def test_kill_9_during_a_wal_checkpoint_loses_nothing_committed(tmp_path) -> None:
    database = tmp_path / "archive.sqlite"
    upgrade(f"sqlite:///{database}")
    seed = int.from_bytes(os.urandom(4), "little")
    rng = np.random.default_rng(seed)
    acknowledged: list[int] = []
    kills = inside = next_k = 0
    # a kill is late when this process wakes after the checkpoint ended (a loaded machine): kill until enough landed
    while kills < CHECKPOINT_KILLS or inside < CHECKPOINT_KILLS // 2 and kills < 4 * CHECKPOINT_KILLS:
        acked, during = kill_in_checkpoint(database, next_k, float(rng.uniform(0.0, 0.5)))
        acknowledged += acked
        inside += during
        kills += 1
        next_k = acked[-1] + 2  # the upload after the last ACK may or may not have committed
    assert inside >= CHECKPOINT_KILLS // 2, f"only {inside} of {kills} kills interrupted a checkpoint (seed {seed})"
    audit(f"sqlite:///{database}", acknowledged, seed)


def audit(url: str, acknowledged: list[int], seed: int) -> None:
    """Every acknowledged upload is stored; every stored upload holds exactly what it reports and was given."""
    with Archive(url, migrate=False) as store:
        uploads = {u.source: u for u in store.uploads(SATELLITE)}
        missing = [k for k in acknowledged if f"upload-{k}" not in uploads]
        assert not missing, f"acknowledged uploads lost (seed {seed}): {missing}"
        for source, upload in uploads.items():
            contents = store.upload_contents(upload.id)
            assert (
                contents
                == (PACKETS_PER_UPLOAD, PACKETS_PER_UPLOAD * PARAMETERS)
                == (upload.packets_accepted, upload.samples_accepted)
            ), f"half-ingested {source} (seed {seed})"
        t, v = store.read_parameter(SATELLITE, "p07", T0_NS, T0_NS + 10**15)
        assert t.size == len(uploads) * PACKETS_PER_UPLOAD
        np.testing.assert_array_equal(v, (t - T0_NS) // PERIOD_NS * 8.0)
        if url.startswith("sqlite"):
            with store.engine.connect() as conn:
                assert conn.execute(text("PRAGMA integrity_check")).scalar() == "ok"
