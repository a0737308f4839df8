"""Live telemetry (issue 5): a link (TCP, or memory in tests) -> decode -> publish to subscribers -> archive in batches.

The stream is a sequence of CCSDS space packets framed by their packet data length field
(CCSDS 133.0-B-2 §4.1.3.5: total length = field + 7 octets).  Complete packets are decoded in
bulk by :func:`telemetry.decoding.decode_stream` at most every ``DECODE_INTERVAL_S`` (a decode
call costs ~2 ms whatever its size, so coalescing is what sustains thousands of packets per
second), published to every subscriber without ever waiting (newest wins: a full queue drops its
oldest message, and the next message the subscriber takes says how many packets it lost), and
committed to the archive in batches from a worker thread so a slow database never stalls the socket
(the archive path never drops a packet the stream accepted).

One listener serves a fleet. Space packets carry no spacecraft identifier (it lives in the transfer frames a
ground station strips), so a connection says whose packets it carries the way an SLE service binds to one
spacecraft before data flows: it may open with the line ``SATELLITE <name>\n`` (:func:`hello`); a connection
without it carries the stream's default satellite. A mixed fleet names the dictionary too,
``SATELLITE <name> DICTIONARY <id>\n``, an id the stream's ``dictionaries`` knows (else the connection is refused,
said in the stats and the log); without it, the stream's own dictionary decodes. The line cannot be mistaken for a
packet: a CCSDS version-1 primary header starts with an octet below 0x20 (version bits 000), ``S`` is 0x53.

Archiving is a group commit over the fleet: every ``archive_interval_s`` one transaction
(:meth:`~telemetry.archive.Archive.ingest_many`, one fsync) commits the pending samples of the satellites that
waited longest, at most ``archive_uploads_per_s`` × the interval of them (more when samples waited
``ARCHIVE_MAX_WAIT_S``: commits that fell behind catch up in bigger groups). An upload costs ~10–30 ms of CPU whatever
its length (a row per parameter, duplicate and limit checks), so the budget caps the archive's CPU (≈ 0.1–0.3 core
at 10 uploads/s) and the time a sample waits to become durable grows with the fleet instead: one interval for a
handful of satellites, satellites ÷ budget seconds beyond (10 s for 100 at 10/s). Subscribers get every batch at
once regardless.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import re
import time
from collections.abc import Callable, Coroutine, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from telemetry.archive import Archive, IngestResult, PacketBatch, PendingUpload
from telemetry.decoding import decode_stream
from telemetry.dictionary import Dictionary
from telemetry.encoding import encode_packets
from telemetry.ingest_report import SampleBatch
from telemetry.limits import LimitSet, dictionary_limits

__all__ = [
    "LiveMessage",
    "LiveStats",
    "Subscriber",
    "LiveStream",
    "Link",
    "TcpLink",
    "MemoryLink",
    "MemoryConnection",
    "LOOPBACK_SOURCES",
    "complete_prefix",
    "source_networks",
    "warm_decoder",
    "DECODE_INTERVAL_S",
    "HELLO_PREFIX",
    "hello",
]

log = logging.getLogger(__name__)

PRIMARY_HEADER_OCTETS = 6
IDLE_APID = 0x7FF  # idle packets, CCSDS 133.0-B-2 §4.1.3.3.4.4
LENGTH_FIELD_OFFSET = 7  # total octets = packet data length field + 7 (CCSDS 133.0-B-2 §4.1.3.5.3)
READ_BYTES = 1 << 16
DECODE_INTERVAL_S = 0.02  # coalescing window: adds <= 20 ms of latency, bounds decode calls to 50/s
ARCHIVE_INTERVAL_S = 0.5
ARCHIVE_MAX_PACKETS = 8_192
ARCHIVE_UPLOADS_PER_S = 10.0  # satellites committed per second at most (see the module docstring)
ARCHIVE_MAX_GROUP = 100  # uploads in one transaction when everything is committed (stop), or when commits fall
# behind: far below SQLite's 30 s busy timeout
ARCHIVE_MAX_WAIT_S = 20.0  # samples waiting this long go in the next commit whatever the budget: commits that fall
# behind (a slow disk, a starved process) take bigger groups, one fsync for more satellites, and catch up
HELLO_PREFIX = b"SATELLITE "
HELLO_MAX_OCTETS = 160  # a connection's first line longer than this is not a hello: its octets are decoded as packets
HELLO_DICTIONARY = "DICTIONARY"  # SATELLITE <name> DICTIONARY <id>
SATELLITE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.:+-]{0,63}")


def hello(satellite: str, dictionary: str | None = None) -> bytes:
    """The line a connection opens with to say that its packets are ``satellite``'s, decoded with ``dictionary``
    (an id the listener knows, such as a dictionary's file name; None: the listener's own); ValueError for a bad
    name or id."""
    for what, text in (("satellite", satellite), ("dictionary", dictionary)):
        if text is not None and not SATELLITE_NAME.fullmatch(text):
            raise ValueError(f"{what}: {text!r} is not 1-64 letters, digits or _.:+- (starting alphanumeric)")
    tail = b"" if dictionary is None else f" {HELLO_DICTIONARY} {dictionary}".encode()
    return HELLO_PREFIX + satellite.encode() + tail + b"\n"


def _read_hello(buffer: bytearray) -> tuple[str | None, str | None, int] | None:
    """(satellite or None, dictionary id or None, octets to drop) once the connection's first octets tell; None
    while they may still become a hello line. A line that starts like a hello but is not one is left as noise."""
    head = bytes(buffer[: len(HELLO_PREFIX)])
    if not HELLO_PREFIX.startswith(head):
        return None, None, 0  # packets (or noise): no hello
    end = buffer.find(b"\n", 0, HELLO_MAX_OCTETS)
    if end < 0:
        return (None, None, 0) if len(buffer) >= HELLO_MAX_OCTETS else None
    words = bytes(buffer[len(HELLO_PREFIX) : end]).decode("ascii", "replace").split()
    if not words or not all(SATELLITE_NAME.fullmatch(w) for w in words[:1] + words[2:]):
        return None, None, 0
    if len(words) == 1:
        return words[0], None, end + 1
    if len(words) == 3 and words[1] == HELLO_DICTIONARY:
        return words[0], words[2], end + 1
    return None, None, 0


def complete_prefix(buffer: bytes | bytearray, packet_octets: Mapping[int, int] | None = None) -> int:
    """Octets of ``buffer`` made of whole packets, walking the length fields (CCSDS 133.0-B-2 §4.1).

    With the dictionary's ``packet_octets`` (APID -> total octets), a header that does not fit
    (version not 0, unknown APID, length differing from the definition) is treated as noise: the
    walk resumes at the next header that fits, so the decoder quarantines the noise and one bad
    octet cannot misalign the rest of the stream.  Without it the length fields are trusted.
    """
    end, size = 0, len(buffer)
    while end + PRIMARY_HEADER_OCTETS <= size:
        if packet_octets is not None and not _header_fits(buffer, end, packet_octets):
            resume = _next_fitting_header(buffer, end + 1, packet_octets)
            if resume is None:
                return _noise_to_release(end, size, packet_octets)
            end = resume
            continue
        total = ((buffer[end + 4] << 8) | buffer[end + 5]) + LENGTH_FIELD_OFFSET
        if end + total > size:
            break
        end += total
    return end


def _header_fits(buffer: bytes | bytearray, at: int, packet_octets: Mapping[int, int]) -> bool:
    """Version 0 and a known APID whose defined length matches the packet length field (or idle)."""
    apid = ((buffer[at] & 0x07) << 8) | buffer[at + 1]
    total = ((buffer[at + 4] << 8) | buffer[at + 5]) + LENGTH_FIELD_OFFSET
    return buffer[at] >> 5 == 0 and (apid == IDLE_APID or packet_octets.get(apid) == total)


def _next_fitting_header(buffer: bytes | bytearray, start: int, packet_octets: Mapping[int, int]) -> int | None:
    for at in range(start, len(buffer) - PRIMARY_HEADER_OCTETS + 1):
        if _header_fits(buffer, at, packet_octets):
            return at
    return None


def _noise_to_release(end: int, size: int, packet_octets: Mapping[int, int]) -> int:
    """Hand over noise once it is longer than any packet (keeping a tail that may start a header)."""
    longest = max(packet_octets.values(), default=0)
    return size - PRIMARY_HEADER_OCTETS if size - end > longest + PRIMARY_HEADER_OCTETS else end


def warm_decoder(dictionary: Dictionary) -> None:
    """Decode one zero-valued packet of each type so compiled kernels exist before data arrives.

    A first decode compiles (or loads) numba kernels: seconds on a busy machine, during which a
    live stream would pile up behind the listener.
    """
    now_ns = np.array([time.time_ns()], dtype=np.int64)
    parts = []
    for packet in dictionary.packets.values():
        try:
            zeros = {p.name: np.zeros(1) for p in packet.parameters}
            parts.append(encode_packets(packet, now_ns, np.zeros(1, dtype=np.int64), zeros).tobytes())
        except ValueError:  # no time code, or zero outside a calibrated range: nothing to warm
            continue
    decode_stream(b"".join(parts), dictionary)


@dataclass(frozen=True)
class LiveMessage:
    """Decoded samples of one packet type, when they were read, packets lost just before, and whose they are."""

    batch: SampleBatch
    received_ns: int
    dropped_packets: int
    satellite: str = ""


@dataclass
class LiveStats:
    """Running tallies of a live stream."""

    connections: int = 0
    packets_received: int = 0
    stretches_quarantined: int = 0
    packets_archived: int = 0
    archive_errors: int = 0
    last_archive_error: str = ""
    connections_refused: int = 0
    last_refused_peer: str = ""
    hellos_refused: int = 0  # connections whose hello line named a dictionary the stream does not know
    last_hello_error: str = ""
    satellites: int = 0  # satellites heard since the start
    archive_pending_packets: int = 0  # decoded, not yet committed (refreshed every archive interval)
    archive_pending_uploads: int = 0  # satellites with samples waiting for their commit
    archive_oldest_pending_s: float = 0.0  # how long the oldest uncommitted sample has waited
    archive_commit_s: float = 0.0  # wall time of the last group commit (the transaction)
    after_commit_s: float = 0.0  # wall time of the bookkeeping after it (on_committed: passes from data)


class Subscriber:
    """A bounded queue of live messages for one in-process consumer (never blocks the stream)."""

    def __init__(self, max_messages: int) -> None:
        if max_messages < 1:
            raise ValueError(f"max_messages: expected at least 1, got {max_messages}")
        self._queue: asyncio.Queue[LiveMessage] = asyncio.Queue(max_messages)
        self._dropped_since_delivery = 0
        self.dropped_packets_total = 0

    def offer(self, batch: SampleBatch, received_ns: int, satellite: str = "") -> bool:
        """Queue a batch without waiting; newest wins: when full, the oldest queued message is dropped and its
        packets counted (the next message taken says how many). False if a message was dropped."""
        dropped = 0
        if self._queue.full():
            dropped = len(self._queue.get_nowait().batch.t_utc_ns)
            self._dropped_since_delivery += dropped
            self.dropped_packets_total += dropped
        self._queue.put_nowait(LiveMessage(batch, received_ns, 0, satellite))
        return dropped == 0

    async def get(self) -> LiveMessage:
        """The next message (waits until one arrives)."""
        return self._delivered(await self._queue.get())

    def get_nowait(self) -> LiveMessage:
        """The next message; raises asyncio.QueueEmpty if none is waiting."""
        return self._delivered(self._queue.get_nowait())

    def _delivered(self, message: LiveMessage) -> LiveMessage:
        """``message`` with the packets dropped since the last delivery (all older than it: drops take the oldest)."""
        if not self._dropped_since_delivery:
            return message
        message = replace(message, dropped_packets=self._dropped_since_delivery)
        self._dropped_since_delivery = 0
        return message

    @property
    def pending(self) -> int:
        """Messages waiting in the queue."""
        return self._queue.qsize()


LOOPBACK_SOURCES = ("127.0.0.0/8", "::1/128")  # default: only this machine may send packets


def source_networks(sources: Sequence[str]) -> tuple[ipaddress.IPv4Network | ipaddress.IPv6Network, ...]:
    """The networks packets may come from (ValueError naming ``allowed_sources`` for a bad entry)."""
    try:
        return tuple(ipaddress.ip_network(source, strict=False) for source in sources)
    except ValueError as exc:
        raise ValueError(f"allowed_sources: {exc}") from None


def _allowed(host: str, networks: Sequence[ipaddress.IPv4Network | ipaddress.IPv6Network]) -> bool:
    address = ipaddress.ip_address(host.split("%", 1)[0])
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return any(address in network for network in networks)


class Peer(Protocol):
    """The writing end of one connection as the stream uses it: who it is, and closing it."""

    def get_extra_info(self, name: str, default: Any = None) -> Any: ...

    def close(self) -> None: ...


ConnectionHandler = Callable[[asyncio.StreamReader, Peer], Coroutine[Any, Any, None]]


class Link(Protocol):
    """Where a live stream's bytes come from (like httpx's transports): TCP in service, memory in tests."""

    async def open(self, handle: ConnectionHandler) -> int:
        """Start accepting connections, each served by ``handle``; the bound port (0 without one)."""
        ...

    def close(self) -> None:
        """Accept no new connection."""
        ...

    async def wait_closed(self) -> None:
        """Wait until the link has released what it holds."""
        ...


class TcpLink:
    """The live link over TCP: a listener on host:port (0 = any free port)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        self._host, self._port = host, port
        self._server: asyncio.Server | None = None

    async def open(self, handle: ConnectionHandler) -> int:
        """Listen; the bound port."""
        self._server = await asyncio.start_server(handle, self._host, self._port)
        return int(self._server.sockets[0].getsockname()[1])

    def close(self) -> None:
        """Stop listening."""
        if self._server is not None:
            self._server.close()

    async def wait_closed(self) -> None:
        """Wait for the listener to close."""
        if self._server is not None:
            await self._server.wait_closed()


class MemoryConnection:
    """One in-memory connection: bytes written here reach the stream's reader directly, no socket."""

    def __init__(self, reader: asyncio.StreamReader, peer: tuple[str, int]) -> None:
        self.reader, self._peer = reader, peer
        self.closed_by_stream = False
        self.served: asyncio.Task[None] | None = None

    def write(self, data: bytes) -> None:
        """Send bytes to the stream (any split: the stream frames packets by their length field)."""
        self.reader.feed_data(data)

    async def aclose(self) -> None:
        """End of stream; returns once the stream has decoded and delivered everything sent."""
        self.reader.feed_eof()
        if self.served is not None:
            await self.served

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        """``peername`` as a socket would give it."""
        return self._peer if name == "peername" else default

    def close(self) -> None:
        """Called by the stream when it is done with the connection."""
        self.closed_by_stream = True


class MemoryLink:
    """The live link in memory, for tests: :meth:`connect` opens a connection from ``peer_host``."""

    def __init__(self, peer_host: str = "127.0.0.1") -> None:
        self._peer_host = peer_host
        self._handle: ConnectionHandler | None = None
        self._connections = 0

    async def open(self, handle: ConnectionHandler) -> int:
        """Accept connections (there is no port)."""
        self._handle = handle
        return 0

    def connect(self) -> MemoryConnection:
        """A new connection served by the stream (call inside the running event loop)."""
        if self._handle is None:
            raise RuntimeError("link: not open (start the stream first)")
        self._connections += 1
        connection = MemoryConnection(asyncio.StreamReader(), (self._peer_host, self._connections))
        connection.served = asyncio.create_task(self._handle(connection.reader, connection))
        return connection

    def close(self) -> None:
        """Accept no new connection."""
        self._handle = None

    async def wait_closed(self) -> None:
        """Nothing held."""


@dataclass(frozen=True)
class _Decoding:
    """How a connection's packets are decoded and checked: dictionary, its packet sizes by APID, limits."""

    dictionary: Dictionary
    packet_octets: dict[int, int]
    limits: dict[str, LimitSet]


class _Refused(Exception):
    """A connection the stream will not decode (its hello named an unknown dictionary)."""


class LiveStream:
    """Listener for the CCSDS packet streams of a fleet (optionally archived), over a :class:`Link`: each
    connection carries one satellite's packets, ``satellite`` unless it opens with a :func:`hello` line.

    ``on_committed(archive, spans, final)`` runs in the commit's worker thread after each group commit, with the
    (satellite, first, last sample ns) of every upload it committed, and once more at stop (no spans, ``final``
    True): bookkeeping over committed data (passes from data) serialised with the commits instead of contending
    for the write lock. ``dictionaries(id)``: the dictionary a hello line names (ValueError saying why for an
    unknown id; None: a hello naming a dictionary is refused), decoded and limit-checked with its own limits."""

    def __init__(
        self,
        dictionary: Dictionary,
        *,
        archive: Archive | None = None,
        satellite: str = "",
        limits: Mapping[str, LimitSet] | None = None,
        archive_interval_s: float = ARCHIVE_INTERVAL_S,
        archive_max_packets: int = ARCHIVE_MAX_PACKETS,
        archive_uploads_per_s: float = ARCHIVE_UPLOADS_PER_S,
        uploaded_by: str = "live",
        allowed_sources: Sequence[str] = LOOPBACK_SOURCES,
        on_committed: Callable[[Archive, list[tuple[str, int, int]], bool], None] | None = None,
        dictionaries: Callable[[str], Dictionary] | None = None,
    ) -> None:
        if archive is not None and not satellite:
            raise ValueError("satellite: required when the stream is archived")
        if not archive_uploads_per_s > 0:
            raise ValueError(f"archive_uploads_per_s: must be > 0, got {archive_uploads_per_s}")
        self._allowed = source_networks(allowed_sources)
        self._dictionary, self._archive, self._satellite = dictionary, archive, satellite
        self._own = _Decoding(dictionary, dictionary.packet_octets_by_apid(), dict(limits or {}))
        self._dictionaries = dictionaries
        self._named: dict[str, _Decoding] = {}  # the dictionaries hello lines named, by id
        self._limits_of: dict[str, dict[str, LimitSet]] = {}  # per satellite: those of the dictionary it came with
        self._interval_s, self._max_packets, self._uploaded_by = archive_interval_s, archive_max_packets, uploaded_by
        self._uploads_per_flush = max(1, round(archive_uploads_per_s * archive_interval_s))
        self._subscribers: list[Subscriber] = []
        self._pending: dict[str, list[SampleBatch]] = {}  # per satellite, in arrival order
        self._pending_since: dict[str, float] = {}  # monotonic time its oldest pending batch arrived
        self._pending_packets: dict[str, int] = {}
        self._heard: set[str] = set()
        self._flush_lock = asyncio.Lock()
        self._link: Link | None = None
        self._connections: set[asyncio.Task[None]] = set()
        self._flushes: set[asyncio.Task[bool]] = set()
        self._commits: set[asyncio.Future[list[IngestResult]]] = set()  # in the worker thread now
        self._flusher: asyncio.Task[None] | None = None
        self._flush_count = 0
        self._on_committed = on_committed
        self.stats = LiveStats()

    def subscribe(self, max_messages: int = 256) -> Subscriber:
        """A new subscriber receiving every batch decoded from now on."""
        subscriber = Subscriber(max_messages)
        self._subscribers.append(subscriber)
        return subscriber

    def unsubscribe(self, subscriber: Subscriber) -> None:
        """Stop delivering to ``subscriber``."""
        self._subscribers.remove(subscriber)

    async def start(self, host: str = "127.0.0.1", port: int = 0, *, link: Link | None = None) -> int:
        """Warm the decoder, then accept connections on ``link`` (default: TCP on host:port, 0 = any free
        port); returns the bound port (0 for a link without one)."""
        await asyncio.to_thread(warm_decoder, self._dictionary)
        self._link = TcpLink(host, port) if link is None else link
        bound = await self._link.open(self._handle)
        if self._archive is not None:
            self._flusher = asyncio.create_task(self._flush_periodically())
        return bound

    async def stop(self) -> None:
        """Close the listener and its connections, then archive everything pending (a commit under way included);
        what the archive refuses stays counted in ``stats.archive_pending_packets`` and is logged as an error."""
        if self._link is not None:
            self._link.close()
        for task in list(self._connections):
            task.cancel()
        await asyncio.gather(*self._connections, *self._flushes, return_exceptions=True)
        if self._flusher is not None:
            self._flusher.cancel()
            await asyncio.gather(self._flusher, return_exceptions=True)
        if self._link is not None:
            await self._link.wait_closed()
        # a commit the cancelled flusher had handed to the worker thread goes on there: it is counted (or its batches
        # are pending again, for the final flush) only once it ends
        await asyncio.gather(*self._commits, return_exceptions=True)
        while self._pending and await self.flush(everything=True):
            pass
        if self._pending:
            self._note_backlog()
            log.error(
                "live stream: stopped with %d decoded packets of %s not archived: %s",
                self.stats.archive_pending_packets,
                ", ".join(sorted(self._pending)),
                self.stats.last_archive_error,
            )
        if self._archive is not None:
            await asyncio.to_thread(self._after_commit, self._archive, [], True)

    async def _handle(self, reader: asyncio.StreamReader, writer: Peer) -> None:
        host = str(writer.get_extra_info("peername")[0])
        if not _allowed(host, self._allowed):  # not on the allow-list: closed before a byte is read
            self.stats.connections_refused += 1
            self.stats.last_refused_peer = host
            writer.close()
            return
        task = asyncio.current_task()
        if task is not None:
            self._connections.add(task)
        self.stats.connections += 1
        peer = "{}:{}".format(*writer.get_extra_info("peername")[:2])
        buffer, arrived, closed = bytearray(), asyncio.Event(), asyncio.Event()
        satellite: str | None = None  # until the first octets tell (hello line or packets)
        decoding = self._own

        async def receive() -> None:
            while data := await reader.read(READ_BYTES):
                buffer.extend(data)
                arrived.set()
            closed.set()
            arrived.set()

        receiving = asyncio.create_task(receive())
        try:
            while not closed.is_set():
                await arrived.wait()
                arrived.clear()
                if satellite is None:
                    satellite, decoding = await self._identify(buffer, peer)
                if satellite is not None:
                    self._process_complete(buffer, peer, satellite, decoding)
                await asyncio.sleep(DECODE_INTERVAL_S)
            if satellite is None:  # the connection ended before its first octets told
                satellite, decoding = await self._identify(buffer, peer, final=True)
        except _Refused:
            buffer.clear()  # nothing of a refused connection is decoded or archived
        except asyncio.CancelledError:
            pass  # stop(): end quietly (a cancelled connection task makes asyncio's stream callback log a traceback)
        finally:
            receiving.cancel()
            if satellite is None:  # stopped before the first octets told: a dictionary not yet loaded is refused
                satellite, named = self._satellite_of(buffer, final=True)
                decoding = self._own if named is None else self._named.get(named, decoding)
                if named is not None and named not in self._named:
                    buffer.clear()
            self._process_complete(buffer, peer, satellite or "", decoding)
            self.stats.stretches_quarantined += 1 if buffer else 0  # a packet cut off by the disconnect
            writer.close()
            if task is not None:
                self._connections.discard(task)

    def _satellite_of(self, buffer: bytearray, final: bool = False) -> tuple[str | None, str | None]:
        """(whose this connection's packets are, the dictionary id its hello named) once its first octets tell (the
        hello line dropped); (None, None) while they may still become a hello line (unless ``final``: it ended)."""
        read = _read_hello(buffer)
        if read is None:
            return (self._satellite if final else None), None
        name, dictionary, octets = read
        del buffer[:octets]
        return name or self._satellite, dictionary

    async def _identify(self, buffer: bytearray, peer: str, final: bool = False) -> tuple[str | None, _Decoding]:
        """(satellite or None while unknown, how its packets decode); :class:`_Refused` for a hello naming a
        dictionary the stream does not know (counted and said in the stats and the log)."""
        satellite, dictionary_id = self._satellite_of(buffer, final)
        if satellite is None or dictionary_id is None:
            return satellite, self._own
        if dictionary_id not in self._named:
            try:
                if self._dictionaries is None:
                    raise ValueError("this listener decodes with its own dictionary only")
                named = await asyncio.to_thread(self._dictionaries, dictionary_id)
            except ValueError as exc:
                self.stats.hellos_refused += 1
                self.stats.last_hello_error = f"{peer}: satellite {satellite}: dictionary {dictionary_id!r}: {exc}"
                log.warning("live stream: connection refused: %s", self.stats.last_hello_error)
                raise _Refused(self.stats.last_hello_error) from None
            self._named[dictionary_id] = _Decoding(named, named.packet_octets_by_apid(), dictionary_limits(named))
        return satellite, self._named[dictionary_id]

    def _process_complete(self, buffer: bytearray, peer: str, satellite: str, decoding: _Decoding) -> None:
        end = complete_prefix(buffer, decoding.packet_octets)
        if end == 0:
            return
        received_ns = time.perf_counter_ns()
        chunk = bytes(buffer[:end])
        del buffer[:end]
        decoded = decode_stream(chunk, decoding.dictionary, source=f"live:{peer}")
        self.stats.stretches_quarantined += len(decoded.report.quarantined)
        for batch in decoded.batches:
            if len(batch.t_utc_ns) == 0:
                continue
            self.stats.packets_received += len(batch.t_utc_ns)
            if satellite not in self._heard:
                self._heard.add(satellite)
                self.stats.satellites = len(self._heard)
            for subscriber in self._subscribers:
                subscriber.offer(batch, received_ns, satellite)
            self._queue_for_archive(satellite, batch, decoding.limits)

    def _queue_for_archive(self, satellite: str, batch: SampleBatch, limits: dict[str, LimitSet]) -> None:
        if self._archive is None:
            return
        self._limits_of[satellite] = limits
        if satellite not in self._pending:
            self._pending[satellite] = []
            self._pending_since[satellite] = time.monotonic()
            self._pending_packets[satellite] = 0
        self._pending[satellite].append(batch)
        self._pending_packets[satellite] += len(batch.t_utc_ns)
        if self._pending_packets[satellite] >= self._max_packets and not self._flush_lock.locked():
            flush = asyncio.create_task(self.flush())
            self._flushes.add(flush)
            flush.add_done_callback(self._flushes.discard)

    async def _flush_periodically(self) -> None:
        while True:
            await asyncio.sleep(self._interval_s)
            await self.flush()

    def _due(self, everything: bool) -> list[str]:
        """Satellites whose pending samples the next commit takes: those past ``archive_max_packets`` or waiting for
        ARCHIVE_MAX_WAIT_S, then the longest waiting, ``archive_uploads_per_s`` × the interval of them (everything:
        all); ARCHIVE_MAX_GROUP at most."""
        waiting = sorted(self._pending, key=self._pending_since.__getitem__)
        if everything:
            return waiting[:ARCHIVE_MAX_GROUP]
        now = time.monotonic()
        urgent = [
            s
            for s in waiting
            if self._pending_packets[s] >= self._max_packets or now - self._pending_since[s] >= ARCHIVE_MAX_WAIT_S
        ]
        rest = [s for s in waiting if s not in urgent]
        return (urgent + rest[: max(self._uploads_per_flush - len(urgent), 0)])[:ARCHIVE_MAX_GROUP]

    def _commit(self, archive: Archive, uploads: list[PendingUpload]) -> list[IngestResult]:
        """One group commit, then ``on_committed`` with what it committed."""
        started = time.perf_counter()
        results = archive.ingest_many(uploads)
        self.stats.archive_commit_s = time.perf_counter() - started
        spans = []
        for u in uploads:
            times = [b.t_utc_ns for b in u.batches if len(b.t_utc_ns)]
            if times:
                spans.append((u.satellite, min(int(t.min()) for t in times), max(int(t.max()) for t in times)))
        started = time.perf_counter()
        self._after_commit(archive, spans, False)
        self.stats.after_commit_s = time.perf_counter() - started
        return results

    def _after_commit(self, archive: Archive, spans: list[tuple[str, int, int]], final: bool) -> None:
        if self._on_committed is None:
            return
        try:
            self._on_committed(archive, spans, final)
        except Exception:  # the samples are archived whatever the bookkeeping does
            log.exception("live stream: bookkeeping after a commit failed")

    def _note_backlog(self) -> None:
        now = time.monotonic()
        self.stats.archive_pending_packets = sum(self._pending_packets.values())
        self.stats.archive_pending_uploads = len(self._pending)
        self.stats.archive_oldest_pending_s = now - min(self._pending_since.values(), default=now)

    async def flush(self, everything: bool = False) -> bool:
        """Commit pending batches, one upload per satellite, in one transaction (failed ones kept for a retry):
        the satellites :meth:`_due` picks, or ``everything`` (up to ARCHIVE_MAX_GROUP of them); False if the
        commit failed."""
        if self._archive is None:
            return True
        async with self._flush_lock:
            self._note_backlog()
            due = self._due(everything)
            if not due:
                return True
            taken = {s: (self._pending.pop(s), self._pending_since.pop(s), self._pending_packets.pop(s)) for s in due}
            self._flush_count += 1
            uploads = [
                PendingUpload(
                    satellite,
                    [PacketBatch.from_sample_batch(b) for b in batches],
                    f"live:{satellite}:{time.time_ns()}:{self._flush_count}",
                    self._uploaded_by,
                    self._limits_of.get(satellite, self._own.limits),
                )
                for satellite, (batches, _, _) in taken.items()
            ]
            commit = asyncio.ensure_future(asyncio.to_thread(self._commit, self._archive, uploads))
            self._commits.add(commit)
            commit.add_done_callback(lambda done: self._committed(done, taken))
            try:  # cancelled here (stop cancels the flusher), the thread commits anyway and the callback counts it
                await asyncio.shield(commit)
            except Exception:
                return False
            return True

    def _committed(
        self, commit: asyncio.Future[list[IngestResult]], taken: dict[str, tuple[list[SampleBatch], float, int]]
    ) -> None:
        """Account for a group commit once its worker thread is done, whoever still waits for it: its packets counted
        as archived, or (the database may be away) its batches pending again ahead of newer ones, for a retry."""
        self._commits.discard(commit)
        error = commit.exception() if not commit.cancelled() else asyncio.CancelledError()
        if error is None:
            self.stats.packets_archived += sum(r.packets_accepted for r in commit.result())
        else:
            self.stats.archive_errors += 1
            self.stats.last_archive_error = repr(error)
            for satellite, (batches, since, packets) in taken.items():
                self._pending[satellite] = batches + self._pending.get(satellite, [])
                self._pending_since[satellite] = min(since, self._pending_since.get(satellite, since))
                self._pending_packets[satellite] = packets + self._pending_packets.get(satellite, 0)
        self._note_backlog()
