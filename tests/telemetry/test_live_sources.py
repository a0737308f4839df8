"""The live listener's door: packets only from the allow-listed networks (loopback by default).

Truth: one spoofed packet used to raise two latched red alarms (issue 16); a refused peer must
deliver nothing at all, an allowed one everything.
"""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from telemetry.live import LOOPBACK_SOURCES, LiveStream, source_networks
from tests.telemetry.packet_streams import packets, reference
from tests.telemetry.test_live import HANG_S, HK_APID, drain, send, until_decoded


async def door(stream: LiveStream) -> None:
    """Until the listener has served or refused the connection."""
    while not stream.stats.connections and not stream.stats.connections_refused:
        await asyncio.sleep(0.01)


def _deliver(sources: tuple[str, ...]) -> tuple[int, int, int]:
    """Packets delivered, connections refused, connections served for 20 packets sent from 127.0.0.1."""
    dictionary = reference()
    raw = packets(dictionary.packets[HK_APID], 20, seed=3).tobytes()

    async def scenario() -> tuple[int, int, int]:
        stream = LiveStream(dictionary, allowed_sources=sources)
        subscriber = stream.subscribe()
        port = await stream.start()
        with contextlib.suppress(ConnectionError):  # a refused peer may see its connection reset mid-send
            await send(port, raw)
        await asyncio.wait_for(door(stream), HANG_S)
        if stream.stats.connections:  # served: every packet decoded before we look
            await until_decoded(stream, 20)
        await stream.stop()
        delivered = sum(len(m.batch.sequence_count) for m in drain(subscriber))
        return delivered, stream.stats.connections_refused, stream.stats.connections

    return asyncio.run(scenario())


def test_loopback_is_the_default_and_is_served() -> None:
    assert LiveStream.__init__.__kwdefaults__["allowed_sources"] == LOOPBACK_SOURCES
    assert _deliver(LOOPBACK_SOURCES) == (20, 0, 1)


def test_a_peer_outside_the_allow_list_delivers_nothing() -> None:
    assert _deliver(("10.0.0.0/8", "192.168.0.0/16")) == (0, 1, 0)


def test_a_bad_network_is_named() -> None:
    with pytest.raises(ValueError, match="allowed_sources"):
        source_networks(["10.0.0.300/8"])


def test_stopping_with_a_sender_connected_logs_nothing() -> None:
    """A stop of the server used to print asyncio's traceback for each open connection (issue 16)."""
    errors: list[dict] = []

    async def scenario() -> None:
        asyncio.get_running_loop().set_exception_handler(lambda _, context: errors.append(context))
        stream = LiveStream(reference())
        port = await stream.start()
        _, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(packets(reference().packets[HK_APID], 5, seed=4).tobytes())
        await writer.drain()
        await until_decoded(stream, 5)
        await stream.stop()
        await asyncio.sleep(0.1)
        writer.close()

    asyncio.run(scenario())
    assert errors == []
