"""The attacker and the well-behaved clients of the adversarial tests, each in a process of its own.

Run as ``python attacker.py NAME JSON``: *NAME* is one of :data:`ATTACKS`,
*JSON* its arguments. It does what it is named for over real sockets,
within a bounded count and time (every attack stops by itself), and
prints one JSON line: what it sent and what the gateway answered. The
tests read that line to check that the attack really happened.

Its own process, not the test's: the gateway's event loop is what the
tests measure, and an attacker on that loop would count its own work as
the gateway's lag. Only loopback addresses are used; ``source`` picks one
of 127.0.0.0/8 so that the gateway sees the attacker and the
well-behaved clients as different addresses.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import random
import struct
import sys
import time
from collections import Counter
from collections.abc import Callable, Coroutine
from typing import Any

Args = dict[str, Any]
Report = dict[str, Any]


async def _open(port: int, source: str) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))


async def _status(reader: asyncio.StreamReader, timeout: float) -> int | str:
    """The status of the HTTP answer *reader* gets, or why there was none."""
    try:
        line = await asyncio.wait_for(reader.readline(), timeout)
    except TimeoutError:
        return "no answer"
    except ConnectionError:
        return "reset"
    if not line:
        return "closed"
    parts = line.split()
    return int(parts[1]) if len(parts) > 1 and parts[1].isdigit() else "garbled"


def _post_head(path: str, length: int, content_type: str = "application/json") -> bytes:
    return (
        f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: {content_type}\r\n"
        f"Content-Length: {length}\r\n\r\n"
    ).encode()


# -- HTTP ---------------------------------------------------------------------------------


async def logins(args: Args) -> Report:
    """Bursts of concurrent logins: every head first, then every body (issue 41's 60 at once)."""
    body = json.dumps({"name": args.get("user", "operator"), "password": "wrong"}).encode()
    statuses: Counter[str] = Counter()
    deadline = time.monotonic() + args.get("duration_s", 0.0)
    bursts = 0
    while True:
        streams = []
        for _ in range(args.get("count", 60)):
            try:
                streams.append(await _open(args["port"], args.get("source", "127.0.0.1")))
            except OSError:
                statuses["connect failed"] += 1
        for _, writer in streams:
            writer.write(_post_head("/api/v1/login", len(body)))
        for _, writer in streams:
            await writer.drain()
        for _, writer in streams:
            writer.write(body)
        answers = await asyncio.gather(*(_status(reader, 30.0) for reader, _ in streams))
        statuses.update(str(answer) for answer in answers)
        for _, writer in streams:
            writer.close()
        bursts += 1
        if time.monotonic() >= deadline:
            break
    return {"bursts": bursts, "statuses": dict(statuses)}


async def slow_bodies(args: Args) -> Report:
    """Connections that announce a 100,000-byte body and send none, *count* at once, round
    after round for *duration_s*; how each ended, and the longest any was held."""
    started = time.monotonic()
    path = args.get("path", "/api/v1/login")

    async def one() -> tuple[str, float]:
        try:
            reader, writer = await _open(args["port"], args.get("source", "127.0.0.1"))
        except OSError:
            return "connect failed", 0.0
        writer.write(_post_head(path, 100_000))
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        answer = await _status(reader, args.get("hold_s", 30.0))
        writer.close()
        return str(answer), time.monotonic() - started

    statuses: Counter[str] = Counter()
    longest = 0.0
    deadline = time.monotonic() + args.get("duration_s", 0.0)
    while True:  # a round a second for duration_s (a refused round ends at once)
        round_started = time.monotonic()
        ends = await asyncio.gather(*(one() for _ in range(args.get("count", 64))))
        statuses.update(status for status, _ in ends)
        longest = max(longest, max(at for _, at in ends) - (round_started - started))
        if time.monotonic() >= deadline:
            break
        await asyncio.sleep(max(0.0, round_started + 1.0 - time.monotonic()))
    return {"statuses": dict(statuses), "longest_s": longest}


async def nested_json(args: Args) -> Report:
    """Bodies of ``[`` x 1000 (1 KB) to a JSON route, one after another on keep-alive, at
    least *count* of them and for at least *duration_s*."""
    import aiohttp

    connector = aiohttp.TCPConnector(local_addr=(args.get("source", "127.0.0.1"), 0), limit=4)
    statuses: Counter[str] = Counter()
    url = f"http://127.0.0.1:{args['port']}{args.get('path', '/api/v1/login')}"
    deadline = time.monotonic() + args.get("duration_s", 0.0)
    sent = 0
    async with aiohttp.ClientSession(connector=connector) as session:
        while sent < args.get("count", 500) or time.monotonic() < deadline:
            sent += 1
            try:
                async with session.post(
                    url, data=b"[" * 1000, headers={"Content-Type": "application/json"}
                ) as response:
                    await response.read()
                    statuses[str(response.status)] += 1
            except aiohttp.ClientError as exc:
                statuses[type(exc).__name__] += 1
    return {"statuses": dict(statuses)}


async def cut_streams(args: Args) -> Report:
    """Parameter-read streams closed after their first bytes, and POST bodies cut halfway:
    at least *count* of each and for at least *duration_s*."""
    port, source = args["port"], args.get("source", "127.0.0.1")
    streams = cuts = 0
    deadline = time.monotonic() + args.get("duration_s", 0.0)
    while cuts < args.get("count", 20) or time.monotonic() < deadline:
        reader, writer = await _open(port, source)
        writer.write(b"GET /api/v1/drives/hall/1/parameters HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        with contextlib.suppress(TimeoutError, ConnectionError):
            await asyncio.wait_for(reader.read(1), 10)
            streams += 1
        writer.close()
        reader, writer = await _open(port, source)
        writer.write(_post_head("/api/v1/login", 200) + b'{"name": "operator", "pass')
        await writer.drain()
        writer.close()
        cuts += 1
    return {"streams_closed": streams, "bodies_cut": cuts}


# -- OPC UA -------------------------------------------------------------------------------


def _bind(source: str) -> None:
    """Make every connection of this process come from *source* (asyncua binds none)."""
    loop = asyncio.get_running_loop()
    create = loop.create_connection

    async def bound(*a: Any, **kw: Any) -> Any:
        kw.setdefault("local_addr", (source, 0))
        return await create(*a, **kw)

    loop.create_connection = bound  # type: ignore[method-assign]


async def _channel(url: str) -> Any:
    """asyncua's low-level client with a secure channel of policy None open on *url*."""
    from asyncua import ua
    from asyncua.client.ua_client import UaClient

    host, port = url.removeprefix("opc.tcp://").rsplit(":", 1)
    client = UaClient(timeout=5)
    await client.connect_socket(host, int(port))
    await client.send_hello(url)
    params = ua.OpenSecureChannelParameters()
    params.ClientProtocolVersion = 0
    params.RequestType = ua.SecurityTokenRequestType.Issue
    params.SecurityMode = ua.MessageSecurityMode.None_
    params.RequestedLifetime = 3_600_000
    params.ClientNonce = b""
    await client.open_secure_channel(params)
    return client


async def opcua_sessions(args: Args) -> Report:
    """CreateSession on the unsecured channel, never activated, until refused or *count*."""
    from asyncua import ua

    _bind(args.get("source", "127.0.0.1"))
    outcomes: Counter[str] = Counter()
    clients = []
    per_connection = args.get("per_connection", 10)
    for _ in range(args.get("count", 100) // per_connection):
        try:
            client = await _channel(args["url"])
        except Exception as exc:
            outcomes[f"channel: {type(exc).__name__}"] += 1
            continue
        clients.append(client)
        for _ in range(per_connection):
            params = ua.CreateSessionParameters()
            params.ClientDescription = ua.ApplicationDescription()
            params.EndpointUrl = args["url"]
            params.SessionName = f"attacker-{random.random()}"
            params.ClientNonce = os.urandom(32)
            params.RequestedSessionTimeout = 3_600_000
            params.MaxResponseMessageSize = 0
            try:
                await client.create_session(params)
                outcomes["created"] += 1
            except ua.UaStatusCodeError as exc:
                outcomes[type(exc).__name__] += 1
            except Exception as exc:
                outcomes[type(exc).__name__] += 1
                break
    await asyncio.sleep(args.get("hold_s", 0.0))  # the sessions stay open, unactivated
    for client in clients:
        with contextlib.suppress(Exception):
            await client.disconnect_socket()
    return {"outcomes": dict(outcomes)}


async def opcua_chunks(args: Args) -> Report:
    """MSG chunks with a wrong token id on open channels, up to *count* a channel, channel
    after channel for *duration_s*: how many went in before each channel was closed."""
    _bind(args.get("source", "127.0.0.1"))
    sent = channels = closed = 0
    deadline = time.monotonic() + args.get("duration_s", 0.0)
    while channels == 0 or time.monotonic() < deadline:
        client = await _channel(args["url"])
        channels += 1
        protocol = client.protocol
        transport = protocol.transport
        channel = protocol._connection.security_token.ChannelId
        for n in range(args.get("count", 2000)):
            if transport.is_closing() or protocol.state == "close":
                break
            body = os.urandom(8)
            header = struct.pack("<4sIIIII", b"MSGF", 24 + len(body), channel, 0xBAD, 100 + n, n)
            transport.write(header + body)
            sent += 1
            if n % 50 == 0:
                await asyncio.sleep(0)  # let the connection notice a close
        for _ in range(50):  # the server's close, if it comes, within 0.5 s
            if transport.is_closing() or protocol.state == "close":
                closed += 1
                break
            await asyncio.sleep(0.01)
        with contextlib.suppress(Exception):
            await client.disconnect_socket()
    return {"sent": sent, "channels": channels, "closed_by_server": closed}


async def opcua_passwords(args: Args) -> Report:
    """Logins with a wrong password over SignAndEncrypt, one after another."""
    from asyncua import Client

    _bind(args.get("source", "127.0.0.1"))
    outcomes: Counter[str] = Counter()
    deadline = time.monotonic() + args.get("duration_s", 5.0)
    while time.monotonic() < deadline:
        client = Client(args["url"], timeout=5)
        await client.set_security_string(args["security"])
        client.set_user(args.get("user", "operator"))
        client.set_password("wrong")
        try:
            await client.connect()
            outcomes["accepted"] += 1
            await client.disconnect()
        except Exception as exc:
            outcomes[type(exc).__name__] += 1
    return {"outcomes": dict(outcomes)}


async def opcua_reader(args: Args) -> Report:
    """A well-behaved operator: logs in (the right password) and reads a value twice a second."""
    from asyncua import Client, ua

    _bind(args.get("source", "127.0.0.1"))
    reads: Counter[str] = Counter()
    client = Client(args["url"], timeout=5)
    await client.set_security_string(args["security"])
    client.set_user(args["user"])
    client.set_password(args["password"])
    deadline = time.monotonic() + args.get("duration_s", 5.0)
    try:
        await client.connect()
    except Exception as exc:
        return {"login": type(exc).__name__, "reads": {}}
    try:
        namespace = await client.get_namespace_index(args["namespace"])
        variable = client.get_node(ua.NodeId(args["node"], namespace))
        while time.monotonic() < deadline:
            try:
                await asyncio.wait_for(variable.read_value(), 2.0)
                reads["ok"] += 1
            except Exception as exc:
                reads[type(exc).__name__] += 1
            await asyncio.sleep(0.5)
    finally:
        with contextlib.suppress(Exception):
            await client.disconnect()
    return {"login": "ok", "reads": dict(reads)}


# -- Modbus and MQTT ----------------------------------------------------------------------


async def modbus_junk(args: Args) -> Report:
    """Random bytes and impossible frames on many Modbus connections."""
    rng = random.Random(args.get("seed", 41))
    sent = connections = 0
    deadline = time.monotonic() + args.get("duration_s", 5.0)
    while time.monotonic() < deadline:
        try:
            _reader, writer = await _open(args["port"], args.get("source", "127.0.0.1"))
        except OSError:
            await asyncio.sleep(0.05)
            continue
        connections += 1
        for _ in range(20):
            kind = rng.randrange(3)
            if kind == 0:
                frame = rng.randbytes(rng.randrange(1, 300))
            elif kind == 1:  # a header that announces more than ever comes
                frame = struct.pack(">HHHB", rng.randrange(65536), 0, 260, 1) + b"\x03"
            else:  # a well-framed read of nonsense
                frame = struct.pack(">HHHBBHH", 1, 0, 6, rng.randrange(256), 3, 65535, 125)
            writer.write(frame)
            sent += 1
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        writer.close()
    return {"frames": sent, "connections": connections}


async def mqtt_junk(args: Args) -> Report:
    """Garbage on the gateway's command topics: wrong types, nesting, oversized, binary."""
    import aiomqtt

    rng = random.Random(args.get("seed", 41))
    junk: list[bytes] = [
        b"[" * 1000,
        b"\xff\xfe\x00",
        b'{"a":' * 200,
        b"nan",
        b"1e999",
        b"x" * 300_000,
        b'"run_forward"',
        b"",
    ]
    topics = [f"{args['prefix']}/hall/1/set/{what}" for what in ("frequency_hz", "command", "x")]
    sent = 0
    deadline = time.monotonic() + args.get("duration_s", 5.0)
    async with aiomqtt.Client("127.0.0.1", args["port"], identifier="attacker") as client:
        while time.monotonic() < deadline:
            await client.publish(rng.choice(topics), rng.choice(junk), qos=0)
            sent += 1
            if sent % 20 == 0:
                await asyncio.sleep(0.01)
    return {"sent": sent}


# -- probes (tests/adversarial/test_probe_findings.py) -------------------------------------


async def held_connections(args: Args) -> Report:
    """*per_source* connections from each of *sources*, each kept busy enough never to be
    idle (an HTTP ``GET`` or a one-register Modbus read every *every_s*), for *hold_s*:
    how many were admitted, and how many of them were still open at the end."""
    port, kind = args["port"], args.get("kind", "http")
    every_s, hold_s = args.get("every_s", 3.0), args.get("hold_s", 8.0)
    if kind == "http":
        request = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
    else:  # Modbus: read holding register 0 of unit 1
        request = struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 0, 1)
    opened = alive = answered = 0
    streams: list[tuple[asyncio.StreamReader, asyncio.StreamWriter]] = []
    for source in args["sources"]:
        for _ in range(args.get("per_source", 32)):
            try:
                streams.append(await _open(port, source))
                opened += 1
            except OSError:
                pass

    async def keep(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> int:
        got = 0
        deadline = time.monotonic() + hold_s
        while time.monotonic() < deadline:
            writer.write(request)
            try:
                await writer.drain()
                data = await asyncio.wait_for(reader.read(4096), 2.0)
            except (ConnectionError, TimeoutError):
                return -1
            if not data:
                return -1
            got += 1
            await asyncio.sleep(min(every_s, max(0.0, deadline - time.monotonic())))
        return got

    results = await asyncio.gather(*(keep(r, w) for r, w in streams))
    alive = sum(1 for n in results if n >= 0)
    answered = sum(n for n in results if n > 0)
    for _, writer in streams:
        writer.close()
    return {"opened": opened, "alive_at_end": alive, "answers": answered}


async def http_pipeline(args: Args) -> Report:
    """*count* requests for *path* written at once on one connection (pipelined), over and
    over for *duration_s*: how many answers came back."""
    request = f"GET {args.get('path', '/metrics')} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode()
    answers = rounds = 0
    deadline = time.monotonic() + args.get("duration_s", 5.0)
    while time.monotonic() < deadline:
        try:
            reader, writer = await _open(args["port"], args.get("source", "127.0.0.1"))
        except OSError:
            await asyncio.sleep(0.05)
            continue
        rounds += 1
        writer.write(request * args.get("count", 200))
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        buffer = b""
        while time.monotonic() < deadline:
            try:
                data = await asyncio.wait_for(reader.read(1 << 16), 2.0)
            except (ConnectionError, TimeoutError):
                break
            if not data:
                break
            buffer = buffer[-16:] + data
            answers += data.count(b"HTTP/1.1 ")
        writer.close()
    return {"rounds": rounds, "answers": answers}


async def modbus_reads(args: Args) -> Report:
    """Well-formed reads of 125 registers, pipelined *window* at a time on one connection,
    across every unit id in *units*, for *duration_s*: how many answers came back."""
    units = args.get("units", [1, 2, 3, 4, 255])
    window = args.get("window", 50)
    address = args.get("address", 0)
    reader, writer = await _open(args["port"], args.get("source", "127.0.0.1"))
    sent = answers = exceptions = 0
    deadline = time.monotonic() + args.get("duration_s", 5.0)
    tid = 0
    while time.monotonic() < deadline:
        frames = []
        for _ in range(window):
            tid = (tid + 1) & 0xFFFF
            frames.append(
                struct.pack(">HHHBBHH", tid, 0, 6, units[tid % len(units)], 3, address, 125)
            )
        writer.write(b"".join(frames))
        sent += window
        try:
            await writer.drain()
            for _ in range(window):
                head = await asyncio.wait_for(reader.readexactly(7), 2.0)
                length = struct.unpack(">H", head[4:6])[0]
                body = await asyncio.wait_for(reader.readexactly(length - 1), 2.0)
                answers += 1
                exceptions += body[0] & 0x80 != 0
        except (ConnectionError, TimeoutError, asyncio.IncompleteReadError):
            break
    writer.close()
    return {"sent": sent, "answers": answers, "exceptions": exceptions}


async def mqtt_flap(args: Args) -> Report:
    """*payloads* in turn on *topic*, not retained, *count* of them as fast as the broker
    takes them, and the messages the broker carried on *watch* meanwhile."""
    import aiomqtt

    payloads = [p.encode() for p in args.get("payloads", ["online", "offline"])]
    sent = seen = 0
    async with (
        aiomqtt.Client("127.0.0.1", args["port"], identifier="flapper") as client,
        aiomqtt.Client("127.0.0.1", args["port"], identifier="watcher") as watcher,
    ):
        await watcher.subscribe(args.get("watch", "#"))

        async def count() -> None:
            nonlocal seen
            async for _ in watcher.messages:
                seen += 1

        counter = asyncio.create_task(count())
        await asyncio.sleep(0.5)
        seen = 0  # the retained ones on subscribing are not the attack's
        deadline = time.monotonic() + args.get("duration_s", 5.0)
        while sent < args.get("count", 1000) and time.monotonic() < deadline:
            await client.publish(args["topic"], payloads[sent % len(payloads)], qos=0)
            sent += 1
            if sent % 20 == 0:
                await asyncio.sleep(0.001)
        await asyncio.sleep(args.get("settle_s", 2.0))
        counter.cancel()
    return {"sent": sent, "carried": seen}


async def opcua_anonymous(args: Args) -> Report:
    """Anonymous sessions over SignAndEncrypt with a certificate of the attacker's own
    (*security*), each with a subscription of *items* monitored items sampled as fast as
    allowed, or a Read of *items* values in a loop (*mode* "read"), for *duration_s*."""
    from asyncua import Client, ua

    _bind(args.get("source", "127.0.0.1"))
    outcomes: Counter[str] = Counter()
    clients = []
    nodes: list[Any] = []
    for _ in range(args.get("sessions", 4)):
        client = Client(args["url"], timeout=10)
        await client.set_security_string(args["security"])
        try:
            await client.connect()
        except Exception as exc:
            outcomes[f"connect: {type(exc).__name__}"] += 1
            continue
        clients.append(client)
    if not clients:
        return {"outcomes": dict(outcomes)}
    namespace = await clients[0].get_namespace_index(args["namespace"])
    names = args["variables"]
    for n in range(args.get("items", 500)):
        nodes.append(ua.NodeId(names[n % len(names)], namespace))
    deadline = time.monotonic() + args.get("duration_s", 5.0)
    notified = 0

    class Handler:
        def datachange_notification(self, *_: Any) -> None:
            nonlocal notified
            notified += 1

    async def one(client: Any) -> None:
        if args.get("mode") == "read":
            params = ua.ReadParameters()
            for node in nodes:
                rv = ua.ReadValueId()
                rv.NodeId = node
                rv.AttributeId = ua.AttributeIds.Value
                params.NodesToRead.append(rv)
            while time.monotonic() < deadline:
                try:
                    await client.uaclient.read(params)
                    outcomes["read"] += 1
                except Exception as exc:
                    outcomes[type(exc).__name__] += 1
            return
        try:
            subscription = await client.create_subscription(
                args.get("publishing_ms", 10), Handler()
            )
            results = await subscription.subscribe_data_change(
                [client.get_node(node) for node in nodes], sampling_interval=0
            )
            outcomes["items"] += sum(1 for r in results if isinstance(r, int))
        except Exception as exc:
            outcomes[f"subscribe: {type(exc).__name__}"] += 1
        await asyncio.sleep(max(0.0, deadline - time.monotonic()))

    await asyncio.gather(*(one(c) for c in clients))
    for client in clients:
        with contextlib.suppress(Exception):
            await client.disconnect()
    return {"outcomes": dict(outcomes), "notified": notified, "sessions": len(clients)}


async def http_dribble(args: Args) -> Report:
    """*count* connections that each dribble a request a few bytes every *every_s*: its
    head (*mode* "head": header lines that never end) or a chunked body that never ends
    (*mode* "chunked", to *path*); how long the gateway let the longest run."""
    path, mode = args.get("path", "/api/v1/parameters/check"), args.get("mode", "head")
    started = time.monotonic()
    limit_s = args.get("hold_s", 12.0)

    async def one() -> tuple[str, float]:
        try:
            reader, writer = await _open(args["port"], args.get("source", "127.0.0.1"))
        except OSError:
            return "connect failed", 0.0
        if mode == "head":
            writer.write(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n".encode())
        else:
            writer.write(
                f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json"
                "\r\nTransfer-Encoding: chunked\r\n\r\n".encode()
            )
        ending = "held"
        n = 0
        while time.monotonic() - started < limit_s:
            n += 1
            piece = f"X-Pad-{n}: a\r\n" if mode == "head" else "1\r\n \r\n"
            try:
                writer.write(piece.encode())
                await writer.drain()
                data = await asyncio.wait_for(reader.read(1024), args.get("every_s", 0.5))
            except TimeoutError:
                continue
            except ConnectionError:
                ending = "reset"
                break
            ending = "closed" if not data else str(data.split(b" ", 2)[1:2])
            break
        writer.close()
        return ending, time.monotonic() - started

    ends = await asyncio.gather(*(one() for _ in range(args.get("count", 10))))
    return {
        "endings": dict(Counter(end for end, _ in ends)),
        "longest_s": max(at for _, at in ends),
    }


ATTACKS: dict[str, Callable[[Args], Coroutine[Any, Any, Report]]] = {
    "logins": logins,
    "slow_bodies": slow_bodies,
    "nested_json": nested_json,
    "cut_streams": cut_streams,
    "opcua_sessions": opcua_sessions,
    "opcua_chunks": opcua_chunks,
    "opcua_passwords": opcua_passwords,
    "opcua_reader": opcua_reader,
    "modbus_junk": modbus_junk,
    "mqtt_junk": mqtt_junk,
    "held_connections": held_connections,
    "http_pipeline": http_pipeline,
    "modbus_reads": modbus_reads,
    "mqtt_flap": mqtt_flap,
    "opcua_anonymous": opcua_anonymous,
    "http_dribble": http_dribble,
}


def main() -> None:
    name, args = sys.argv[1], json.loads(sys.argv[2])
    # At the lowest priority: an attacker on the plant network runs on a machine of its
    # own, so here it may only have the processor time the gateway does not want. The
    # loop's lag measured is then the gateway's own work, not this machine's two cores
    # shared with ten attackers.
    os.nice(19)
    report: Report = asyncio.run(ATTACKS[name](args))
    print(json.dumps(report), flush=True)


if __name__ == "__main__":
    main()
