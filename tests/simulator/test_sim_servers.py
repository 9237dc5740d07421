"""The TCP and pty servers, spoken to with raw bytes as any serial program would."""

from __future__ import annotations

import asyncio
import os
import termios
from collections.abc import AsyncIterator

import pytest
import serial  # pyserial

from sj300_async.simulator import (
    LinePacing,
    PtyServer,
    SimulatorServer,
    open_pty_server,
    serve_serial_device,
    serve_tcp,
)
from sj300_async.simulator.sj300 import SimulatedBus

from .simwire import ack, ack_data, data_reply, request

TIMEOUT = 2.0

# -- TCP ------------------------------------------------------------------------------


@pytest.fixture
async def tcp() -> AsyncIterator[SimulatorServer]:
    server = await serve_tcp(SimulatedBus(nodes=[1, 2]), port=0)
    yield server
    server.close()
    await server.wait_closed()


async def _connect(server: SimulatorServer) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.wait_for(asyncio.open_connection("127.0.0.1", server.port), TIMEOUT)


async def _ask(
    reader: asyncio.StreamReader, writer: asyncio.StreamWriter, raw: bytes, n: int
) -> bytes:
    writer.write(raw)
    await writer.drain()
    return await asyncio.wait_for(reader.readexactly(n), TIMEOUT)


async def test_tcp_listens_on_loopback_by_default(tcp: SimulatorServer) -> None:
    assert tcp.host == "127.0.0.1"
    assert tcp.port > 0


async def test_tcp_raw_request_and_reply(tcp: SimulatorServer) -> None:
    reader, writer = await _connect(tcp)
    raw = bytes.fromhex("02 30 31 30 30 31 33 30 0D")  # the reference's run-forward example
    assert await _ask(reader, writer, raw, 7) == bytes.fromhex("02 30 31 06 30 37 0D")
    expected = data_reply(b"02", b"02000100")
    assert await _ask(reader, writer, request(b"02", b"04"), len(expected)) == expected
    writer.close()


async def test_tcp_bytes_split_across_writes(tcp: SimulatorServer) -> None:
    reader, writer = await _connect(tcp)
    raw = request(b"01", b"06", b"A004")
    for byte in raw:
        writer.write(bytes((byte,)))
        await writer.drain()
    expected = ack_data(b"01", b"00000500")
    assert await asyncio.wait_for(reader.readexactly(len(expected)), TIMEOUT) == expected
    writer.close()


async def test_tcp_clients_share_one_bus(tcp: SimulatorServer) -> None:
    r1, w1 = await _connect(tcp)
    r2, w2 = await _connect(tcp)
    assert await _ask(r1, w1, request(b"01", b"07", b"F00200001000"), 7) == ack(b"01")
    expected = ack_data(b"01", b"00001000")
    assert await _ask(r2, w2, request(b"01", b"06", b"F002"), len(expected)) == expected
    assert tcp.connections == 2
    w1.close()
    w2.close()


async def test_tcp_close_disconnects_clients() -> None:
    server = await serve_tcp(SimulatedBus(nodes=[1]), port=0)
    reader, writer = await _connect(server)
    assert await _ask(reader, writer, request(b"01", b"0B"), 7) == ack(b"01")
    server.close()
    await asyncio.wait_for(server.wait_closed(), TIMEOUT)
    assert await asyncio.wait_for(reader.read(), TIMEOUT) == b""  # EOF
    with pytest.raises(ConnectionRefusedError):
        await asyncio.open_connection("127.0.0.1", server.port)
    writer.close()


async def test_tcp_with_pacing_takes_the_wire_time() -> None:
    pacing = LinePacing(2400, 8, "N", 1)  # 4.17 ms a character
    async with await serve_tcp(SimulatedBus(nodes=[1]), port=0, pacing=pacing) as server:
        reader, writer = await _connect(server)
        loop = asyncio.get_running_loop()
        started = loop.time()
        assert await _ask(reader, writer, request(b"01", b"0B"), 7) == ack(b"01")
        assert loop.time() - started >= 14 * pacing.char_time_s - 0.001
        writer.close()


# -- pty ------------------------------------------------------------------------------


@pytest.fixture
async def pty() -> AsyncIterator[PtyServer]:
    server = await open_pty_server(SimulatedBus(nodes=[1, 2]))
    yield server
    server.close()


class TtyClient:
    """A host on a terminal descriptor: writes requests, reads replies through the loop."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        os.set_blocking(fd, False)
        self.buffer = bytearray()
        self._readable = asyncio.Event()
        asyncio.get_running_loop().add_reader(self.fd, self._on_readable)

    def _on_readable(self) -> None:
        self.buffer += os.read(self.fd, 4096)
        self._readable.set()

    async def ask(self, raw: bytes, n: int) -> bytes:
        os.write(self.fd, raw)
        async with asyncio.timeout(TIMEOUT):
            while len(self.buffer) < n:
                self._readable.clear()
                await self._readable.wait()
        out = bytes(self.buffer[:n])
        del self.buffer[:n]
        return out

    def close(self) -> None:
        asyncio.get_running_loop().remove_reader(self.fd)
        os.close(self.fd)


def open_client(path: str) -> TtyClient:
    """Open a pty's slave like a serial port."""
    return TtyClient(os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK))


async def test_pty_path_is_a_terminal(pty: PtyServer) -> None:
    assert pty.path.startswith("/dev/")
    client = open_client(pty.path)
    assert os.isatty(client.fd)
    client.close()


async def test_pty_raw_request_and_reply_keeps_cr(pty: PtyServer) -> None:
    client = open_client(pty.path)
    reply = await client.ask(bytes.fromhex("02 30 31 30 30 31 33 30 0D"), 7)
    assert reply == bytes.fromhex("02 30 31 06 30 37 0D")  # CR stayed CR, nothing echoed
    expected = data_reply(b"02", b"0" * 104)  # node 2 is stopped: an all-zero monitor block
    assert await client.ask(request(b"02", b"03"), len(expected)) == expected
    await asyncio.sleep(0.02)
    assert client.buffer == b""  # no echo, no extra bytes
    client.close()


async def test_pty_slave_is_raw(pty: PtyServer) -> None:
    client = open_client(pty.path)
    iflag, oflag, _cflag, lflag, *_ = termios.tcgetattr(client.fd)
    assert not iflag & (termios.ICRNL | termios.INLCR | termios.IGNCR)
    assert not oflag & termios.OPOST
    assert not lflag & (termios.ECHO | termios.ICANON)
    client.close()


async def test_pty_survives_a_client_closing_and_another_opening(pty: PtyServer) -> None:
    first = open_client(pty.path)
    assert await first.ask(request(b"02", b"0B"), 7) == ack(b"02")
    first.close()
    await asyncio.sleep(0.02)  # a master with no slave open would now read EIO in a loop
    second = open_client(pty.path)
    assert await second.ask(request(b"02", b"0B"), 7) == ack(b"02")
    second.close()


async def test_pty_with_pyserial(pty: PtyServer) -> None:
    def talk() -> bytes:
        with serial.Serial(pty.path, 19200, timeout=TIMEOUT) as port:
            port.write(request(b"01", b"06", b"F002"))
            return bytes(port.read(15))

    assert await asyncio.to_thread(talk) == ack_data(b"01", b"00003000")


async def test_pty_close_is_idempotent() -> None:
    server = await open_pty_server(SimulatedBus(nodes=[1]))
    path = server.path
    server.close()
    server.close()
    # both sides are closed: the pty is gone and its path cannot be opened
    with pytest.raises(OSError, match=r"No such file|Input/output"):
        os.close(os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK))


# -- an existing serial device ------------------------------------------------------


async def test_serial_device_server_on_one_end_of_a_pty_pair() -> None:
    master, slave = os.openpty()  # stands in for socat's pair or a real port
    host = TtyClient(master)
    try:
        path = os.ttyname(slave)
        async with await serve_serial_device(
            SimulatedBus(nodes=[4]), path, settings=LinePacing(9600, 8, "N", 2)
        ) as server:
            assert server.path == path
            _iflag, _oflag, cflag, lflag, ispeed, ospeed, _cc = termios.tcgetattr(slave)
            assert ispeed == ospeed == termios.B9600
            assert cflag & termios.CSTOPB
            assert not lflag & termios.ECHO
            reply = await host.ask(request(b"04", b"06", b"C072"), 15)
            assert reply == ack_data(b"04", b"00000004")
    finally:
        host.close()
        os.close(slave)


async def test_serial_device_refuses_a_speed_the_system_lacks() -> None:
    master, slave = os.openpty()
    try:
        with pytest.raises(ValueError, match="12345 bps"):
            await serve_serial_device(
                SimulatedBus(nodes=[1]), os.ttyname(slave), settings=LinePacing(12345)
            )
    finally:
        os.close(master)
        os.close(slave)
