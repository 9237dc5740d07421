"""A misbehaving MQTT broker of the tests' own: the faults mosquitto never shows, on demand.

Brokers in the field were seen to answer every PINGREQ and never send a
PUBACK, and to refuse a subscription (SUBACK 0x80: EMQX and HiveMQ on an
ACL deny) while taking the connection and every publish; a broker that
never answers a SUBSCRIBE is the same stall one packet earlier. mosquitto does
neither, so :class:`MisbehavingBroker` does, over a real loopback socket:
an asyncio TCP server speaking just enough MQTT 3.1.1, parsed here with
code of its own (not the gateway's codec, which is what is under test):

- CONNECT: CONNACK 0; the connection is recorded (client id, keepalive,
  will), and so is how it ends (DISCONNECT, or the socket closed without
  one: a real broker then publishes the will).
- PINGREQ: always PINGRESP (it looks alive), each time recorded.
- PUBLISH: recorded; at QoS 1 a PUBACK (after ``puback_delay_s``) while
  :attr:`MisbehavingBroker.acknowledge` is true, else swallowed (its
  arrival time kept: when the stall began).
- SUBSCRIBE: SUBACK granting each filter the QoS asked, 0x80 for the
  filters in :attr:`MisbehavingBroker.refuse` (after ``suback_delay_s``),
  while :attr:`MisbehavingBroker.suback` is true; else swallowed, never
  answered (each filter and its arrival time kept). UNSUBSCRIBE: UNSUBACK.
  Right after a SUBACK granting a filter of :attr:`MisbehavingBroker.deliver`,
  its messages (QoS 0), as a broker relays a flood already under way.

Nothing else is delivered to the clients. Tests wait on :meth:`MisbehavingBroker.until`,
woken by each packet (a condition), never on a guessed time.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field

__all__ = ["Connection", "MisbehavingBroker", "misbehaving_broker"]


@dataclass
class Connection:
    """One client connection as the broker saw it."""

    client_id: str
    keepalive_s: int
    #: (topic, payload, retain) of the will, None without one.
    will: tuple[str, bytes, bool] | None
    opened_at: float
    #: (topic, payload, qos) of every PUBLISH, in order.
    publishes: list[tuple[str, bytes, int]] = field(default_factory=list)
    #: Loop time of the first QoS 1 PUBLISH left unacknowledged, None while every one was.
    first_swallowed_at: float | None = None
    #: (filter, qos asked, code answered) of every subscription.
    subscriptions: list[tuple[str, int, int]] = field(default_factory=list)
    #: (filter, loop time) of every subscription left unanswered (no SUBACK).
    swallowed: list[tuple[str, float]] = field(default_factory=list)
    #: Loop time of every PINGREQ (each answered).
    pings: list[float] = field(default_factory=list)
    #: The client sent DISCONNECT (a clean end: no will).
    disconnected: bool = False
    #: Loop time the socket ended, None while open.
    closed_at: float | None = None


@dataclass
class MisbehavingBroker:
    """See the module docstring; :func:`misbehaving_broker` starts one."""

    #: QoS 1 publishes get their PUBACK while this is true.
    acknowledge: bool = True
    #: How late each PUBACK goes (PINGREQs are answered at once meanwhile).
    puback_delay_s: float = 0.0
    #: Topic filters whose subscription is refused (SUBACK 0x80).
    refuse: set[str] = field(default_factory=set)
    #: SUBSCRIBEs get their SUBACK while this is true (else never: swallowed).
    suback: bool = True
    #: How late each SUBACK goes.
    suback_delay_s: float = 0.0
    #: Messages (topic, payload) sent at QoS 0 right after the SUBACK granting a filter.
    deliver: dict[str, list[tuple[str, bytes]]] = field(default_factory=dict)
    port: int = 0
    connections: list[Connection] = field(default_factory=list)
    #: Set on the way out: a connection that still arrives is closed at once.
    closing: bool = False
    _changed: asyncio.Condition = field(default_factory=asyncio.Condition)
    _writers: set[asyncio.StreamWriter] = field(default_factory=set)

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    async def until(
        self, predicate: Callable[[], object], what: str, *, timeout: float = 10.0
    ) -> None:
        """Return once *predicate* holds (checked at each packet); fail after *timeout* s."""
        try:
            async with asyncio.timeout(timeout), self._changed:
                await self._changed.wait_for(predicate)
        except TimeoutError:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}") from None

    def drop(self) -> None:
        """Close every client's socket (as a broker restart would): they reconnect."""
        for writer in list(self._writers):
            writer.transport.abort()

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """One client connection, until it ends."""
        loop = asyncio.get_running_loop()
        if self.closing:
            writer.transport.abort()
            return
        self._writers.add(writer)
        connection: Connection | None = None
        try:
            while True:
                first, body = await _read_packet(reader)
                kind = first >> 4
                if connection is None:
                    assert kind == 1, f"the first packet is not CONNECT: {first:#04x}"
                    connection = _connect(body, loop.time())
                    self.connections.append(connection)
                    writer.write(b"\x20\x02\x00\x00")
                elif kind == 3:  # PUBLISH
                    self._publish(connection, first, body, writer, loop.time())
                elif kind == 8:  # SUBSCRIBE
                    self._subscribe(connection, body, writer, loop.time())
                elif kind == 10:  # UNSUBSCRIBE
                    writer.write(b"\xb0\x02" + body[:2])
                elif kind == 12:  # PINGREQ
                    connection.pings.append(loop.time())
                    writer.write(b"\xd0\x00")
                elif kind == 14:  # DISCONNECT
                    connection.disconnected = True
                # PUBACK (4) never comes: nothing is delivered to a client.
                await writer.drain()
                await self._notify()
        except (asyncio.IncompleteReadError, ConnectionError):
            pass  # the client closed (or aborted) its socket
        finally:
            self._writers.discard(writer)
            if connection is not None:
                connection.closed_at = loop.time()
            writer.close()
            await self._notify()

    def _publish(
        self,
        connection: Connection,
        first: int,
        body: bytes,
        writer: asyncio.StreamWriter,
        now: float,
    ) -> None:
        qos = (first >> 1) & 3
        topic, at = _string(body, 0)
        packet_id = body[at : at + 2] if qos else b""
        connection.publishes.append((topic.decode(), body[at + len(packet_id) :], qos))
        if qos != 1:
            return
        if self.acknowledge:
            puback = b"\x40\x02" + packet_id
            if self.puback_delay_s:
                asyncio.get_running_loop().call_later(self.puback_delay_s, writer.write, puback)
            else:
                writer.write(puback)
        elif connection.first_swallowed_at is None:
            connection.first_swallowed_at = now

    def _subscribe(
        self, connection: Connection, body: bytes, writer: asyncio.StreamWriter, now: float
    ) -> None:
        codes = bytearray()
        relayed: list[bytes] = []
        at = 2
        while at < len(body):
            topic_filter, at = _string(body, at)
            qos = body[at]
            at += 1
            if not self.suback:
                connection.swallowed.append((topic_filter.decode(), now))
                continue
            code = 0x80 if topic_filter.decode() in self.refuse else qos
            connection.subscriptions.append((topic_filter.decode(), qos, code))
            codes.append(code)
            if code != 0x80:
                relayed += [
                    _publish_packet(t, p) for t, p in self.deliver.get(topic_filter.decode(), ())
                ]
        if not self.suback:
            return
        suback = bytes((0x90, 2 + len(codes))) + body[:2] + codes + b"".join(relayed)
        if self.suback_delay_s:
            asyncio.get_running_loop().call_later(self.suback_delay_s, writer.write, suback)
        else:
            writer.write(suback)


def _publish_packet(topic: str, payload: bytes) -> bytes:
    """PUBLISH at QoS 0."""
    name = topic.encode()
    size = 2 + len(name) + len(payload)
    length = bytearray()
    while True:
        size, digit = divmod(size, 128)
        length.append(digit | (0x80 if size else 0))
        if not size:
            break
    return b"\x30" + bytes(length) + struct.pack("!H", len(name)) + name + payload


def _string(data: bytes, at: int) -> tuple[bytes, int]:
    """A length-prefixed string at *at*, and where what follows it starts."""
    (length,) = struct.unpack_from("!H", data, at)
    return data[at + 2 : at + 2 + length], at + 2 + length


async def _read_packet(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    """One packet: its first byte and its body."""
    first = (await reader.readexactly(1))[0]
    length, shift = 0, 0
    while True:
        byte = (await reader.readexactly(1))[0]
        length |= (byte & 0x7F) << shift
        if not byte & 0x80:
            break
        shift += 7
    return first, await reader.readexactly(length)


def _connect(body: bytes, now: float) -> Connection:
    name, at = _string(body, 0)
    assert (name, body[at]) == (b"MQTT", 4), "not MQTT 3.1.1"
    flags = body[at + 1]
    (keepalive,) = struct.unpack_from("!H", body, at + 2)
    client_id, at = _string(body, at + 4)
    will = None
    if flags & 0x04:
        topic, at = _string(body, at)
        payload, at = _string(body, at)
        will = (topic.decode(), payload, bool(flags & 0x20))
    return Connection(client_id.decode(), keepalive, will, now)


@contextlib.asynccontextmanager
async def misbehaving_broker(
    *,
    acknowledge: bool = True,
    refuse: set[str] | None = None,
    puback_delay_s: float = 0.0,
    suback: bool = True,
    suback_delay_s: float = 0.0,
    deliver: dict[str, list[tuple[str, bytes]]] | None = None,
) -> AsyncIterator[MisbehavingBroker]:
    """A :class:`MisbehavingBroker` on a free loopback port; closed, clients and all, on exit."""
    broker = MisbehavingBroker(
        acknowledge,
        puback_delay_s,
        set(refuse or ()),
        suback=suback,
        suback_delay_s=suback_delay_s,
        deliver=dict(deliver or {}),
    )
    tasks: set[asyncio.Task[None]] = set()

    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        tasks.add(asyncio.current_task())  # type: ignore[arg-type]
        await broker.serve(reader, writer)

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    broker.port = server.sockets[0].getsockname()[1]
    try:
        yield broker
    finally:
        # Each connection ends by its socket's end, not by a cancellation: asyncio's
        # stream server logs a cancelled connection task as an error.
        broker.closing = True
        server.close()
        broker.drop()
        if tasks:
            _, stuck = await asyncio.wait(tasks, timeout=5)
            for task in stuck:
                task.cancel()
        await server.wait_closed()
