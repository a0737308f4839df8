"""Live TCP stream: framing by the length field, bounded subscribers that report drops, archiving."""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time
from typing import Any, cast

import numpy as np
import pytest

from telemetry import live
from telemetry.archive import Archive, IngestResult, PendingUpload
from telemetry.decoding import decode_stream
from telemetry.dictionary import load_dictionary
from telemetry.live import LiveMessage, LiveStream, MemoryLink, Subscriber, complete_prefix, hello
from tests.telemetry.archive_databases import archive, archive_url  # noqa: F401  (fixtures)
from tests.telemetry.packet_streams import T0_UTC_NS, engineering_values, packets, reference

HK_APID = 256
STALL_S = 0.5  # about twice the 0.25-s send: most of the stream arrives while the loop is blocked
HANG_S = 60.0  # a listener that never decodes what was sent fails the wait after this (a hang bound, not a budget)


async def send(port: int, data: bytes, piece_sizes: np.ndarray | None = None, pause_s: float = 0.0) -> None:
    """Open a connection, send ``data`` in the given piece sizes (default: at once), close."""
    _, writer = await asyncio.open_connection("127.0.0.1", port)
    sizes = [len(data)] if piece_sizes is None else piece_sizes.tolist()
    at = 0
    for size in sizes:
        if at >= len(data):
            break
        writer.write(data[at : at + size])
        at += size
        await writer.drain()
        if pause_s:
            await asyncio.sleep(pause_s)
    writer.write(data[at:])
    await writer.drain()
    writer.close()
    await writer.wait_closed()


async def until_decoded(stream: LiveStream, n_packets: int) -> None:
    """Wait until the listener has decoded ``n_packets`` (its tally says so): they are in its subscribers' queues
    and its archive's pending batches."""

    async def tally() -> None:
        while stream.stats.packets_received < n_packets:
            await asyncio.sleep(live.DECODE_INTERVAL_S)

    await asyncio.wait_for(tally(), HANG_S)


def drain(subscriber: Subscriber) -> list[LiveMessage]:
    """Every message waiting in a subscriber's queue."""
    out = []
    while subscriber.pending:
        out.append(subscriber.get_nowait())
    return out


def test_complete_prefix_walks_the_packet_length_fields() -> None:
    packet_7 = bytes([0x08, 0x01, 0xC0, 0x00, 0x00, 0x00, 0xAA])  # data length field 0 -> 7 octets
    packet_9 = bytes([0x08, 0x02, 0xC0, 0x01, 0x00, 0x02, 1, 2, 3])  # field 2 -> 9 octets
    stream = packet_7 + packet_9
    assert [complete_prefix(stream[:k]) for k in (0, 5, 7, 8, 15, 16)] == [0, 0, 7, 7, 7, 16]


def test_complete_prefix_skips_noise_that_does_not_fit_the_dictionary() -> None:
    packet_7 = bytes([0x08, 0x01, 0xC0, 0x00, 0x00, 0x00, 0xAA])  # APID 1, 7 octets
    noise = bytes([0x08, 0x01, 0xC0, 0x00, 0xFF, 0xF0, 0x55])  # APID 1 but claims 65,527 octets
    stream = packet_7 + noise + packet_7
    assert complete_prefix(stream) == 7  # trusting the length field would wait for 65 kB
    assert complete_prefix(stream, {1: 7}) == 21
    assert complete_prefix(noise, {1: 7}) == 0  # short noise waits: the next header may start in it


def test_noise_between_packets_is_quarantined_and_every_packet_delivered() -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 60, seed=6)
    noise = np.random.default_rng(8).integers(0, 256, 37, dtype=np.uint8).tobytes()
    data = raw[:30].tobytes() + noise + raw[30:].tobytes()

    async def scenario() -> tuple[list[LiveMessage], int]:
        stream = LiveStream(dictionary)
        subscriber = stream.subscribe()
        port = await stream.start()
        await send(port, data, np.full(12, 500), pause_s=0.03)
        await until_decoded(stream, 60)
        await stream.stop()
        return drain(subscriber), stream.stats.stretches_quarantined

    messages, quarantined = asyncio.run(scenario())
    np.testing.assert_array_equal(np.concatenate([m.batch.sequence_count for m in messages]), np.arange(60))
    assert quarantined >= 1


def test_packets_cut_at_arbitrary_boundaries_arrive_as_decoded_offline() -> None:
    dictionary = reference()
    hk = dictionary.packets[HK_APID]
    raw = packets(hk, 400, seed=1)
    offline = decode_stream(raw.tobytes(), dictionary)
    pieces = np.random.default_rng(5).integers(1, 300, 400)

    async def scenario() -> list[LiveMessage]:
        stream = LiveStream(dictionary)
        subscriber = stream.subscribe(max_messages=10_000)
        port = await stream.start()
        await send(port, raw.tobytes(), pieces, pause_s=0.001)
        await until_decoded(stream, 400)
        await stream.stop()
        return drain(subscriber)

    messages = asyncio.run(scenario())
    assert len(messages) > 1  # the stream really was decoded in several batches
    live_t = np.concatenate([m.batch.t_utc_ns for m in messages])
    np.testing.assert_array_equal(live_t, offline.batches[0].t_utc_ns)
    for name, column in offline.batches[0].values.items():
        np.testing.assert_array_equal(np.concatenate([m.batch.values[name] for m in messages]), column)
    np.testing.assert_array_equal(
        np.concatenate([m.batch.values["wheel_speed_rad_s_1"] for m in messages]),
        engineering_values(hk, 400, seed=1)["wheel_speed_rad_s_1"],
    )
    assert all(m.dropped_packets == 0 for m in messages)


def test_slow_subscriber_never_stalls_the_stream_sees_the_newest_batch_and_is_told_what_it_dropped() -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 2_001, seed=2)

    async def scenario() -> tuple[list[LiveMessage], Subscriber, LiveMessage]:
        stream = LiveStream(dictionary)
        fast, slow = stream.subscribe(max_messages=10_000), stream.subscribe(max_messages=1)
        port = await stream.start()
        await send(port, raw[:2_000].tobytes(), np.full(20, 100 * raw.shape[1]), pause_s=0.03)
        await until_decoded(stream, 2_000)
        fast_messages = drain(fast)
        first_slow = slow.get_nowait()
        await send(port, raw[2_000:].tobytes())
        await until_decoded(stream, 2_001)
        await stream.stop()
        assert first_slow.dropped_packets == slow.dropped_packets_total > 0  # every loss lies before it
        assert int(first_slow.batch.sequence_count[-1]) == 1_999  # newest wins: the slow one sees the present
        assert first_slow.dropped_packets + len(first_slow.batch.t_utc_ns) == 2_000
        return fast_messages, slow, slow.get_nowait()

    fast_messages, slow, late = asyncio.run(scenario())
    assert sum(len(m.batch.t_utc_ns) for m in fast_messages) == 2_000
    assert late.dropped_packets == 0
    assert int(late.batch.sequence_count[0]) == 2_000


def test_a_stalled_listener_catches_up_without_losing_packets() -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 1_000, seed=9)

    def blocking_sender(port: int) -> None:
        with socket.create_connection(("127.0.0.1", port)) as link:
            for piece in np.array_split(raw, 50):
                link.sendall(piece.tobytes())
                time.sleep(0.005)

    async def scenario() -> list[LiveMessage]:
        stream = LiveStream(dictionary)
        subscriber = stream.subscribe(max_messages=10_000)
        port = await stream.start()
        sender = threading.Thread(target=blocking_sender, args=(port,))
        sender.start()
        time.sleep(STALL_S)  # the event loop stalls: the kernel buffers the stream meanwhile
        await asyncio.to_thread(sender.join)
        await until_decoded(stream, 1_000)
        await stream.stop()
        return drain(subscriber)

    counts = np.concatenate([m.batch.sequence_count for m in asyncio.run(scenario())])
    np.testing.assert_array_equal(counts, np.arange(1_000))


def test_corrupt_packet_is_quarantined_and_its_neighbours_delivered() -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 50, seed=3)
    raw[25, 40] ^= 0xFF  # breaks packet 25's CRC-16 (ECSS-E-ST-70-41C §7.4.1)

    async def scenario() -> tuple[list[LiveMessage], int]:
        stream = LiveStream(dictionary)
        subscriber = stream.subscribe()
        port = await stream.start()
        await send(port, raw.tobytes())
        await until_decoded(stream, 49)  # packet 25 quarantined
        await stream.stop()
        return drain(subscriber), stream.stats.stretches_quarantined

    messages, quarantined = asyncio.run(scenario())
    counts = np.concatenate([m.batch.sequence_count for m in messages])
    np.testing.assert_array_equal(counts, np.delete(np.arange(50), 25))
    assert quarantined == 1


def test_stream_is_archived_in_batches(archive: Archive) -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 600, seed=4)

    async def scenario() -> int:
        stream = LiveStream(dictionary, archive=archive, satellite="REF", archive_interval_s=0.05)
        port = await stream.start()
        await send(port, raw.tobytes(), np.full(6, 100 * raw.shape[1]), pause_s=0.1)
        await until_decoded(stream, 600)
        await stream.stop()
        return stream.stats.packets_archived

    assert asyncio.run(scenario()) == 600
    assert len(archive.uploads("REF")) > 1
    t, v = archive.read_parameter("REF", "wheel_speed_rad_s_2", T0_UTC_NS, T0_UTC_NS + 10**12)
    assert t.size == 600
    np.testing.assert_array_equal(
        v, engineering_values(dictionary.packets[HK_APID], 600, seed=4)["wheel_speed_rad_s_2"]
    )
    assert b"".join(p for _, p in archive.replay("REF", T0_UTC_NS, T0_UTC_NS + 10**12)) == raw.tobytes()


class _HeldArchive:
    """The real archive, but its first group commit waits in the worker thread until ``release`` is set."""

    def __init__(self, archive: Archive) -> None:
        self._archive = archive
        self.entered, self.release = threading.Event(), threading.Event()

    def ingest_many(self, uploads: list[PendingUpload]) -> list[IngestResult]:
        if not self.entered.is_set():
            self.entered.set()
            self.release.wait(HANG_S)
        return self._archive.ingest_many(uploads)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._archive, name)


class _ReleasingLink(MemoryLink):
    """A memory link that lets the held commit go once ``stop`` has closed the link (its flusher cancelled)."""

    def __init__(self, held: _HeldArchive) -> None:
        super().__init__()
        self._held = held

    async def wait_closed(self) -> None:
        self._held.release.set()


def test_stop_counts_and_keeps_the_commit_its_flusher_had_under_way(archive: Archive) -> None:
    """``stop`` cancels the periodic flusher while its group commit runs in the worker thread: the commit ends there
    anyway, and stop returns only once it is counted, then commits the rest (every decoded packet archived)."""
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 300, seed=5)
    held = _HeldArchive(archive)

    async def scenario() -> live.LiveStats:
        link = _ReleasingLink(held)
        stream = LiveStream(
            dictionary, archive=cast(Archive, held), satellite="REF", archive_interval_s=0.01, archive_uploads_per_s=1e3
        )
        await stream.start(link=link)
        first = link.connect()
        first.write(raw[:200].tobytes())
        await first.aclose()
        assert await asyncio.to_thread(held.entered.wait, HANG_S)  # a commit is under way in the worker thread
        second = link.connect()
        second.write(raw[200:].tobytes())
        await second.aclose()
        await stream.stop()
        return stream.stats

    stats = asyncio.run(scenario())
    assert (stats.packets_archived, stats.archive_pending_packets, stats.archive_errors) == (300, 0, 0)
    t, _ = archive.read_parameter("REF", "wheel_speed_rad_s_2", T0_UTC_NS, T0_UTC_NS + 10**12)
    assert t.size == 300
    assert b"".join(p for _, p in archive.replay("REF", T0_UTC_NS, T0_UTC_NS + 10**12)) == raw.tobytes()


class _RefusingArchive:
    """An archive whose database is away: every group commit fails."""

    def ingest_many(self, uploads: list[PendingUpload]) -> list[IngestResult]:
        raise OSError("database away")


def test_stop_says_what_it_could_not_archive(caplog: pytest.LogCaptureFixture) -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 50, seed=6)

    async def scenario() -> live.LiveStats:
        link = MemoryLink()
        stream = LiveStream(dictionary, archive=cast(Archive, _RefusingArchive()), satellite="REF")
        await stream.start(link=link)
        connection = link.connect()
        connection.write(raw.tobytes())
        await connection.aclose()
        await stream.stop()
        return stream.stats

    with caplog.at_level(logging.ERROR, logger="telemetry.live"):
        stats = asyncio.run(scenario())
    assert (stats.packets_archived, stats.archive_pending_packets, stats.archive_errors) == (0, 50, 1)
    assert "stopped with 50 decoded packets of REF not archived" in caplog.text
    assert "database away" in caplog.text


def test_archived_stream_needs_a_satellite_and_subscribers_a_positive_queue() -> None:
    with pytest.raises(ValueError, match="satellite"):
        LiveStream(reference(), archive=object())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_messages"):
        Subscriber(0)


def test_one_listener_serves_a_fleet_each_connection_filed_under_the_satellite_its_hello_names(
    archive: Archive, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Three satellites, each on its own connection (hello line cut anywhere, even mid-name) plus one connection
    without a hello (the stream's own satellite): every packet reaches subscribers tagged with its satellite and
    the archive under that satellite, byte-exact; a budget of one upload per interval commits the longest waiting
    satellite first, samples that waited ARCHIVE_MAX_WAIT_S go whatever the budget, and ``stop`` commits the rest."""

    dictionary = reference()
    fleet = {name: packets(dictionary.packets[HK_APID], 40 + 10 * k, seed=k) for k, name in enumerate("ABC")}
    own = packets(dictionary.packets[HK_APID], 25, seed=9)

    async def scenario() -> tuple[dict[str, int], int]:
        link = MemoryLink()
        stream = LiveStream(
            dictionary, archive=archive, satellite="OWN", archive_interval_s=3600.0, archive_uploads_per_s=1 / 3600
        )
        subscriber = stream.subscribe(max_messages=1000)
        await stream.start(link=link)
        for k, (name, raw) in enumerate(fleet.items()):
            data = hello(name) + raw.tobytes()
            connection = link.connect()
            for cut in (0, 4 + k, 12, len(data)):  # "SATE" | "LLITE A" ... : the hello arrives in pieces
                connection.write(data[:cut])
                data = data[cut:]
                await asyncio.sleep(0)
            await connection.aclose()
        connection = link.connect()
        connection.write(own.tobytes())
        await connection.aclose()
        tagged: dict[str, int] = {}
        for message in drain(subscriber):
            tagged[message.satellite] = tagged.get(message.satellite, 0) + len(message.batch.t_utc_ns)
        # no satellite past the wait limit, however long the machine took to get here (20 s on the wall clock)
        monkeypatch.setattr(live, "ARCHIVE_MAX_WAIT_S", float("inf"))
        assert await stream.flush()  # the budget: one satellite, the one waiting longest (A)
        assert [_archived(name, archive) for name in ("A", "B", "C", "OWN")] == [True, False, False, False]
        monkeypatch.setattr(live, "ARCHIVE_MAX_WAIT_S", 0.0)  # B and C have waited that long: past the budget
        assert await stream.flush()
        assert [_archived(name, archive) for name in ("A", "B", "C", "OWN")] == [True, True, True, True]
        await stream.stop()
        return tagged, stream.stats.satellites

    tagged, heard = asyncio.run(scenario())
    assert tagged == {**{name: raw.shape[0] for name, raw in fleet.items()}, "OWN": own.shape[0]} and heard == 4
    for name, raw in {**fleet, "OWN": own}.items():
        assert b"".join(p for _, p in archive.replay(name, T0_UTC_NS, T0_UTC_NS + 10**12)) == raw.tobytes()


def _archived(satellite: str, archive: Archive) -> bool:
    try:
        return bool(archive.uploads(satellite))
    except ValueError:  # nothing archived under that name
        return False


def test_a_first_line_that_names_no_valid_satellite_is_noise_and_a_bad_name_is_refused() -> None:

    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 20, seed=2)
    with pytest.raises(ValueError, match="satellite"):
        hello("bad name\n")

    async def scenario() -> list[LiveMessage]:
        link = MemoryLink()
        stream = LiveStream(dictionary, satellite="OWN")
        subscriber = stream.subscribe(max_messages=100)
        await stream.start(link=link)
        connection = link.connect()
        connection.write(b"SATELLITE a b\n" + raw.tobytes())
        await connection.aclose()
        await stream.stop()
        return drain(subscriber)

    messages = asyncio.run(scenario())
    assert {m.satellite for m in messages} == {"OWN"}
    assert sum(len(m.batch.t_utc_ns) for m in messages) == raw.shape[0]  # the line was quarantined, no packet lost


NOAA20_PACKETS = "real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
NOAA20_DICTIONARY = "noaa20_apid11_ccsdspy.yaml"


def test_a_mixed_fleet_on_one_listener_each_connection_decoded_with_the_dictionary_its_hello_names(
    archive: Archive, shared_data, tmp_path
) -> None:
    from backend.ingest.dictionary_catalogue import DictionaryCatalogue

    own = reference()
    noaa = load_dictionary(NOAA20_DICTIONARY)
    real = (shared_data / NOAA20_PACKETS).read_bytes()
    real = real[: complete_prefix(real[:200_000], noaa.packet_octets_by_apid())]  # whole packets of a real pass
    ref = packets(own.packets[HK_APID], 40, seed=7)
    assert hello("N20", NOAA20_DICTIONARY) == b"SATELLITE N20 DICTIONARY noaa20_apid11_ccsdspy.yaml\n"
    with pytest.raises(ValueError, match="dictionary"):
        hello("N20", "no such.yaml")

    async def scenario() -> tuple[list[LiveMessage], live.LiveStats]:
        link = MemoryLink()
        catalogue = DictionaryCatalogue(tmp_path)
        stream = LiveStream(own, archive=archive, satellite="OWN", dictionaries=catalogue.load_known)
        subscriber = stream.subscribe(max_messages=10_000)
        await stream.start(link=link)
        for data in (
            hello("N20", NOAA20_DICTIONARY) + real,  # another mission's packets, its dictionary named
            hello("REF-2") + ref.tobytes(),  # the listener's own dictionary, as before
            hello("X-1", "nope.yaml") + ref.tobytes(),  # a dictionary nobody knows: refused
        ):
            connection = link.connect()
            connection.write(data)
            await connection.aclose()
        await stream.stop()
        return drain(subscriber), stream.stats

    messages, stats = asyncio.run(scenario())
    assert {m.satellite for m in messages} == {"N20", "REF-2"}  # nothing of the refused connection
    assert stats.hellos_refused == 1 and "'nope.yaml'" in stats.last_hello_error
    assert NOAA20_DICTIONARY in stats.last_hello_error  # the error names the known dictionaries
    for satellite, data, dictionary in (("N20", real, noaa), ("REF-2", ref.tobytes(), own)):
        offline = {b.packet: b for b in decode_stream(data, dictionary).batches}
        got = [m.batch for m in messages if m.satellite == satellite]
        assert {b.packet for b in got} == set(offline) and sum(len(b.t_utc_ns) for b in got) > 0
        for name, batch in offline.items():
            mine = [b for b in got if b.packet == name]
            for parameter, column in batch.values.items():
                np.testing.assert_array_equal(np.concatenate([b.values[parameter] for b in mine]), column)
        t0, t1 = int(min(b.t_utc_ns.min() for b in got)), int(max(b.t_utc_ns.max() for b in got))
        assert b"".join(p for _, p in archive.replay(satellite, t0, t1 + 1)) == data  # archived as sent
    assert not _archived("X-1", archive)
