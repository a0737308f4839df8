"""The live stream over the in-memory link: the same framing, decoding, drop accounting and allow-list as
over TCP, deterministic and without sleeps (closing a memory connection returns once it is decoded)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from telemetry.decoding import decode_stream
from telemetry.live import LiveMessage, LiveStats, LiveStream, MemoryConnection, MemoryLink, Subscriber
from tests.telemetry.packet_streams import packets, reference

HK_APID = 256


def drain(subscriber: Subscriber) -> list[LiveMessage]:
    """Every message waiting in a subscriber's queue."""
    out = []
    while subscriber.pending:
        out.append(subscriber.get_nowait())
    return out


async def send(link: MemoryLink, data: bytes, cuts: np.ndarray | None = None) -> MemoryConnection:
    """One connection carrying ``data`` split at ``cuts``; returns once the stream has decoded all of it."""
    connection = link.connect()
    for piece in np.split(np.frombuffer(data, np.uint8), [] if cuts is None else cuts):
        connection.write(piece.tobytes())
    await connection.aclose()
    return connection


def test_packets_cut_anywhere_arrive_as_decoded_offline() -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 400, seed=1)
    offline = decode_stream(raw.tobytes(), dictionary)
    cuts = np.sort(np.random.default_rng(5).choice(raw.size, 300, replace=False))  # mid-header cuts included

    async def scenario() -> tuple[list[LiveMessage], MemoryConnection, int]:
        stream, link = LiveStream(dictionary), MemoryLink()
        subscriber = stream.subscribe(max_messages=10_000)
        port = await stream.start(link=link)
        connection = await send(link, raw.tobytes(), cuts)
        await stream.stop()
        return drain(subscriber), connection, port

    messages, connection, port = asyncio.run(scenario())
    assert port == 0 and connection.closed_by_stream
    np.testing.assert_array_equal(np.concatenate([m.batch.t_utc_ns for m in messages]), offline.batches[0].t_utc_ns)
    for name, column in offline.batches[0].values.items():
        np.testing.assert_array_equal(np.concatenate([m.batch.values[name] for m in messages]), column)
    assert all(m.dropped_packets == 0 for m in messages)


def test_a_full_subscriber_keeps_the_newest_batch_and_its_next_message_counts_the_lost() -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 40, seed=2)
    parts = [raw[i : i + 10].tobytes() for i in range(0, 40, 10)]  # four connections of 10 packets each

    async def scenario() -> tuple[LiveMessage, LiveMessage, Subscriber]:
        stream, link = LiveStream(dictionary), MemoryLink()
        slow = stream.subscribe(max_messages=1)
        await stream.start(link=link)
        await send(link, parts[0])
        await send(link, parts[1])  # queue full: parts[0] dropped, counted
        await send(link, parts[2])  # parts[1] dropped, counted
        first = slow.get_nowait()
        await send(link, parts[3])
        await stream.stop()
        return first, slow.get_nowait(), slow

    first, late, slow = asyncio.run(scenario())
    assert first.dropped_packets == 20 and int(first.batch.sequence_count[0]) == 20  # the newest, after the gap
    assert slow.dropped_packets_total == 20 and late.dropped_packets == 0
    assert int(late.batch.sequence_count[0]) == 30


@pytest.mark.parametrize(
    ("peer", "allowed", "accepted"),
    [
        ("127.0.0.1", ("127.0.0.0/8",), True),
        ("192.0.2.7", ("127.0.0.0/8",), False),
        ("192.0.2.7", ("192.0.2.0/24",), True),
    ],
)
def test_the_allow_list_decides_before_a_byte_is_read(peer: str, allowed: tuple[str, ...], accepted: bool) -> None:
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 5, seed=3)

    async def scenario() -> tuple[list[LiveMessage], LiveStats]:
        stream, link = LiveStream(dictionary, allowed_sources=allowed), MemoryLink(peer_host=peer)
        subscriber = stream.subscribe()
        await stream.start(link=link)
        await send(link, raw.tobytes())
        await stream.stop()
        return drain(subscriber), stream.stats

    messages, stats = asyncio.run(scenario())
    assert sum(len(m.batch.t_utc_ns) for m in messages) == (5 if accepted else 0)
    assert (stats.connections_refused, stats.last_refused_peer) == ((0, "") if accepted else (1, peer))


def test_connecting_before_the_stream_started_names_the_link() -> None:
    with pytest.raises(RuntimeError, match="link"):
        MemoryLink().connect()
