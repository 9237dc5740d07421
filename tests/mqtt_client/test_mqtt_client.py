"""The gateway's MQTT client against a real mosquitto, and against scripted brokers for what
mosquitto never does (refuse a CONNACK, stop reading, hold PUBACKs back or never send them,
break the protocol).

What the client publishes is checked by another implementation (aiomqtt on
paho); what it receives comes from ``mosquitto_pub``.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import ssl
import subprocess
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path

import aiomqtt
import pytest
from mqtt_broker import Broker, running_broker, tool
from mqtt_misbehaving import misbehaving_broker
from transports.bridges import wait_for_port
from waiting import wait_for

from sj300_async.gateway.mqttlink.client import (
    Client,
    Message,
    MqttError,
    PublishUnacknowledged,
    SubscribeUnacknowledged,
    Will,
)
from sj300_async.gateway.mqttlink.client._acks import PubackWatch
from sj300_async.gateway.mqttlink.client._packets import PacketParser, encode_publish


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


@contextlib.asynccontextmanager
async def watching(broker: Broker, topic: str) -> AsyncIterator[list[aiomqtt.Message]]:
    """An independent subscriber (aiomqtt) to *topic*, collecting what it receives."""
    got: list[aiomqtt.Message] = []
    async with aiomqtt.Client("127.0.0.1", broker.port, identifier="watcher") as sub:
        await sub.subscribe(topic, qos=1)

        async def collect() -> None:
            async for message in sub.messages:
                got.append(message)

        task = asyncio.create_task(collect())
        try:
            yield got
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


def client(broker: Broker, **kwargs: object) -> Client:
    return Client("127.0.0.1", broker.port, identifier="under-test", **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("qos", [0, 1])
async def test_a_burst_arrives_whole_and_in_order(broker: Broker, qos: int) -> None:
    messages = [(f"t/{i % 7}", f"m{i}".encode(), False) for i in range(3000)]
    async with watching(broker, "t/#") as got, client(broker, max_in_flight=64) as c:
        # In bursts of 500: mosquitto drops QoS 1 messages past a slow subscriber's
        # queue of 1000 (max_queued_messages), and the watcher is the slow one.
        for end in range(500, len(messages) + 1, 500):
            await c.publish_many(messages[end - 500 : end], qos=qos)
            await wait_for(lambda n=end: len(got) >= n, "the burst at the subscriber")  # type: ignore[misc]
    assert [(m.topic.value, m.payload) for m in got] == [(t, p) for t, p, _ in messages]


async def test_retain_and_a_large_payload(broker: Broker) -> None:
    big = bytes(range(256)) * 400  # 102,400 bytes: a three-byte remaining length
    async with client(broker) as c:
        await c.publish("keep/a", big, qos=1, retain=True)
        await c.publish("keep/b", "text", retain=True)
    async with watching(broker, "keep/#") as got:
        await wait_for(lambda: len(got) == 2, "both retained messages")
    assert {m.topic.value: (m.payload, m.retain) for m in got} == {
        "keep/a": (big, True),
        "keep/b": (b"text", True),
    }


async def test_subscribed_messages_arrive_and_qos1_is_acknowledged(broker: Broker) -> None:
    async with client(broker) as c:
        assert await c.subscribe([("in/#", 1), ("other", 0)]) == (1, 0)
        for i in range(5):
            await broker.publish(f"in/{i}", f"v{i}")  # mosquitto_pub, QoS 1
        received: list[Message] = []
        async for message in c.messages:
            received.append(message)
            if len(received) == 5:
                break
        await c.unsubscribe("in/#")
        await broker.publish("in/late", "x")
        await c.publish("other", b"mine")  # something after the unsubscribe
        late = await anext(c.messages)
    assert [(m.topic, m.payload, m.qos) for m in received] == [
        (f"in/{i}", f"v{i}".encode(), 1) for i in range(5)
    ]
    assert late.topic == "other"  # nothing from in/late came


async def test_the_will_is_published_when_the_connection_dies_not_when_it_ends(
    broker: Broker,
) -> None:
    will = Will("gw/availability", "offline", qos=1, retain=False)
    async with watching(broker, "gw/availability") as got:
        async with client(broker, will=will):
            pass  # a clean end: DISCONNECT, no will
        async with client(broker, will=will) as c:
            protocol = c._protocol
            assert protocol is not None
            assert protocol.transport is not None
            protocol.transport.abort()  # the socket dies as in a crash
            await wait_for(lambda: c._error is not None, "the connection lost")
            with pytest.raises(MqttError):
                await c.publish("probe", b"")
        await wait_for(lambda: len(got) == 1, "the will")
        # A clean end before would have shown here as a second message.
        await broker.publish("gw/availability", "marker")
        await wait_for(lambda: len(got) == 2, "the marker")
    assert [m.payload for m in got] == [b"offline", b"marker"]


async def test_a_stopped_broker_fails_every_waiter(broker: Broker) -> None:
    async with client(broker) as c:
        await c.subscribe("x", qos=1)
        reader = asyncio.create_task(anext(c.messages))
        await asyncio.sleep(0)
        await broker.stop()
        with pytest.raises(MqttError, match="connection lost"):
            await reader
        with pytest.raises(MqttError):
            await c.publish("x", b"after", qos=1)


async def test_tls_with_the_brokers_ca(broker: Broker, tmp_path: Path) -> None:
    ca, key, cert = _certificates(tmp_path)
    await broker.stop()
    port = broker.port
    conf = tmp_path / "tls.conf"
    conf.write_text(
        f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
        f"cafile {ca}\ncertfile {cert}\nkeyfile {key}\n"
        # Run as root (as tests here are), mosquitto drops to its own user, which
        # cannot read the key in the test's private directory: it stays root.
        "user root\n",
        encoding="utf-8",
    )
    proc = await asyncio.create_subprocess_exec(
        tool("mosquitto"), "-c", str(conf), stderr=asyncio.subprocess.DEVNULL
    )
    try:
        trusting = ssl.create_default_context(cafile=str(ca))
        await wait_for_port(port)
        async with Client("localhost", port, identifier="tls", tls=trusting) as c:
            assert await c.subscribe("secure", qos=1) == (1,)
            await c.publish("secure", b"over TLS", qos=1)
            message = await anext(c.messages)
        assert message.payload == b"over TLS"
        with pytest.raises(MqttError, match="CERTIFICATE_VERIFY_FAILED"):
            async with Client(
                "localhost", port, identifier="untrusting", tls=ssl.create_default_context()
            ):
                pass
    finally:
        proc.terminate()
        await proc.wait()


def _certificates(directory: Path) -> tuple[Path, Path, Path]:
    """A CA and a server certificate for localhost, made by openssl."""
    ca_key, ca, key, csr, cert = (
        directory / n for n in ("ca.key", "ca.pem", "s.key", "s.csr", "s.pem")
    )

    def run(*args: str) -> None:
        subprocess.run(["openssl", *args], check=True, capture_output=True)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", str(ca_key), "-out", str(ca),
        "-days", "2", "-subj", "/CN=test CA")  # fmt: skip
    run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", str(key), "-out", str(csr),
        "-subj", "/CN=localhost")  # fmt: skip
    ext = directory / "ext.cnf"
    ext.write_text("subjectAltName=DNS:localhost\n", encoding="utf-8")
    run("x509", "-req", "-in", str(csr), "-CA", str(ca), "-CAkey", str(ca_key),
        "-CAcreateserial", "-out", str(cert), "-days", "2", "-extfile", str(ext))  # fmt: skip
    return ca, key, cert


# -- scripted brokers -------------------------------------------------------------------

Script = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


@contextlib.asynccontextmanager
async def scripted(script: Script) -> AsyncIterator[int]:
    """A TCP server on a free loopback port that runs *script* for each connection."""
    tasks: set[asyncio.Task[None]] = set()

    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        tasks.add(asyncio.current_task())  # type: ignore[arg-type]
        try:
            await script(reader, writer)
        finally:
            writer.close()

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        for task in tasks:
            task.cancel()
        server.close()
        await server.wait_closed()


async def _read_connect(reader: asyncio.StreamReader) -> None:
    first = await reader.readexactly(2)
    assert first[0] == 0x10
    await reader.readexactly(first[1])


@pytest.mark.parametrize(
    ("code", "says"), [(4, "user name or password"), (5, "did not authorize"), (9, "unknown")]
)
async def test_a_refused_connection_says_why(code: int, says: str) -> None:
    async def refuse(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _read_connect(reader)
        writer.write(bytes((0x20, 2, 0, code)))
        await reader.read()

    async with scripted(refuse) as port:
        with pytest.raises(MqttError, match=f"refused \\({code}\\): .*{says}"):
            async with Client("127.0.0.1", port, identifier="c"):
                pass


async def test_a_silent_broker_times_the_connect_out() -> None:
    async def silent(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.read()

    async with scripted(silent) as port:
        with pytest.raises(MqttError, match=r"no answer .* within 0\.2 s"):
            async with Client("127.0.0.1", port, identifier="c", connect_timeout_s=0.2):
                pass


async def test_nobody_listening_is_an_mqtt_error() -> None:
    async def nothing(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        pass

    async with scripted(nothing) as port:
        pass  # closed: nobody listens on the port now
    with pytest.raises(MqttError, match="Connect call failed"):
        async with Client("127.0.0.1", port, identifier="c"):
            pass


async def test_no_more_than_max_in_flight_wait_for_their_puback() -> None:
    """The scripted broker holds PUBACKs back and counts what arrives meanwhile."""
    window = 8
    most = 0

    async def slow_acks(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        nonlocal most
        await _read_connect(reader)
        writer.write(b"\x20\x02\x00\x00")
        parser = PacketParser()
        unacked: list[int] = []
        while True:
            data = await reader.read(65536)
            if not data:
                return
            for packet in parser.feed(data):  # PUBLISH parses the same both ways
                assert packet.packet_id is not None  # type: ignore[union-attr]
                unacked.append(packet.packet_id)  # type: ignore[union-attr]
            most = max(most, len(unacked))
            await asyncio.sleep(0.005)  # the acknowledgements come late
            for packet_id in unacked:
                writer.write(b"\x40\x02" + packet_id.to_bytes(2, "big"))
            unacked.clear()

    async with (
        scripted(slow_acks) as port,
        Client("127.0.0.1", port, identifier="c", max_in_flight=window) as c,
    ):
        await c.publish_many([("t", b"x", False)] * 200, qos=1)
    assert most == window


async def test_a_broker_that_stops_reading_is_found_by_the_keepalive() -> None:
    async def deaf(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _read_connect(reader)
        writer.write(b"\x20\x02\x00\x00")
        await asyncio.sleep(3600)  # never reads again: the socket's buffers fill up

    async def publish_for_ever(c: Client) -> None:
        chunk = [("t", b"x" * 60_000, False)] * 20
        while True:  # waits, paused, once the buffers are full
            await c.publish_many(chunk)

    async with (
        scripted(deaf) as port,
        Client("127.0.0.1", port, identifier="c", keepalive_s=1) as c,
    ):
        with pytest.raises(MqttError, match="no answer from the broker within 1 s"):
            await publish_for_ever(c)


async def test_a_broker_breaking_the_protocol_ends_the_connection() -> None:
    async def broken(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _read_connect(reader)
        writer.write(b"\x20\x02\x00\x00")
        await reader.readexactly(2)  # something the client sent
        writer.write(b"\x50\x02\x00\x01")  # PUBREC: QoS 2, which it never spoke
        await reader.read()

    async with (
        scripted(broken) as port,
        Client("127.0.0.1", port, identifier="c", keepalive_s=0) as c,
    ):
        with pytest.raises(MqttError, match=r"broke MQTT 3\.1\.1: packet type PUBREC"):
            await c.subscribe("x")


async def test_an_oversized_payload_is_skipped_and_delivered_with_its_length(
    broker: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level("DEBUG", "sj300_async.gateway.mqttlink.client")
    async with Client("127.0.0.1", broker.port, identifier="c", max_publish_bytes=1000) as c:
        await c.subscribe("big/#", qos=1)
        await broker.publish("big/one", b"y" * 5000)
        await broker.publish("big/two", "small")
        big, small = await anext(c.messages), await anext(c.messages)
        assert c.oversized == 1
        # Acknowledged: the broker kept no QoS 1 message waiting for this session.
        await c.publish("big/three", b"after", qos=1)
        assert (await anext(c.messages)).payload == b"after"
    assert (big.topic, big.payload, big.length, big.skipped) == ("big/one", b"y" * 256, 5000, True)
    assert (small.payload, small.length, small.skipped) == (b"small", 5, False)
    assert "a message of 5000 bytes on 'big/one' skipped (limit 1000)" in caplog.text


# -- what the adversarial review found ----------------------------------------------------


async def _connack(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    await _read_connect(reader)
    writer.write(b"\x20\x02\x00\x00")


async def test_a_broker_that_stops_reading_but_goes_on_sending_is_found() -> None:
    """Only a PINGRESP answers a PINGREQ: other packets do not show the broker reading."""

    async def talking(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _connack(reader, writer)
        while True:  # never reads again, and publishes on
            writer.write(encode_publish(b"news", b"x"))
            await asyncio.sleep(0.1)

    async with (
        scripted(talking) as port,
        Client("127.0.0.1", port, identifier="c", keepalive_s=1) as c,
    ):
        with pytest.raises(MqttError, match="no answer from the broker within 1 s"):
            async for _ in c.messages:
                pass


async def test_a_slow_reader_does_not_make_a_healthy_broker_look_dead(broker: Broker) -> None:
    """Reading paused (the reader is behind): the PINGRESP waits, and is judged later."""
    async with Client(
        "127.0.0.1", broker.port, identifier="c", keepalive_s=1, max_queued_messages=10
    ) as c:
        await c.subscribe("many", qos=1)
        await c.publish_many([("many", b"x", False)] * 50)
        await wait_for(lambda: c._reading_paused, "reading paused")
        loop = asyncio.get_running_loop()
        until = loop.time() + 2.5  # two and a half keepalives behind
        while loop.time() < until:
            await asyncio.sleep(0.1)
        taken = [await anext(c.messages) for _ in range(50)]
        await c.publish("many", b"still connected", qos=1)
        assert (await anext(c.messages)).payload == b"still connected"
    assert len(taken) == 50


async def test_a_cancelled_exit_still_closes_the_socket() -> None:
    async def deaf(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _connack(reader, writer)
        await asyncio.sleep(3600)

    async with scripted(deaf) as port:
        c = Client("127.0.0.1", port, identifier="c")
        await c.__aenter__()
        filling = asyncio.create_task(c.publish_many([("t", b"x" * 60_000, False)] * 400))
        await wait_for(lambda: c._writable is not None, "the socket's buffers full")
        exiting = asyncio.create_task(c.__aexit__(None, None, None))
        # Past the DISCONNECT: the connection is over, the socket's close still waits.
        await wait_for(lambda: c._error is not None, "the exit under way")
        exiting.cancel()
        with pytest.raises(asyncio.CancelledError):
            await exiting
        protocol = c._protocol
        assert protocol is not None
        assert protocol.transport is not None
        assert protocol.transport.is_closing()
        await asyncio.wait_for(protocol.lost, 1)  # aborted: closed at once
        with pytest.raises(MqttError, match="disconnected"):
            await filling


async def test_a_second_connack_in_the_same_read_fails_the_connect() -> None:
    async def twice(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _read_connect(reader)
        writer.write(b"\x20\x02\x00\x00" * 2)
        await reader.read()

    async with scripted(twice) as port:
        with pytest.raises(MqttError, match="a second CONNACK"):
            async with Client("127.0.0.1", port, identifier="c"):
                pass


async def test_packet_identifiers_are_never_exhausted_silently() -> None:
    with pytest.raises(ValueError, match=r"max_in_flight must be 1\.\.65000"):
        Client("h", identifier="c", max_in_flight=65_535)


async def test_a_cancelled_subscribe_keeps_its_identifier_until_answered() -> None:
    """Else its late SUBACK would answer the next request given the same identifier."""
    subacks: list[bytes] = []

    async def late(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _connack(reader, writer)
        first = await reader.readexactly(2)
        packet = await reader.readexactly(first[1])
        subacks.append(packet[:2])
        await asyncio.sleep(3600)  # never answers

    async with scripted(late) as port, Client("127.0.0.1", port, identifier="c") as c:
        with pytest.raises(TimeoutError):
            async with asyncio.timeout(0.2):
                await c.subscribe("x", qos=1)
        assert len(subacks) == 1
        taken = int.from_bytes(subacks[0], "big")
        c._last_id = taken - 1  # the next one is taken: the one after it is given
        assert c._next_id() == taken + 1


async def test_packet_identifiers_wrap_from_65535_to_1_past_those_in_flight() -> None:
    """One counter, nothing kept per identifier given (itertools.cycle kept all 65,535)."""
    c = Client("h", identifier="c")
    c._last_id = 0xFFFE
    assert c._next_id() == 0xFFFF
    c._inflight[1] = c._inflight[2] = object()  # type: ignore[assignment]
    assert c._next_id() == 3
    assert c._next_id() == 4


async def test_one_task_reads_the_messages() -> None:
    async with (
        scripted(lambda r, w: _connack_and_wait(r, w)) as port,
        Client("127.0.0.1", port, identifier="c") as c,
    ):
        first = asyncio.create_task(anext(c.messages))
        await asyncio.sleep(0)
        with pytest.raises(RuntimeError, match="one task at a time"):
            await anext(c.messages)
        first.cancel()


async def _connack_and_wait(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    await _connack(reader, writer)
    await reader.read()


async def test_a_host_name_that_cannot_be_one_is_an_mqtt_error() -> None:
    with pytest.raises(MqttError):
        async with Client("bad..host", 1883, identifier="c", connect_timeout_s=5):
            pass


async def test_a_flood_of_oversized_payloads_is_read_into_one_buffer_of_its_own() -> None:
    """30 MB of 300 KB payloads past max_publish_bytes: skipped as they come, each read of the
    socket into the protocol's one reused buffer. Before, each read was a fresh 256 KiB
    object, about one page fault per 6 KB read: 2.1-2.5 times the CPU per MB of a flood."""
    resource = pytest.importorskip("resource")
    count, size = 100, 300_000
    stream = memoryview(b"".join(encode_publish(b"set/x", b"x" * size) for _ in range(count)))

    async def flood(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await _connack(reader, writer)
        for at in range(0, len(stream), 1 << 16):  # drained: the sender's buffer stays small
            writer.write(stream[at : at + (1 << 16)])
            await writer.drain()
        await reader.read()

    async with (
        scripted(flood) as port,
        Client("127.0.0.1", port, identifier="c", max_publish_bytes=4096) as c,
    ):
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        got = [await anext(c.messages) for _ in range(count)]
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
    assert c.oversized == count
    assert all(m.length == size and m.skipped for m in got)
    assert faults < 1000, faults  # fresh buffers: about 4,500


async def test_a_broker_that_answers_pings_but_never_acknowledges_ends_the_connection() -> None:
    """The keepalive judges PUBACKs too: pings answered do not keep a stalled publish alive."""
    async with misbehaving_broker(acknowledge=False) as broker:
        c = Client("127.0.0.1", broker.port, identifier="c", keepalive_s=1)
        async with c, asyncio.timeout(10):  # a hang fails, not at the suite's time-out
            with pytest.raises(PublishUnacknowledged) as raised:
                await c.publish_many([("t/a", b"1", False), ("t/b", b"2", False)], qos=1)
        await broker.until(lambda: broker.connections[0].closed_at is not None, "the end")
    (seen,) = broker.connections
    assert seen.first_swallowed_at is not None
    assert seen.closed_at is not None
    stalled_s = seen.closed_at - seen.first_swallowed_at
    assert 0.9 <= stalled_s <= 2.25, stalled_s  # keepalive_s to 1.5 keepalive_s, and slack
    assert any(t > seen.first_swallowed_at for t in seen.pings)  # answered meanwhile
    assert not seen.disconnected  # aborted: a real broker publishes the will
    text = str(raised.value)
    assert "no PUBACK for 1." in text
    assert "keepalive_s 1" in text
    assert "of client c, the oldest of 2 waiting" in text


async def test_publishes_acknowledged_slowly_but_within_the_keepalive_keep_the_connection() -> None:
    """Publishes always in flight for 1.5 keepalives, each acknowledged in time: no stall."""
    async with (
        misbehaving_broker(puback_delay_s=0.25) as broker,
        Client("127.0.0.1", broker.port, identifier="c", keepalive_s=1, max_in_flight=2) as c,
    ):
        # Two at a time, each PUBACK 0.25 s late: 1.5 s with some always unacknowledged.
        await c.publish_many([(f"t/{n}", b"x", False) for n in range(12)], qos=1)
        await c.publish("t/last", b"x", qos=1)
    (seen,) = broker.connections
    assert len(seen.publishes) == 13
    assert seen.pings  # the keepalive ran meanwhile
    assert seen.disconnected


async def test_a_broker_that_never_answers_a_subscribe_ends_the_connection() -> None:
    """A SUBACK is due within the keepalive too: before, the subscribe (a session's set-up)
    waited for ever while the broker answered every ping."""
    async with misbehaving_broker(suback=False) as broker:
        c = Client("127.0.0.1", broker.port, identifier="c", keepalive_s=1)
        async with c, asyncio.timeout(10):  # a hang fails, not at the suite's time-out
            with pytest.raises(SubscribeUnacknowledged) as raised:
                await c.subscribe([("cmd/#", 1), ("status", 0)])
            with pytest.raises(SubscribeUnacknowledged):  # what comes after hears it too
                await c.publish("t", b"after", qos=1)
        await broker.until(lambda: broker.connections[0].closed_at is not None, "the end")
    (seen,) = broker.connections
    assert [f for f, _ in seen.swallowed] == ["cmd/#", "status"]
    asked = seen.swallowed[0][1]
    assert seen.closed_at is not None
    stalled_s = seen.closed_at - asked
    assert 0.9 <= stalled_s <= 2.25, stalled_s  # keepalive_s to 1.5 keepalive_s, and slack
    assert any(t > asked for t in seen.pings)  # answered meanwhile: it looked alive
    assert not seen.disconnected  # aborted: a real broker publishes the will
    assert isinstance(raised.value, MqttError)  # what a session catches
    text = str(raised.value)
    assert text.startswith("no SUBACK for 1."), text
    assert text.endswith(
        "(keepalive_s 1): SUBSCRIBE packet 1 (cmd/#, status) of client c, the oldest of 1 waiting"
    ), text


async def test_subscribes_answered_slowly_but_within_the_keepalive_keep_the_connection() -> None:
    """Three SUBACKs 0.6 s late each: 1.8 s of set-up, longer than the keepalive, no stall."""
    async with (
        misbehaving_broker(suback_delay_s=0.6) as broker,
        Client("127.0.0.1", broker.port, identifier="c", keepalive_s=1) as c,
    ):
        for name in ("a", "b", "c"):
            assert await c.subscribe(name, qos=1) == (1,)
        await c.unsubscribe("a")  # answered at once: the UNSUBACK is watched the same way
    (seen,) = broker.connections
    assert [f for f, _, _ in seen.subscriptions] == ["a", "b", "c"]
    assert seen.pings  # the keepalive ran meanwhile
    assert seen.disconnected


def test_the_puback_watch_knows_a_publish_by_its_id_and_its_batch() -> None:
    """Sans-IO: ids are reused, a batch's end bounds the wait, and a held reader defers it."""

    @dataclass
    class Batch:
        written: float = math.inf  # still waiting for slots

    watch = PubackWatch(1.0)
    first, second = Batch(), Batch(written=1.25)  # times exact in binary
    assert watch.overdue(0.5, {}) is None
    assert watch.overdue(0.5, {7: first}) is None  # first seen: its wait starts now
    assert watch.overdue(1.25, {7: first}) is None
    assert watch.overdue(1.5, {7: first}) == (7, 1.0)
    assert watch.overdue(1.5, {7: second}) is None  # id 7 again: another publish, from 1.25
    assert watch.overdue(2.25, {7: second}) == (7, 1.0)
    watch.hold(2.5)  # the reader is behind: the PUBACK may wait behind its messages
    assert watch.overdue(3.25, {7: second}) is None
    assert watch.overdue(3.5, {7: second}) == (7, 1.0)
