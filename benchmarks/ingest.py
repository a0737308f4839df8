"""Telemetry ingest benchmarks (issue 5); prints the figures.

    .venv/bin/python benchmarks/ingest.py [--scales 1,10,100] [--live-seconds 60] [--skip-live]

* bulk: a mixed-APID stream of the reference satellite (1x = 30 min: ACS_HK at 4 Hz, 48 values,
  and GPS_NAV at 1 Hz) is framed, validated and decoded (telemetry.decoding, the packets
  engineer's part), then limit-checked and committed to a fresh SQLite archive in one upload
  (telemetry.archive, the archive engineer's part); each phase is timed and the scaling over
  1x, 10x, 100x reported.  Target: >= 2,000,000 samples/s committed.
* query: one parameter over a 2-hour pass at 4 Hz downsampled to 1,000 points.  Target < 20 ms.
* live: a separate process sends 2,000 packets/s of 50 float parameters over TCP for N seconds,
  stamping each packet's CUC time with the wall clock when it is encoded; a subscriber measures
  packet-to-subscriber latency (wall clock at delivery minus packet time).  Target p99 < 100 ms,
  nothing dropped for a keeping-up subscriber.
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import os
import socket
import tempfile
import time
from pathlib import Path

import numpy as np

from telemetry.archive import Archive
from telemetry.decoding import decode_stream
from telemetry.dictionary import Dictionary, PacketDefinition, Parameter, load_dictionary
from telemetry.encoding import encode_packets
from telemetry.limits import dictionary_limits
from telemetry.live import LiveStream
from telemetry.queries import downsample

BASE_SECONDS = 1_800  # 1x: a 30-minute dump
LIVE_RATE_HZ = 2_000
LIVE_BURST = 20  # packets per 10 ms burst
LIVE_PARAMETERS = 50
QUERY_REPEATS = 50


def reference_dictionary() -> Dictionary:
    """The shipped reference-satellite dictionary."""
    return load_dictionary("reference_satellite.yaml")


def plausible_values(packet: PacketDefinition, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Float fields: small noise (inside limits); integer fields: zero."""
    return {p.name: (rng.normal(0.0, 0.01, n) if p.data_type == "float" else np.zeros(n)) for p in packet.parameters}


def reference_stream(dictionary: Dictionary, seconds: int, t0_ns: int, rng: np.random.Generator) -> bytes:
    """Time-interleaved packets of every APID of the dictionary over ``seconds``."""
    parts, times = [], []
    for packet in dictionary.packets.values():
        period_ns = int(round((packet.period_s or 1.0) * 1e9))
        n = int(seconds * 1e9 // period_ns)
        t = t0_ns + np.arange(n, dtype=np.int64) * period_ns
        parts.append(encode_packets(packet, t, np.arange(n) % 16_384, plausible_values(packet, n, rng)))
        times.append(t)
    order = np.argsort(np.concatenate(times), kind="stable")
    rows = [row for part in parts for row in part]
    return b"".join(rows[i].tobytes() for i in order)


def bench_bulk(scales: list[int], workdir: Path) -> None:
    """Decode + validate, then limit-check + commit, per scale."""
    dictionary = reference_dictionary()
    limits = dictionary_limits(dictionary)
    rng = np.random.default_rng(0)
    decode_stream(reference_stream(dictionary, 10, 1_750_000_000 * 10**9, rng), dictionary)  # compile kernels
    print("bulk ingest (SQLite, WAL, synchronous=FULL), one upload per file, after a 10-s warm-up upload:")
    print(
        f"{'scale':>6} {'packets':>9} {'samples':>11} {'decode s':>9} {'commit s':>9} "
        f"{'commit Msamp/s':>15} {'end-to-end Msamp/s':>19} {'db MB':>7}"
    )
    for scale in scales:
        data = reference_stream(dictionary, BASE_SECONDS * scale, 1_750_000_000 * 10**9, rng)
        path = workdir / f"bulk_{scale}.sqlite"
        with Archive(f"sqlite:///{path}") as archive:
            warm_up = reference_stream(dictionary, 10, 1_700_000_000 * 10**9, rng)  # a server is long-running:
            archive.ingest_decoded("REF", decode_stream(warm_up, dictionary), uploaded_by="bench")  # warm caches
            t0 = time.perf_counter()
            decoded = decode_stream(data, dictionary, source=f"bench-{scale}x")
            t1 = time.perf_counter()
            result = archive.ingest_decoded("REF", decoded, uploaded_by="bench", limits=limits)
            t2 = time.perf_counter()
        samples = result.samples_accepted
        size_mb = sum(p.stat().st_size for p in workdir.glob(f"bulk_{scale}.sqlite*")) / 1e6
        print(
            f"{scale:>5}x {result.packets_accepted:>9,} {samples:>11,} {t1 - t0:>9.3f} {t2 - t1:>9.3f} "
            f"{samples / (t2 - t1) / 1e6:>15.2f} {samples / (t2 - t0) / 1e6:>19.2f} {size_mb:>7.1f}"
        )


def bench_chunk_sizes(workdir: Path) -> None:
    """Commit and query time of a 2-hour, 4 Hz ACS_HK dump for a few packets-per-chunk settings."""
    from telemetry.archive import store

    dictionary = reference_dictionary()
    hk = dictionary.packets[256]
    n = 2 * 3_600 * 4
    t = 1_750_000_000 * 10**9 + np.arange(n, dtype=np.int64) * 250_000_000
    values = plausible_values(hk, n, np.random.default_rng(4))
    decoded = decode_stream(encode_packets(hk, t, np.arange(n) % 16_384, values).tobytes(), dictionary)
    chosen = store.CHUNK_PACKETS
    with Archive(f"sqlite:///{workdir / 'chunks_warm_up.sqlite'}") as archive:
        archive.ingest_decoded("REF", decoded, uploaded_by="bench")  # first-use costs out of the sweep
    cells = []
    for size in (1_024, 8_192, 16_384, 65_536):
        store.CHUNK_PACKETS = size
        with Archive(f"sqlite:///{workdir / f'chunks_{size}.sqlite'}") as archive:
            start = time.perf_counter()
            result = archive.ingest_decoded("REF", decoded, uploaded_by="bench")
            commit_s = time.perf_counter() - start
            start = time.perf_counter()
            for _ in range(QUERY_REPEATS):
                downsample(archive, "REF", "omega_est_b_rad_s_x", int(t[0]), int(t[0]) + 600 * 10**9, 1_000)
            query_ms = (time.perf_counter() - start) / QUERY_REPEATS * 1e3
        cells.append(
            f"{size:,}: commit {result.samples_accepted / commit_s / 1e6:.1f} M samples/s, "
            f"10-min query {query_ms:.2f} ms"
        )
    store.CHUNK_PACKETS = chosen
    print(f"packets per chunk (archive uses {chosen:,}): " + "; ".join(cells))


def bench_row_layout(workdir: Path) -> None:
    """The layout we did not choose: one SQLite row per sample (parameter, time, value)."""
    import sqlite3

    n_packets, n_params = 28_800, 48
    t = 1_750_000_000 * 10**9 + np.arange(n_packets, dtype=np.int64) * 250_000_000
    values = np.random.default_rng(3).normal(size=(n_params, n_packets))
    db = sqlite3.connect(workdir / "rows.sqlite", isolation_level=None)
    db.execute("PRAGMA journal_mode=WAL")
    db.execute("PRAGMA synchronous=FULL")
    db.execute(
        "CREATE TABLE sample (parameter INTEGER, t_ns INTEGER, value REAL, PRIMARY KEY (parameter, t_ns)) WITHOUT ROWID"
    )
    start = time.perf_counter()
    db.execute("BEGIN IMMEDIATE")
    for k in range(n_params):
        db.executemany("INSERT INTO sample VALUES (?, ?, ?)", zip([k] * n_packets, t.tolist(), values[k].tolist()))
    db.execute("COMMIT")
    insert_s = time.perf_counter() - start
    start = time.perf_counter()
    rows = db.execute(
        "SELECT t_ns, value FROM sample WHERE parameter = 3 AND t_ns BETWEEN ? AND ?", (int(t[0]), int(t[-1]))
    ).fetchall()
    np.array(rows)
    query_s = time.perf_counter() - start
    db.close()
    print(
        f"row-per-sample layout (not used): insert {n_packets * n_params / insert_s / 1e6:.2f} M samples/s, "
        f"reading one 2-h parameter {query_s * 1e3:.1f} ms"
    )


def bench_query(workdir: Path) -> None:
    """Downsample a 2-hour, 4 Hz parameter to 1,000 points."""
    dictionary = reference_dictionary()
    hk = dictionary.packets[256]
    n = 2 * 3_600 * 4
    t0_ns = 1_750_000_000 * 10**9
    t = t0_ns + np.arange(n, dtype=np.int64) * 250_000_000
    rng = np.random.default_rng(1)
    decoded = decode_stream(
        encode_packets(hk, t, np.arange(n) % 16_384, plausible_values(hk, n, rng)).tobytes(), dictionary
    )
    with Archive(f"sqlite:///{workdir / 'query.sqlite'}") as archive:
        archive.ingest_decoded("REF", decoded, uploaded_by="bench")
        durations = []
        for _ in range(QUERY_REPEATS):
            start = time.perf_counter()
            stats = downsample(archive, "REF", "omega_est_b_rad_s_x", int(t[0]), int(t[-1]), 1_000)
            durations.append(time.perf_counter() - start)
    ms = np.array(durations) * 1e3
    print(
        f"query: {int(stats.count.sum()):,} samples (2 h at 4 Hz) -> 1,000 buckets: "
        f"median {np.median(ms):.2f} ms, p95 {np.percentile(ms, 95):.2f} ms, max {ms.max():.2f} ms (target < 20 ms)"
    )


def live_definition() -> Dictionary:
    """One 50-float packet type (CUC 4+2 time, CRC-16) for the live benchmark."""
    reference = reference_dictionary().packets[256]
    header_bits = 8 * (6 + reference.time_code.octets)
    params = tuple(Parameter(f"p{k:02d}", "float", header_bits + 32 * k, 32) for k in range(LIVE_PARAMETERS))
    octets = (header_bits + 32 * LIVE_PARAMETERS) // 8 + 2
    return Dictionary(
        "live-bench", {300: PacketDefinition("BENCH", 300, octets, params, reference.time_code, crc=True)}
    )


def live_sender(port: int, seconds: float) -> None:
    """Sender process: LIVE_BURST packets every LIVE_BURST / LIVE_RATE_HZ s, time-stamped on encoding."""
    packet = live_definition().packets[300]
    rng = np.random.default_rng(2)
    values = {p.name: rng.normal(size=LIVE_BURST) for p in packet.parameters}
    sock = socket.create_connection(("127.0.0.1", port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    period = LIVE_BURST / LIVE_RATE_HZ
    start = time.perf_counter()
    for k in range(int(seconds / period)):
        delay = start + k * period - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        t = np.full(LIVE_BURST, time.time_ns(), dtype=np.int64)
        seq = (k * LIVE_BURST + np.arange(LIVE_BURST)) % 16_384
        sock.sendall(encode_packets(packet, t, seq, values).tobytes())
    sock.close()


async def live_run(seconds: float, workdir: Path) -> tuple[np.ndarray, int, int, int]:
    """Run the listener (archiving to SQLite) and a keeping-up subscriber; latencies in ms."""
    archive = Archive(f"sqlite:///{workdir / 'live.sqlite'}")
    stream = LiveStream(live_definition(), archive=archive, satellite="LIVE")
    subscriber = stream.subscribe(max_messages=10_000)
    port = await stream.start()
    latencies: list[np.ndarray] = []

    async def consume() -> None:
        while True:
            message = await subscriber.get()
            latencies.append((time.time_ns() - message.batch.t_utc_ns) / 1e6)

    consumer = asyncio.create_task(consume())
    sender = multiprocessing.get_context("fork").Process(target=live_sender, args=(port, seconds))
    sender.start()
    while sender.is_alive():
        await asyncio.sleep(0.2)
    await asyncio.sleep(0.5)
    await stream.stop()
    consumer.cancel()
    archive.close()
    received = sum(a.size for a in latencies)
    return (
        np.concatenate(latencies) if latencies else np.zeros(0),
        received,
        subscriber.dropped_packets_total,
        stream.stats.packets_archived,
    )


def bench_live(seconds: float, workdir: Path) -> None:
    """Print live-stream latency percentiles and counts."""
    cpu_start = time.process_time()
    latency_ms, received, dropped, archived = asyncio.run(live_run(seconds, workdir))
    cpu_share = (time.process_time() - cpu_start) / seconds
    sent = int(seconds / (LIVE_BURST / LIVE_RATE_HZ)) * LIVE_BURST
    print(
        f"live: {LIVE_RATE_HZ:,} packets/s x {LIVE_PARAMETERS} parameters for {seconds:.0f} s: sent {sent:,}, "
        f"delivered {received:,}, dropped {dropped}, archived {archived:,}; listener CPU {cpu_share:.0%} of a core"
    )
    if latency_ms.size:
        print(
            f"      packet-to-subscriber latency: p50 {np.percentile(latency_ms, 50):.1f} ms, "
            f"p99 {np.percentile(latency_ms, 99):.1f} ms, max {latency_ms.max():.1f} ms (target p99 < 100 ms)"
        )


def main() -> None:
    """Run the selected benchmarks in a temporary directory."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scales", default="1,10,100", help="file sizes as multiples of a 30-min dump")
    parser.add_argument("--live-seconds", type=float, default=60.0)
    parser.add_argument("--skip-live", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="acs-twin-bench-") as tmp:
        workdir = Path(tmp)
        bench_bulk([int(s) for s in args.scales.split(",")], workdir)
        bench_query(workdir)
        bench_row_layout(workdir)
        bench_chunk_sizes(workdir)
        if not args.skip_live:
            bench_live(args.live_seconds, workdir)
    print(f"machine load average while running: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
