"""The RFC 2217 transport beyond the shared contract (test_contract.py and
test_asyncio_transport.py run it through ser2net like every other transport).

- real ser2net (``telnet(rfc2217)``) on the simulator's own pseudo-terminal:
  the URL's settings and a change on the open connection reach the terminal
  the simulator holds, and requests are answered at each speed;
- pyserial's RFC 2217 server (``PortManager``, an independent implementation)
  over its loopback port: settings, purge, escaping both ways, a change while
  reading is paused;
- scripted servers for what ser2net cannot be made to do: never confirm,
  refuse the option, confirm another value, hang up, say nothing at all, and
  put line and modem notifications between serial bytes;
- the URL form.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import termios
from collections.abc import AsyncIterator, Callable

import pytest
from waiting import wait_for

import sj300_async as sj
from sj300_async import LineSettings
from sj300_async.bus import parse_bus_url
from sj300_async.simulator import open_pty_server
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.transports import (
    Rfc2217Error,
    Rfc2217RefusedError,
    Rfc2217TimeoutError,
    Rfc2217Transport,
    rfc2217_connector,
)
from sj300_async.transports._telnet import LineState, ModemState

from .bridges import ser2net
from .rawline import Recorder

IAC, SB, SE, WILL, WONT, DO, DONT = 255, 250, 240, 251, 252, 253, 254
BINARY, COM_PORT = 0, 44
#: Node 01, command 04 (read status), BCC "05": one SJ300 request frame.
READ_STATUS_1 = b"\x020104" + b"05\r"


async def _connect(
    port: int, line: LineSettings, *, confirm_timeout_s: float = 2.0
) -> tuple[Rfc2217Transport, Recorder]:
    recorder = Recorder()
    connect = rfc2217_connector("127.0.0.1", port, line, confirm_timeout_s=confirm_timeout_s)
    transport = await connect(lambda: recorder)
    assert isinstance(transport, Rfc2217Transport)
    assert recorder.events == ["made"]  # connection_made only once the line is set
    return transport, recorder


async def _close(transport: asyncio.Transport, recorder: Recorder) -> None:
    transport.close()
    await asyncio.wait_for(recorder.lost.wait(), 5)


# -- real ser2net on the simulator's own pseudo-terminal -----------------------------------------
#
# Why not the socat pair the contract suite uses: socat holds the masters of two
# separate pseudo-terminals and copies bytes between them, never their termios.
# Checked with ser2net 4.3.11: SET-BAUDRATE 19200 moved ser2net's end (B9600 ->
# B19200) while the simulator's end stayed at B38400. Here ser2net opens the slave
# of the simulator's own pty; Linux answers termios requests on a master with the
# slave's settings, so the simulator's descriptor sees what ser2net set. A Linux
# pty keeps speed and stop bits but forces 8 data bits and no parity (ser2net
# confirms parity E all the same): speed and stop bits are what can be seen.


def _speed_and_stopbits(fd: int) -> tuple[int, int]:
    attrs = termios.tcgetattr(fd)
    return attrs[4], 2 if attrs[2] & termios.CSTOPB else 1


@contextlib.asynccontextmanager
async def _simulator_behind_ser2net() -> AsyncIterator[tuple[int, int]]:
    """The simulator on a pty, ser2net (RFC 2217) on its slave: yields (simulator's fd, port)."""
    sim = SimulatedBus(nodes=(1,))
    async with await open_pty_server(sim) as server, ser2net(server.path, rfc2217=True) as port:
        yield server._master, port  # the descriptor the simulator reads and writes


async def test_the_urls_line_settings_reach_the_simulators_terminal() -> None:
    async with _simulator_behind_ser2net() as (fd, port):
        url = f"rfc2217://127.0.0.1:{port}?baudrate=9600&stopbits=2"
        async with sj.open_bus(url, timeout=1.0) as bus:
            await wait_for(
                lambda: _speed_and_stopbits(fd) == (termios.B9600, 2), "9600 baud, 2 stop bits"
            )
            assert (await bus.drive(1).read_status()).b is sj.StatusB.STOPPED


async def test_a_baud_rate_change_on_the_open_connection_reaches_the_simulator() -> None:
    async with _simulator_behind_ser2net() as (fd, port):
        transport, recorder = await _connect(port, LineSettings(9600))
        try:
            await wait_for(lambda: _speed_and_stopbits(fd) == (termios.B9600, 1), "9600 baud")
            assert transport.get_extra_info("line_settings") == LineSettings(9600)
            transport.write(READ_STATUS_1)
            await wait_for(lambda: recorder.received.endswith(b"\r"), "an answer at 9600")

            await transport.set_line(LineSettings(19200, stopbits=2))
            await wait_for(
                lambda: _speed_and_stopbits(fd) == (termios.B19200, 2), "19200 baud, 2 stop bits"
            )
            assert transport.line == LineSettings(19200, stopbits=2)
            recorder.received.clear()
            transport.write(READ_STATUS_1)
            await wait_for(lambda: recorder.received.endswith(b"\r"), "an answer at 19200")
            assert recorder.received.startswith(b"\x0201")  # node 01's answer, nothing else
        finally:
            await _close(transport, recorder)


# -- pyserial's RFC 2217 server ------------------------------------------------------------------


class _PyserialServer(asyncio.Protocol):
    """pyserial's PortManager on its ``loop://`` port: what the client writes comes back."""

    def __init__(self, ports: list[object]) -> None:
        self._ports = ports

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        import serial
        from serial.rfc2217 import PortManager

        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.serial = serial.serial_for_url("loop://", timeout=0)
        self._ports.append(self.serial)
        self.manager = PortManager(self.serial, self)  # writes its negotiation through .write

    def write(self, data: bytes) -> None:
        self.transport.write(data)

    def data_received(self, data: bytes) -> None:
        for byte in self.manager.filter(data):
            self.serial.write(byte)
        waiting = self.serial.in_waiting
        if waiting:
            self.transport.write(b"".join(self.manager.escape(self.serial.read(waiting))))

    def connection_lost(self, exc: Exception | None) -> None:
        self.serial.close()


@contextlib.asynccontextmanager
async def _pyserial_server() -> AsyncIterator[tuple[int, list[object]]]:
    ports: list[object] = []
    loop = asyncio.get_running_loop()
    srv = await loop.create_server(lambda: _PyserialServer(ports), "127.0.0.1", 0)
    try:
        yield srv.sockets[0].getsockname()[1], ports
    finally:
        srv.close()
        await srv.wait_closed()


async def test_pyserials_server_gets_the_settings_and_the_bytes() -> None:
    async with _pyserial_server() as (port, ports):
        transport, recorder = await _connect(port, LineSettings(9600, 7, "E", 2))
        try:
            (serial_port,) = ports
            settings = (serial_port.baudrate, serial_port.bytesize, serial_port.parity)  # type: ignore[attr-defined]
            assert settings == (9600, 7, "E")
            assert serial_port.stopbits == 2  # type: ignore[attr-defined]
            # The server told its modem lines once the client agreed RFC 2217.
            assert isinstance(transport.modem_state, ModemState)
            payload = bytes(range(256)) * 4  # every byte value, 0xFF among them
            transport.write(payload)
            await wait_for(lambda: len(recorder.received) >= len(payload), "the echo")
            assert recorder.received == payload  # unescaped, and nothing but the serial bytes

            await transport.set_line(LineSettings(19200))
            assert serial_port.baudrate == 19200  # type: ignore[attr-defined]
            assert serial_port.stopbits == 1  # type: ignore[attr-defined]
        finally:
            await _close(transport, recorder)


async def test_a_change_while_reading_is_paused_holds_the_serial_bytes() -> None:
    async with _pyserial_server() as (port, _):
        transport, recorder = await _connect(port, LineSettings(9600))
        try:
            transport.pause_reading()
            transport.write(b"held \xff bytes")
            # The answers get through while reading is paused; the echo is held.
            await transport.set_line(LineSettings(19200))
            assert transport.line == LineSettings(19200)
            assert not transport.is_reading()
            assert recorder.received == b""
            transport.resume_reading()
            await wait_for(lambda: recorder.received == b"held \xff bytes", "the held bytes")
        finally:
            await _close(transport, recorder)


# -- scripted servers ----------------------------------------------------------------------------

# One token of what the client sends: a COM-PORT command, a negotiation, or a serial byte.
_TOKEN = re.compile(
    rb"\xff\xfa\x2c(?P<code>.)(?P<value>(?:[^\xff]|\xff\xff)*)\xff\xf0"
    rb"|\xff(?P<verb>[\xfb-\xfe])(?P<option>.)"
    rb"|(?P<byte>\xff\xff|[^\xff])",
    re.S,
)
#: Every option the client needs, offered at once (as ser2net does).
_WILLING = bytes([IAC, DO, BINARY, IAC, WILL, BINARY, IAC, DO, COM_PORT])


def _reply(code: int, value: bytes) -> bytes:
    return (
        bytes([IAC, SB, COM_PORT, 100 + code])
        + value.replace(b"\xff", b"\xff\xff")
        + bytes([IAC, SE])
    )


Script = Callable[["_Scripted", int, bytes], None]


class _Scripted(asyncio.Protocol):
    """A server that greets, then calls its script for each COM-PORT command or negotiation.

    The script gets the command code (or the verb, for WILL/WONT/DO/DONT) and the value
    (or the option). Serial bytes are kept in ``data`` (unescaped), everything received in
    ``raw``; serial ``b"go"`` is answered with *on_go*.
    """

    def __init__(self, greeting: bytes, script: Script, on_go: bytes = b"") -> None:
        self._greeting = greeting
        self._script = script
        self._on_go = on_go
        self._buffer = bytearray()
        self.data = bytearray()
        self.raw = bytearray()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        transport.write(self._greeting)

    def data_received(self, data: bytes) -> None:
        self.raw += data
        self._buffer += data
        position = 0
        while match := _TOKEN.match(self._buffer, position):  # an unfinished token waits
            if match["byte"] is not None:
                self.data += match["byte"][:1]
            elif match["verb"] is not None:
                self._script(self, match["verb"][0], match["option"])
            else:
                self._script(self, match["code"][0], match["value"].replace(b"\xff\xff", b"\xff"))
            position = match.end()
        del self._buffer[:position]
        if self._on_go and self.data.endswith(b"go"):
            self.transport.write(self._on_go)


@contextlib.asynccontextmanager
async def _scripted(greeting: bytes, script: Script, on_go: bytes = b"") -> AsyncIterator[int]:
    loop = asyncio.get_running_loop()
    server = await loop.create_server(lambda: _Scripted(greeting, script, on_go), "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()
        await server.wait_closed()


def _confirm(server: _Scripted, code: int, value: bytes) -> None:
    """A well-behaved server: every setting confirmed as asked."""
    if code < 100:
        server.transport.write(_reply(code, value))


def _silent(server: _Scripted, code: int, value: bytes) -> None:
    """Agrees the options (in its greeting), then never answers a setting."""


async def test_a_server_that_never_confirms_is_a_typed_error_within_the_time_out() -> None:
    async with _scripted(_WILLING, _silent) as port:
        loop = asyncio.get_running_loop()
        start = loop.time()
        with pytest.raises(Rfc2217TimeoutError) as info:
            await _connect(port, LineSettings(19200), confirm_timeout_s=0.2)
        assert 0.2 <= loop.time() - start < 1.0
    error = info.value
    assert isinstance(error, sj.TransportError)
    assert (error.host, error.port, error.setting) == ("127.0.0.1", port, "baud rate 19200")
    assert str(error) == (
        f"RFC 2217 server 127.0.0.1:{port} did not confirm baud rate 19200 within 0.2 s"
    )


async def test_a_server_that_says_nothing_at_all_is_not_an_rfc2217_port() -> None:
    async with _scripted(b"", _silent) as port:
        with pytest.raises(Rfc2217TimeoutError, match="did not agree BINARY, BINARY, COM-PORT"):
            await _connect(port, LineSettings(19200), confirm_timeout_s=0.1)


def _refuse_com_port(server: _Scripted, code: int, value: bytes) -> None:
    if code == WILL and value == bytes([COM_PORT]):
        server.transport.write(bytes([IAC, DONT, COM_PORT]))


async def test_a_server_that_refuses_the_option_is_refused_through_open_bus() -> None:
    greeting = bytes([IAC, DO, BINARY, IAC, WILL, BINARY])
    async with _scripted(greeting, _refuse_com_port) as port:
        with pytest.raises(Rfc2217RefusedError) as info:
            async with sj.open_bus(f"rfc2217://127.0.0.1:{port}"):
                pass
    assert info.value.setting == "COM-PORT-OPTION"
    assert str(info.value) == f"RFC 2217 server 127.0.0.1:{port} refused to accept COM-PORT-OPTION"


def _other_baud(server: _Scripted, code: int, value: bytes) -> None:
    if code == 1:
        value = (9600).to_bytes(4, "big")
    _confirm(server, code, value)


async def test_a_server_that_sets_another_speed_is_refused() -> None:
    async with _scripted(_WILLING, _other_baud) as port:
        with pytest.raises(Rfc2217RefusedError) as info:
            await _connect(port, LineSettings(19200))
    assert info.value.setting == "baud rate 19200"
    assert str(info.value).endswith("refused baud rate 19200: it answered baud rate 9600")


def _hang_up(server: _Scripted, code: int, value: bytes) -> None:
    server.transport.close()


async def test_a_server_that_hangs_up_while_setting_up_is_a_transport_error() -> None:
    async with _scripted(_WILLING, _hang_up) as port:
        with pytest.raises(sj.TransportError, match="closed the connection"):
            await _connect(port, LineSettings(19200))


def _notify_among_data(server: _Scripted, code: int, value: bytes) -> None:
    _confirm(server, code, value)
    if code == 12:  # the purge's answer, and right behind it bytes from before the purge
        server.transport.write(b"before the purge")


async def test_notifications_between_serial_bytes_are_kept_not_delivered() -> None:
    linestate = _reply(6, bytes([LineState.PARITY_ERROR | LineState.DATA_READY]))
    modemstate = _reply(7, bytes([ModemState.CTS | ModemState.DELTA_CTS]))
    stream = b"ab" + linestate + b"c\xff\xffd" + modemstate + b"e"
    async with _scripted(_WILLING, _notify_among_data, on_go=stream) as port:
        transport, recorder = await _connect(port, LineSettings(19200))
        try:
            # Bytes that came with the purge's answer were sent before it: dropped, counted.
            assert transport.discarded_bytes == len(b"before the purge")
            transport.write(b"go")
            await wait_for(lambda: recorder.received == b"abc\xffde", "the serial bytes")
            assert transport.get_extra_info("line_state") == (
                LineState.PARITY_ERROR | LineState.DATA_READY
            )
            assert transport.get_extra_info("modem_state") == ModemState.CTS | ModemState.DELTA_CTS
        finally:
            await _close(transport, recorder)


async def test_writes_reach_the_server_escaped_and_a_write_after_close_is_ignored() -> None:
    servers: list[_Scripted] = []

    def keep(server: _Scripted, code: int, value: bytes) -> None:
        if server not in servers:
            servers.append(server)
        _confirm(server, code, value)

    async with _scripted(_WILLING, keep) as port:
        transport, recorder = await _connect(port, LineSettings(19200))
        transport.write(b"x\xffy")
        await wait_for(lambda: servers[0].data.endswith(b"x\xffy"), "the bytes")
        assert servers[0].raw.endswith(b"x\xff\xffy")  # escaped on the wire
        transport.close()
        transport.write(b"late")
        await asyncio.wait_for(recorder.lost.wait(), 5)
        assert recorder.lost_exc is None
        assert servers[0].data.endswith(b"x\xffy")  # nothing after close
        with pytest.raises(sj.TransportError, match="closed"):
            await transport.set_line(LineSettings(9600))


# -- the URL -------------------------------------------------------------------------------------


def test_the_url_form() -> None:
    address = parse_bus_url("rfc2217://bridge:4001")
    assert (address.scheme, address.host, address.port) == ("rfc2217", "bridge", 4001)
    assert address.line == LineSettings(19200, 8, "N", 1)  # set remotely: always some settings
    assert address.description == "rfc2217://bridge:4001"
    assert parse_bus_url("rfc2217://h:1?baudrate=9600&parity=E").line == LineSettings(9600, 8, "E")
    with pytest.raises(sj.LocalProtocolError, match="rfc2217 URL needs a host and a port"):
        parse_bus_url("rfc2217://bridge")


def test_the_errors_are_transport_errors_that_pickle() -> None:
    import pickle

    error = Rfc2217TimeoutError("message", "h", 1, "parity E")
    copy = pickle.loads(pickle.dumps(error))
    assert (type(copy), str(copy), copy.host, copy.port, copy.setting) == (
        Rfc2217TimeoutError,
        "message",
        "h",
        1,
        "parity E",
    )
    assert issubclass(Rfc2217Error, sj.TransportError)
    assert not issubclass(Rfc2217TimeoutError, TimeoutError)  # see _rfc2217.py: the link's
