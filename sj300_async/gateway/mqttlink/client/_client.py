"""An asyncio MQTT 3.1.1 client made for publishing many small messages.

Why our own: at plant scale (2,048 drives at 1 Hz) the gateway publishes
thousands of messages a second, and aiomqtt 2 on paho cost 65-87 µs of CPU
per message (docs/BENCHMARKS.md, "plant"): more than the whole poll of a
drive. The alternatives measured were an alpha (aiomqtt 3, MQTT 5 only) and
gmqtt (no back-pressure on its writes); mqttproto is not on PyPI. A client
of MQTT 3.1.1's eleven packets over a sans-IO codec (:mod:`._packets`) is
small, and is shaped for the one job:

- **Writes are batched.** A publish encodes its packet and appends it to
  the connection's outgoing list; the list goes to the socket in one write
  per turn of the event loop. A burst of 256 publishes is one system call,
  not 256.
- **A batch is one awaitable.** :meth:`Client.publish_many` sends a list of
  messages and, at QoS 1, waits for all their PUBACKs on one future (no
  task, no coroutine per message). At most ``max_in_flight`` QoS 1
  messages are unacknowledged at once; the rest wait for a slot.
- **Back-pressure, not a queue.** While the socket does not take what is
  written (asyncio pauses the protocol above its high-water mark), every
  publish waits. A broker that stops reading is found by the keepalive:
  a PINGREQ goes out every ``keepalive_s / 2`` whatever else is sent, and
  one whose PINGRESP has not come within ``keepalive_s`` ends the
  connection (whatever else the broker sends meanwhile).
- **A PUBACK is due within the keepalive too.** A broker may answer every
  PINGREQ and never acknowledge a publish; the same tick ends the
  connection (:class:`PublishUnacknowledged`, without DISCONNECT: the will
  speaks) once the oldest QoS 1 publish in flight has waited
  ``keepalive_s`` (:mod:`._acks`). So is a SUBSCRIBE's SUBACK
  (:class:`SubscribeUnacknowledged`): a session subscribes before
  anything else, and hung there for ever.
- **Incoming messages are bounded.** Past ``max_queued_messages`` not yet
  taken by the reader (give or take one read of the socket, at most 256
  KiB), the connection stops reading the socket (TCP then holds the
  broker back) until half are taken. Meanwhile the broker's answers
  (PUBACK, SUBACK, PINGRESP) wait behind those messages too: a publish at
  QoS 1 finishes once the reader has caught up, and the keepalive judges
  the broker only while reading. A payload longer than
  ``max_publish_bytes`` is skipped unread as it arrives: the message is
  delivered with its first 256 bytes as ``payload`` and its whole
  ``length`` (so the application can refuse it as too long, quoting its
  start, as it would a long one it read), counted in ``oversized`` and
  logged at DEBUG with its topic excerpted.
- **QoS 1 received is acknowledged on receipt** (at-least-once: a message
  the application had not taken when the connection broke may come again).
- Leaving ``async with`` disconnects cleanly (DISCONNECT: the broker drops
  the will), whatever ended the block, as aiomqtt did: the callers publish
  what a will would say themselves before they leave.

Failures (refused or lost connections, time-outs, a broker breaking the
protocol) raise :class:`MqttError` (an unacknowledged publish or subscribe
its subclasses, which a session counts, :mod:`._types`); every waiting
publish, subscribe and reader gets it.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import math
import ssl
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from typing import Final, cast

from ._acks import PubackWatch, Request, unanswered
from ._packets import (
    CONNACK_REASONS,
    DISCONNECT,
    PINGREQ,
    ConnAck,
    MalformedPacket,
    Oversized,
    PacketParser,
    PingResp,
    PubAck,
    Publish,
    SubAck,
    UnsubAck,
    encode_connect,
    encode_puback,
    encode_publish,
    encode_subscribe,
    encode_unsubscribe,
)
from ._types import Message, MqttError, PublishUnacknowledged, Will

__all__ = ["MAX_IN_FLIGHT", "Client", "Message", "Will"]

_log = logging.getLogger("sj300_async.gateway.mqttlink.client")

#: How long a clean disconnect waits for the socket to take its last bytes.
CLOSE_TIMEOUT_S: Final = 2.0
#: Bytes gathered for one write at most: past it they go to the socket at once, so a
#: caller that publishes without ever yielding meets the transport's back-pressure.
FLUSH_BYTES: Final = 1 << 16
#: QoS 1 publishes unacknowledged at most: the packet identifiers are 65,535,
#: and subscriptions need some too.
MAX_IN_FLIGHT: Final = 65_000
#: The buffer each read of the socket fills at most (asyncio reads 256 KiB at a time).
READ_BYTES: Final = 1 << 18
#: How much of a topic a DEBUG line shows.
_EXCERPT: Final = 80


class _Batch:
    """QoS 1 messages published together, done when the last PUBACK comes."""

    __slots__ = ("future", "remaining", "written")

    def __init__(self, future: asyncio.Future[None]) -> None:
        self.future = future
        self.remaining = 0
        #: Loop time its last message was written (inf while it waits for a slot).
        self.written = math.inf


class _Protocol(asyncio.BufferedProtocol):
    """The connection's socket side: bytes in to the parser, batched bytes out.

    Read into one buffer of its own, reused (:data:`READ_BYTES`): a broker
    sending hundreds of MB a second (a flood of 300 KB payloads, skipped
    unread) then costs the copy from the kernel, not a fresh 256 KiB
    object per read (page faults included). The parser copies what it keeps.
    """

    def __init__(self, client: Client) -> None:
        self.client = client
        self._read = memoryview(bytearray(READ_BYTES))
        self.transport: asyncio.Transport | None = None
        self.out: list[bytes] = []
        self.out_bytes = 0
        self.lost: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not isinstance(): uvloop's transports implement the interface without
        # deriving from asyncio's classes.
        transport = cast(asyncio.Transport, transport)
        self.transport = transport

    def get_buffer(self, sizehint: int) -> memoryview:
        return self._read

    def buffer_updated(self, nbytes: int) -> None:
        self.client._received(self._read[:nbytes])

    def connection_lost(self, exc: Exception | None) -> None:
        self.client._lost(exc)
        if not self.lost.done():
            self.lost.set_result(None)

    def pause_writing(self) -> None:
        self.client._pause_writing()

    def resume_writing(self) -> None:
        self.client._resume_writing()


class Client:
    """One MQTT 3.1.1 connection, ``async with Client(...) as client:`` (module docstring)."""

    def __init__(
        self,
        host: str,
        port: int = 1883,
        *,
        identifier: str,
        username: str | None = None,
        password: str | None = None,
        tls: ssl.SSLContext | None = None,
        will: Will | None = None,
        clean_session: bool = True,
        keepalive_s: int = 60,
        max_in_flight: int = 256,
        max_queued_messages: int = 1000,
        max_publish_bytes: int = 1 << 20,
        connect_timeout_s: float = 10.0,
    ) -> None:
        if not 1 <= max_in_flight <= MAX_IN_FLIGHT or max_queued_messages < 2:
            raise ValueError(
                f"max_in_flight must be 1..{MAX_IN_FLIGHT} and max_queued_messages >= 2"
            )
        self.host, self.port = host, port
        self.identifier = identifier
        self._username, self._password = username, password
        self._tls = tls
        self._will = will
        self._clean_session = clean_session
        self.keepalive_s = keepalive_s
        self.max_in_flight = max_in_flight
        self.max_queued_messages = max_queued_messages
        self.connect_timeout_s = connect_timeout_s
        self._parser = PacketParser(max_publish_bytes=max_publish_bytes)
        self._protocol: _Protocol | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._error: MqttError | None = None  # set once the connection is over
        self._connack: asyncio.Future[ConnAck] | None = None
        self._flush_handle: asyncio.Handle | None = None
        self._writable: asyncio.Future[None] | None = None  # set while writing is paused
        self._slot: asyncio.Future[None] | None = None  # a waiter for an in-flight slot
        self._inflight: dict[int, _Batch] = {}
        self._acks: dict[int, Request[asyncio.Future[tuple[int, ...]]]] = {}
        # The last packet identifier given (the next is one more, 65535 wraps to 1): a
        # counter, not itertools.cycle, which keeps every value of its first pass (a list
        # and 65,535 ints, 2.5 MiB a client after as many QoS 1 messages; issue 44).
        self._last_id = 0
        self._messages: collections.deque[Message] = collections.deque()
        self._message_waiter: asyncio.Future[None] | None = None
        self._reading_paused = False
        self._keepalive: asyncio.TimerHandle | None = None
        self._ping_sent: float | None = None
        self._pubacks = PubackWatch(keepalive_s)
        self._subacks = PubackWatch(keepalive_s)  # the SUBSCRIBEs' (and UNSUBSCRIBEs')
        #: PUBLISH packets longer than ``max_publish_bytes``, skipped.
        self.oversized = 0

    # -- connecting ---------------------------------------------------------------------

    async def __aenter__(self) -> Client:
        loop = self._loop = asyncio.get_running_loop()
        self._connack = loop.create_future()
        protocol = _Protocol(self)
        try:
            async with asyncio.timeout(self.connect_timeout_s):
                await loop.create_connection(
                    lambda: protocol,
                    self.host,
                    self.port,
                    ssl=self._tls,
                    server_hostname=self.host if self._tls is not None else None,
                )
                self._protocol = protocol
                will = self._will
                self._write(
                    encode_connect(
                        self.identifier,
                        keepalive_s=self.keepalive_s,
                        clean_session=self._clean_session,
                        username=self._username,
                        password=self._password,
                        will=None
                        if will is None
                        else (
                            will.topic,
                            will.payload.encode()
                            if isinstance(will.payload, str)
                            else will.payload,
                            will.qos,
                            will.retain,
                        ),
                    )
                )
                connack = await self._connack
        except TimeoutError:
            self._abort()
            raise MqttError(
                f"no answer from {self.host}:{self.port} within {self.connect_timeout_s:g} s"
            ) from None
        except (OSError, ValueError) as exc:  # ssl.SSLError is an OSError; a bad host name
            self._abort()  # a UnicodeError (IDNA), a ValueError
            raise MqttError(str(exc) or type(exc).__name__) from exc
        except BaseException:
            self._abort()
            raise
        if connack.return_code:
            self._abort()
            reason = CONNACK_REASONS.get(connack.return_code, "unknown reason")
            raise MqttError(f"connection refused ({connack.return_code}): {reason}")
        if self._error is not None:  # what came with the CONNACK broke the connection
            self._abort()
            raise self._error
        if self.keepalive_s:
            self._keepalive = loop.call_later(self.keepalive_s / 2, self._tick)
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        protocol = self._protocol
        if protocol is None or protocol.transport is None:
            return
        if self._error is not None:
            return
        self._write(DISCONNECT)
        self._flush()
        self._lost(None, "disconnected")  # what still waits hears that, not "lost"
        protocol.transport.close()
        try:
            async with asyncio.timeout(CLOSE_TIMEOUT_S):
                await asyncio.shield(protocol.lost)
        except TimeoutError:
            pass
        finally:  # the socket is closed even when this wait is cancelled
            if not protocol.lost.done():
                protocol.transport.abort()

    def _abort(self) -> None:
        protocol = self._protocol
        if protocol is not None and protocol.transport is not None:
            protocol.transport.abort()
        self._lost(None, "the connection was not made")

    # -- publishing ---------------------------------------------------------------------

    async def publish(
        self, topic: str, payload: bytes | str, *, qos: int = 0, retain: bool = False
    ) -> None:
        """Publish one message; at QoS 1, return once the broker acknowledged it."""
        data = payload.encode() if isinstance(payload, str) else payload
        await self.publish_many(((topic, data, retain),), qos=qos)

    async def publish_many(
        self, messages: Iterable[tuple[str, bytes, bool]], *, qos: int = 0
    ) -> None:
        """Publish (topic, payload, retain) messages in order; at QoS 1, until all are acknowledged.

        Raises:
            MqttError: the connection is lost (at QoS 1, some may have reached the broker).
        """
        if qos not in (0, 1):
            raise ValueError(f"QoS {qos} is not supported (0 or 1)")
        if self._error is not None:
            raise self._error
        if qos == 0:
            write = self._write
            for topic, payload, retain in messages:
                write(encode_publish(topic.encode(), payload, retain=retain))
            if self._writable is not None:
                await self._wait_writable()
            return
        assert self._loop is not None
        batch = _Batch(self._loop.create_future())
        inflight = self._inflight
        limit = self.max_in_flight
        for topic, payload, retain in messages:
            while len(inflight) >= limit:
                await self._wait_slot()
            packet_id = self._next_id()
            inflight[packet_id] = batch
            batch.remaining += 1
            self._write(
                encode_publish(topic.encode(), payload, qos=1, retain=retain, packet_id=packet_id)
            )
        batch.written = self._loop.time()
        if self._writable is not None:
            await self._wait_writable()
        if batch.remaining:
            await batch.future

    def _next_id(self) -> int:
        packet_id = self._last_id
        for _ in range(0xFFFF):
            packet_id = packet_id % 0xFFFF + 1
            if packet_id not in self._inflight and packet_id not in self._acks:
                self._last_id = packet_id
                return packet_id
        # Only subscriptions never acknowledged, past the in-flight cap, get here.
        raise MqttError("every packet identifier is waiting for an acknowledgement")

    async def _wait_slot(self) -> None:
        if self._error is not None:
            raise self._error
        if self._slot is None:
            assert self._loop is not None
            self._slot = self._loop.create_future()
        await asyncio.shield(self._slot)

    async def _wait_writable(self) -> None:
        while self._writable is not None:
            await asyncio.shield(self._writable)
        if self._error is not None:
            raise self._error

    # -- subscribing --------------------------------------------------------------------

    async def subscribe(
        self, filters: str | Sequence[tuple[str, int]], *, qos: int = 0
    ) -> tuple[int, ...]:
        """Subscribe; the QoS granted per filter (0x80: refused)."""
        pairs = [(filters, qos)] if isinstance(filters, str) else list(filters)
        packet = partial(encode_subscribe, filters=pairs)
        return await self._acknowledged(packet, "SUBSCRIBE", ", ".join(f for f, _ in pairs))

    async def unsubscribe(self, filters: str | Sequence[str]) -> None:
        names = [filters] if isinstance(filters, str) else list(filters)
        await self._acknowledged(partial(encode_unsubscribe, filters=names), "UNSUBSCRIBE",
                                 ", ".join(names))  # fmt: skip

    async def _acknowledged(
        self, packet: Callable[[int], bytes], name: str, filters: str
    ) -> tuple[int, ...]:
        if self._error is not None:
            raise self._error
        assert self._loop is not None
        packet_id = self._next_id()
        future: asyncio.Future[tuple[int, ...]] = self._loop.create_future()
        # The id stays taken until its acknowledgement comes (or the connection ends),
        # even for a caller that stopped waiting: a late one must not answer another.
        self._acks[packet_id] = Request(future, self._loop.time(), name, filters)
        self._write(packet(packet_id))
        return await future

    # -- receiving ----------------------------------------------------------------------

    @property
    def messages(self) -> Client:
        """``async for message in client.messages``: until the connection is lost (MqttError)."""
        return self

    def __aiter__(self) -> Client:
        return self

    async def __anext__(self) -> Message:
        while not self._messages:
            if self._error is not None:
                raise self._error
            assert self._loop is not None
            if self._message_waiter is not None:
                raise RuntimeError("one task at a time reads a client's messages")
            self._message_waiter = self._loop.create_future()
            try:
                await self._message_waiter
            finally:
                self._message_waiter = None
        message = self._messages.popleft()
        if self._reading_paused and len(self._messages) <= self.max_queued_messages // 2:
            self._reading_paused = False
            if self._loop is not None:  # the broker's answers are judged from now on
                now = self._loop.time()
                if self._ping_sent is not None:
                    self._ping_sent = now
                self._pubacks.hold(now)
                self._subacks.hold(now)
            protocol = self._protocol
            if protocol is not None and protocol.transport is not None and self._error is None:
                protocol.transport.resume_reading()
        return message

    # -- the socket's side --------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        protocol = self._protocol
        if protocol is None or self._error is not None:
            raise self._error or MqttError("not connected")
        protocol.out.append(data)
        protocol.out_bytes += len(data)
        if protocol.out_bytes >= FLUSH_BYTES:
            self._flush()
        elif self._flush_handle is None:
            assert self._loop is not None
            self._flush_handle = self._loop.call_soon(self._flush)

    def _flush(self) -> None:
        if self._flush_handle is not None:
            self._flush_handle.cancel()
            self._flush_handle = None
        protocol = self._protocol
        if protocol is None or protocol.transport is None or not protocol.out:
            return
        out = protocol.out
        data = out[0] if len(out) == 1 else b"".join(out)
        out.clear()
        protocol.out_bytes = 0
        if not protocol.transport.is_closing():
            protocol.transport.write(data)

    def _pause_writing(self) -> None:
        if self._writable is None and self._loop is not None:
            self._writable = self._loop.create_future()

    def _resume_writing(self) -> None:
        waiter, self._writable = self._writable, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _received(self, data: bytes | memoryview) -> None:
        try:
            packets = self._parser.feed(data)
        except MalformedPacket as exc:
            self._fail(MqttError(f"the broker broke MQTT 3.1.1: {exc}"))
            return
        for packet in packets:
            if isinstance(packet, PubAck):
                self._puback(packet.packet_id)
            elif isinstance(packet, Publish):
                self._publish_received(packet)
            elif isinstance(packet, SubAck | UnsubAck):
                request = self._acks.pop(packet.packet_id, None)
                future = None if request is None else request.future
                if future is not None and not future.done():
                    future.set_result(packet.return_codes if isinstance(packet, SubAck) else ())
            elif isinstance(packet, ConnAck):
                if self._connack is not None and not self._connack.done():
                    self._connack.set_result(packet)
                else:
                    self._fail(MqttError("the broker broke MQTT 3.1.1: a second CONNACK"))
                    return
            elif isinstance(packet, Oversized):
                self.oversized += 1
                _log.debug(
                    "MQTT: a message of %d bytes on %r skipped (limit %d)",
                    packet.length,
                    packet.topic[:_EXCERPT],
                    self._parser.max_publish_bytes,
                )
                if packet.packet_id is not None:
                    self._write(encode_puback(packet.packet_id))
                self._deliver(
                    Message(packet.topic, packet.head, packet.qos, packet.retain, packet.length)
                )
            elif isinstance(packet, PingResp):
                # Only the answer to the PINGREQ counts: a broker that stopped reading
                # may go on sending.
                self._ping_sent = None
            else:  # pragma: no cover - the parser's types
                raise AssertionError(packet)

    def _puback(self, packet_id: int) -> None:
        batch = self._inflight.pop(packet_id, None)
        if batch is None:
            _log.debug("MQTT: PUBACK for packet %d, which is not in flight: ignored", packet_id)
            return
        batch.remaining -= 1
        if not batch.remaining and not batch.future.done():
            batch.future.set_result(None)
        slot, self._slot = self._slot, None
        if slot is not None and not slot.done():
            slot.set_result(None)

    def _publish_received(self, packet: Publish) -> None:
        if packet.packet_id is not None:
            self._write(encode_puback(packet.packet_id))
        payload = packet.payload
        self._deliver(Message(packet.topic, payload, packet.qos, packet.retain, len(payload)))

    def _deliver(self, message: Message) -> None:
        self._messages.append(message)
        waiter = self._message_waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)
        if not self._reading_paused and len(self._messages) >= self.max_queued_messages:
            protocol = self._protocol
            if protocol is not None and protocol.transport is not None:
                self._reading_paused = True
                protocol.transport.pause_reading()

    def _tick(self) -> None:
        """Every keepalive_s / 2: a PINGREQ, or the end of a broker that did not answer one."""
        assert self._loop is not None
        now = self._loop.time()
        if self._reading_paused:
            # The answer may be waiting behind the messages the reader has not taken:
            # the broker's silence is judged once reading goes on.
            if self._ping_sent is not None:
                self._ping_sent = now
            self._pubacks.hold(now)
            self._subacks.hold(now)
        elif self._ping_sent is not None and now - self._ping_sent >= self.keepalive_s:
            self._fail(MqttError(f"no answer from the broker within {self.keepalive_s} s"))
            return
        elif (overdue := self._pubacks.overdue(now, self._inflight)) is not None:
            packet_id, waited = overdue
            self._fail(PublishUnacknowledged(
                f"no PUBACK for {waited:.1f} s (keepalive_s {self.keepalive_s}): QoS 1 publish, "
                f"packet {packet_id} of client {self.identifier}, the oldest of "
                f"{len(self._inflight)} waiting"))  # fmt: skip
            return
        elif (late := self._subacks.overdue(now, self._acks)) is not None:
            self._fail(unanswered(*late, self._acks, keepalive_s=self.keepalive_s,
                                  client=self.identifier))  # fmt: skip
            return
        if self._ping_sent is None:
            self._ping_sent = now
            self._write(PINGREQ)
        self._keepalive = self._loop.call_later(self.keepalive_s / 2, self._tick)

    def _fail(self, error: MqttError) -> None:
        """End the connection with *error* (the broker broke the protocol, or went quiet)."""
        protocol = self._protocol
        self._lost(None, error=error)
        if protocol is not None and protocol.transport is not None:
            protocol.transport.abort()

    def _lost(
        self, exc: Exception | None, why: str = "connection lost", *, error: MqttError | None = None
    ) -> None:
        """The connection is over: every waiter gets the error, once."""
        if self._error is not None:
            return
        if error is None:
            error = MqttError(f"{why}: {exc}" if exc is not None else why)
        self._error = error
        if self._keepalive is not None:
            self._keepalive.cancel()
            self._keepalive = None
        if self._flush_handle is not None:
            self._flush_handle.cancel()
            self._flush_handle = None
        batches, self._inflight = list(self._inflight.values()), {}
        acks, self._acks = [request.future for request in self._acks.values()], {}
        futures: list[asyncio.Future[None] | None] = [batch.future for batch in batches]
        futures += [self._slot, self._writable, self._message_waiter]
        for future in (*futures, self._connack, *acks):
            if future is not None and not future.done():
                future.set_exception(error)
                future.exception()  # retrieved: a waiter may have gone (cancelled)
