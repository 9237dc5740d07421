"""The gateway's Modbus TCP server on raw sockets: bytes in, the exact bytes out.

Against a running gateway polling the simulator over TCP (drives 1..4).
Every exception case the spec names, pipelined requests answered in order
with their own ids, broken frames closing only their connection, and the
listener's limits (the cap, the idle timeout). The issue (26) found each of
these wrong in the pymodbus-based server: pipelined requests beyond the
first unanswered, a write's answer sent under the next request's ids, 0x80
with 0x01 for a bad quantity, canned data for diagnostics and unit 99.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
from collections.abc import AsyncIterator

import pytest
from waiting import wait_for

from sj300_async.gateway import Gateway
from sj300_async.gateway.modbus._northbound import ModbusNorthbound
from sj300_async.gateway.modbus._server import ModbusServer

from .conftest import SimLine, gateway_toml, modbus_port, polled, running_gateway

WRITES = """
    [[lines.writes]]
    nodes = "1-2"
    parameters = ["A004", "F002"]
    control = true
    """

Stream = tuple[asyncio.StreamReader, asyncio.StreamWriter]


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def server_of(gateway: Gateway) -> ModbusServer:
    northbound = gateway.northbounds["modbus"]
    assert isinstance(northbound, ModbusNorthbound)
    assert northbound.server is not None
    return northbound.server


@contextlib.asynccontextmanager
async def raw(gateway: Gateway, source: str = "127.0.0.1") -> AsyncIterator[Stream]:
    """A plain TCP connection to the gateway's Modbus port."""
    reader, writer = await asyncio.open_connection(
        "127.0.0.1", modbus_port(gateway), local_addr=(source, 0)
    )
    try:
        yield reader, writer
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def answer(reader: asyncio.StreamReader) -> bytes:
    """One whole answer (its MBAP header says how long)."""
    async with asyncio.timeout(5):
        header = await reader.readexactly(6)
        return header + await reader.readexactly(struct.unpack(">H", header[4:])[0])


async def ask(stream: Stream, request: bytes) -> bytes:
    reader, writer = stream
    writer.write(request)
    await writer.drain()
    return await answer(reader)


async def closed(reader: asyncio.StreamReader) -> bytes:
    """What is left before the server closes the connection (it must close it)."""
    async with asyncio.timeout(5):
        try:
            return await reader.read()
        except ConnectionResetError:
            return b""


# -- conformance, byte for byte ------------------------------------------------------------

#: (request, answer) on a read-only gateway; drives 1..4 stopped, SJ300, A004 = 50.0 Hz.
READ_ONLY = [
    # Reads: FC3 and FC4 of the identity block's protocol and node; A004 (500 = 50.0 Hz).
    ("0001 0000 0006 01 03 0002 0002", "0001 0000 0007 01 03 04 0001 0001"),
    ("0002 0000 0006 03 04 0002 0002", "0002 0000 0007 03 04 04 0001 0003"),
    ("0003 0000 0006 01 03 2ee8 0002", "0003 0000 0007 01 03 04 0000 01f4"),
    ("0004 0000 0006 02 03 00c8 0002", "0004 0000 0007 02 03 04 0000 0000"),
    # Bad quantity: 0x03 (the old server: function 0x80, 0x01).
    ("0005 0000 0006 01 03 0000 0000", "0005 0000 0003 01 83 03"),
    ("0006 0000 0006 01 03 0000 007e", "0006 0000 0003 01 83 03"),
    ("0007 0000 0006 01 04 0000 0000", "0007 0000 0003 01 84 03"),
    ("0008 0000 0005 01 03 0000 00", "0008 0000 0003 01 83 03"),  # PDU cut short
    # Bad address: 0x02.
    ("0009 0000 0006 01 03 1388 0001", "0009 0000 0003 01 83 02"),  # 5000
    ("000a 0000 0006 01 03 0063 0002", "000a 0000 0003 01 83 02"),  # 99..100
    ("000b 0000 0006 01 03 ffff 0002", "000b 0000 0003 01 83 02"),  # past 65535
    ("000c 0000 0006 01 03 36b4 0002", "000c 0000 0003 01 83 02"),  # B002: not polled
    # No drive behind the unit: 0x0A, whatever the function (never data).
    ("000d 0000 0006 63 03 0000 0001", "000d 0000 0003 63 83 0a"),  # unit 99
    ("000e 0000 0004 63 18 0000", "000e 0000 0003 63 98 0a"),  # FC 24 to unit 99
    ("000f 0000 0006 00 03 0000 0001", "000f 0000 0003 00 83 0a"),  # unit 0
    # Unit 255: the summary, read-only (register 0: the listener's four drives).
    ("0010 0000 0006 ff 03 0000 0001", "0010 0000 0005 ff 03 02 0004"),
    ("0110 0000 0006 ff 06 0008 0001", "0110 0000 0003 ff 86 01"),
    # Writes on a read-only line: 0x01; a read-only register 0x01; no register 0x02.
    ("0011 0000 0006 01 06 03e8 0001", "0011 0000 0003 01 86 01"),
    ("0012 0000 0006 01 06 0064 0001", "0012 0000 0003 01 86 01"),
    ("0013 0000 0006 01 06 1388 0001", "0013 0000 0003 01 86 02"),
    ("0014 0000 000b 01 10 2ee8 0002 04 0000 0258", "0014 0000 0003 01 90 01"),
    # FC 6 and 16 malformed: 0x03.
    ("0015 0000 0004 01 06 03e8", "0015 0000 0003 01 86 03"),
    ("0016 0000 0007 01 10 2ee8 0000 00", "0016 0000 0003 01 90 03"),  # quantity 0
    ("0017 0000 0009 01 10 0000 007c 02 0000", "0017 0000 0003 01 90 03"),  # 124
    ("0018 0000 000a 01 10 2ee8 0002 03 000000", "0018 0000 0003 01 90 03"),  # byte count
    ("0019 0000 0009 01 10 2ee8 0002 04 0000", "0019 0000 0003 01 90 03"),  # data short
]
#: Every function the gateway does not implement, 23 (read/write multiple) included: 0x01.
UNIMPLEMENTED = (1, 2, 5, 8, 11, 12, 15, 17, 20, 21, 22, 23, 24, 43, 0x41, 0x64, 0x7F, 0x83)


async def test_conformance_byte_for_byte(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        async with raw(gateway) as stream:
            for request, expected in READ_ONLY:
                assert (await ask(stream, h(request))).hex(" ") == h(expected).hex(" "), request
            for tid, function in enumerate(UNIMPLEMENTED, 0x100):
                unimplemented = struct.pack(">HHHBB4x", tid, 0, 6, 2, function)
                refusal = struct.pack(">HHHBBB", tid, 0, 3, 2, function | 0x80, 0x01)
                assert await ask(stream, unimplemented) == refusal, function
            # The connection is still in step after all of it.
            assert await ask(stream, h("7777 0000 0006 04 03 0003 0001")) == h(
                "7777 0000 0005 04 03 02 0004"
            )
        clients = server_of(gateway).counters
        assert clients.requests["127.0.0.1"] == len(READ_ONLY) + len(UNIMPLEMENTED) + 1
        assert clients.exceptions[("127.0.0.1", 0x0A)] == 3
        assert clients.exceptions[("127.0.0.1", 0x01)] == 4 + len(UNIMPLEMENTED)


async def test_writes_byte_for_byte(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        async with raw(gateway) as scada, raw(gateway, "127.0.0.2") as hmi:
            p = "0000 000b"  # a function 16 of two registers: protocol 0, length 11
            exchanges = [
                (scada, "0001 0000 0006 01 06 03e8 0001", "0001 0000 0006 01 06 03e8 0001"),
                # Another client's heartbeat while the lease is held: busy.
                (hmi, "0002 0000 0006 01 06 03e8 0001", "0002 0000 0003 01 86 06"),
                # A004 = 60.0 Hz, answered once read back.
                (scada, f"0003 {p} 01 10 2ee8 0002 04 0000 0258", "0003 0000 0006 01 10 2ee8 0002"),
                # Half of A004; A004 = 999.9 Hz; unit 3 not granted; run command 7.
                (scada, "0004 0000 0006 01 06 2ee9 0258", "0004 0000 0003 01 86 03"),
                (scada, f"0005 {p} 01 10 2ee8 0002 04 0000 270f", "0005 0000 0003 01 90 03"),
                (scada, f"0006 {p} 03 10 2ee8 0002 04 0000 0258", "0006 0000 0003 03 90 01"),
                (scada, "0007 0000 0006 01 06 03ea 0007", "0007 0000 0003 01 86 03"),
                # Set frequency 25.00 Hz: function 6 echoes the request.
                (scada, "0008 0000 0006 01 06 03eb 09c4", "0008 0000 0006 01 06 03eb 09c4"),
                (scada, "0009 0000 0006 01 03 2ee8 0002", "0009 0000 0007 01 03 04 0000 0258"),
            ]
            for stream, request, expected in exchanges:
                assert (await ask(stream, h(request))).hex(" ") == h(expected).hex(" "), request
    assert sim_line.sim.drives[1].parameters["A004"] == 600
    assert sim_line.sim.drives[1].parameters["F001"] == 2500
    assert sim_line.log.interleaved() == []


# -- pipelining ---------------------------------------------------------------------------


async def test_five_pipelined_requests_are_answered_in_order_with_their_ids(
    sim_line: SimLine,
) -> None:
    requests = [
        # A heartbeat (unit 1), a read (unit 2), a parameter write that waits for the
        # line and its read-back (unit 1), a read behind it (unit 3), a write (unit 2).
        ("0101 0000 0006 01 06 03e8 0001", "0101 0000 0006 01 06 03e8 0001"),
        ("0102 0000 0006 02 03 0002 0002", "0102 0000 0007 02 03 04 0001 0002"),
        ("0103 0000 000b 01 10 2ee8 0002 04 0000 0258", "0103 0000 0006 01 10 2ee8 0002"),
        ("0104 0000 0006 03 03 0002 0002", "0104 0000 0007 03 03 04 0001 0003"),
        ("0105 0000 000b 02 10 2ee8 0002 04 0000 0226", "0105 0000 0006 02 10 2ee8 0002"),
    ]
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        async with raw(gateway) as (reader, writer):
            writer.write(b"".join(h(request) for request, _ in requests))  # back to back
            await writer.drain()
            got = [await answer(reader) for _ in requests]
            assert [a.hex(" ") for a in got] == [h(e).hex(" ") for _, e in requests]
            # Nothing more: one answer per request.
            assert await ask((reader, writer), h("0106 0000 0006 04 03 0003 0001")) == h(
                "0106 0000 0005 04 03 02 0004"
            )
    assert sim_line.sim.drives[1].parameters["A004"] == 600
    assert sim_line.sim.drives[2].parameters["A004"] == 550


async def test_a_request_cut_byte_by_byte_is_answered_once(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        async with raw(gateway) as (reader, writer):
            for byte in h("0042 0000 0006 02 03 0003 0001"):
                writer.write(bytes([byte]))
                await writer.drain()
            assert await answer(reader) == h("0042 0000 0005 02 03 02 0002")


# -- broken frames ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "bad",
    [
        "0002 0005 0006 01 03 0002 0001",  # protocol id 5
        "0002 0000 0001 01",  # length 1: not even a function code
        "0002 0000 00ff 01 03",  # length 255: an ADU over 260 bytes
        "ff 0002 0000 0006 01 03 0002 0001",  # a stray byte before a request
    ],
)
async def test_a_broken_frame_closes_its_connection_only(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture, bad: str
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.modbus")
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        async with raw(gateway) as other, raw(gateway) as (reader, writer):
            # A good request and the bad frame in one segment: the good one is answered.
            writer.write(h("0001 0000 0006 01 03 0003 0001") + h(bad))
            assert await answer(reader) == h("0001 0000 0005 01 03 02 0001")
            assert await closed(reader) == b""
            # The other connection is served as before.
            assert await ask(other, h("0003 0000 0006 01 03 0003 0001")) == h(
                "0003 0000 0005 01 03 02 0001"
            )
        # A client that reconnects is served.
        async with raw(gateway) as stream:
            assert await ask(stream, h("0004 0000 0006 02 03 0003 0001")) == h(
                "0004 0000 0005 02 03 02 0002"
            )
        assert server_of(gateway).bad_frames == 1
        families = {m.name: m for m in gateway.metrics()}
        assert families["sj300_modbus_bad_frames"].samples[0].value == 1
    lines = [r for r in caplog.records if "connection closed. First bytes" in r.getMessage()]
    assert len(lines) == 1, lines
    assert lines[0].levelno == logging.WARNING
    assert lines[0].exc_info is None


async def test_bad_frames_are_logged_once_per_interval(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.modbus")
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        for _ in range(5):
            async with raw(gateway) as (reader, writer):
                writer.write(b"GET / HTTP/1.1\r\n\r\n" + bytes(range(256)) * 4)
                assert await closed(reader) == b""
        assert server_of(gateway).bad_frames == 5
    lines = [r for r in caplog.records if "connection closed. First bytes" in r.getMessage()]
    assert [r.levelno for r in lines] == [logging.WARNING] + [logging.DEBUG] * 4
    # One line each, with the header's bytes in hex: nothing of the rest, no traceback.
    assert "protocol id 21536, not 0; connection closed. First bytes: 47 45 54 20 2f 20 48" in (
        lines[0].getMessage()
    )
    assert all(len(r.getMessage()) < 200 and r.exc_info is None for r in lines)


# -- connections ---------------------------------------------------------------------------


async def test_the_connection_cap_refuses_newcomers_at_once(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.modbus")
    # All from 127.0.0.1: the per-address cap (half the cap by default) raised to the cap.
    text = gateway_toml(sim_line.url, extra="max_connections = 2\nmax_connections_per_address = 2")
    async with running_gateway(text) as gateway:
        await polled(gateway)
        limit = server_of(gateway).limit
        read = h("0001 0000 0006 01 03 0003 0001"), h("0001 0000 0005 01 03 02 0001")
        async with raw(gateway) as first, raw(gateway) as second:
            assert await ask(first, read[0]) == read[1]
            assert await ask(second, read[0]) == read[1]
            for _ in range(3):
                async with raw(gateway) as (reader, _writer):
                    assert await closed(reader) == b""  # accepted and closed at once
            assert (limit.open, limit.refused) == (2, 3)
            assert await ask(first, read[0]) == read[1]  # the admitted ones are served
        await wait_for(lambda: limit.open == 0, "both connections released")
        async with raw(gateway) as third:
            assert await ask(third, read[0]) == read[1]
        families = {m.name: m for m in gateway.metrics()}
        assert families["sj300_modbus_connections_refused"].samples[0].value == 3
    refusals = [r for r in caplog.records if "(max_connections): refused" in r.getMessage()]
    assert [r.levelno for r in refusals] == [logging.WARNING, logging.DEBUG, logging.DEBUG]


async def test_an_idle_connection_is_closed(sim_line: SimLine) -> None:
    text = gateway_toml(sim_line.url, extra="idle_timeout_s = 0.2")
    async with running_gateway(text) as gateway:
        await polled(gateway)
        async with raw(gateway) as (reader, writer):
            assert await ask((reader, writer), h("0001 0000 0006 01 03 0003 0001")) == h(
                "0001 0000 0005 01 03 02 0001"
            )
            assert await closed(reader) == b""
        assert server_of(gateway).limit.timed_out == 1


async def test_a_closed_connection_is_reported_after_its_write(
    sim_line: SimLine, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[tuple[str, int]] = []
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        drive = sim_line.sim.drives[1]
        monkeypatch.setattr(
            gateway, "disconnected", lambda name: seen.append((name, drive.parameters["A004"]))
        )
        async with raw(gateway) as (_reader, writer):
            port = writer.get_extra_info("sockname")[1]
            # A parameter write (through the line), and the client gone before its answer.
            writer.write(h("0001 0000 000b 01 10 2ee8 0002 04 0000 0258"))
            await writer.drain()
        await wait_for(lambda: seen, "the connection's end reported")
        # Reported once, after the write was carried out (a lease it took lapses after it).
        assert seen == [(f"127.0.0.1:{port}", 600)]
        async with raw(gateway) as (_reader, writer):
            port = writer.get_extra_info("sockname")[1]
        await wait_for(lambda: len(seen) == 2, "the second connection's end reported")
        assert seen[1] == (f"127.0.0.1:{port}", 600)


async def test_the_clients_end_of_stream_waits_for_its_answers(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        async with raw(gateway) as (reader, writer):
            # A write through the line, a read behind it, then no more (``nc -N``).
            writer.write(h("0001 0000 000b 01 10 2ee8 0002 04 0000 0258"))
            writer.write(h("0002 0000 0006 01 03 2ee8 0002"))
            writer.write_eof()
            assert await closed(reader) == h(
                "0001 0000 0006 01 10 2ee8 0002" + "0002 0000 0007 01 03 04 0000 0258"
            )
