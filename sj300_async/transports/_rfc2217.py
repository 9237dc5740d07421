"""RFC 2217 transport: a serial port on an access server, its line settings set from here.

Where :mod:`._tcp` passes raw bytes to a device server configured by hand,
an RFC 2217 server (ser2net's ``telnet(rfc2217)`` accepter, a Moxa NPort
or a Lantronix in RFC 2217 mode) speaks telnet and lets the client set the
port's speed and character format. The connector:

1. opens TCP (no Nagle delay, keep-alive on, as :mod:`._tcp`);
2. negotiates BINARY both ways, SUPPRESS-GO-AHEAD, and the client's
   COM-PORT-OPTION; BINARY and COM-PORT-OPTION are required;
3. sends SET-BAUDRATE, SET-DATASIZE, SET-PARITY, SET-STOPSIZE and
   PURGE-DATA (both buffers) at once and waits for every answer: the server
   answers each with the value now in force, which must be the one asked;
4. only then hands the transport to the protocol (``connection_made``).

A server that refuses an option or a setting raises
:class:`Rfc2217RefusedError`; one that does not answer within
``confirm_timeout_s``, :class:`Rfc2217TimeoutError`. Both name the host,
the port and the setting, and the connection is closed again.

The protocol sees the serial bytes only: the telnet layer (a sans-IO codec,
:mod:`._telnet`) unescapes 0xFF on the way in and escapes it on the way
out; the server's line and modem notifications are kept on the transport
(``get_extra_info("line_state")``, ``"modem_state"``), never passed on as
data. :meth:`Rfc2217Transport.set_line` changes the settings of an open
connection, confirmed the same way.

The python library that does this, pyserial's ``rfc2217://``, is threaded
and blocking; its asyncio wrapper cannot drive it (pyserial-asyncio issue
46), hence this one.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable
from typing import Any, Final, cast

from ..wire import LineSettings, TransportError
from ._buffered import BufferedReads
from ._telnet import (
    BINARY,
    COM_PORT,
    PURGE_BOTH,
    SGA,
    BadSubnegotiation,
    ComPortCommand,
    ComPortReply,
    FlowControl,
    LineState,
    LineStateChanged,
    ModemState,
    ModemStateChanged,
    OptionChanged,
    OptState,
    Payload,
    Side,
    Signature,
    TelnetCodec,
    TelnetError,
    TelnetEvent,
    com_port_command,
    escape,
    line_commands,
)

__all__ = [
    "Rfc2217Error",
    "Rfc2217RefusedError",
    "Rfc2217TimeoutError",
    "Rfc2217Transport",
    "rfc2217_connector",
]

_log = logging.getLogger(__name__)

#: How long the server may take to agree the options and confirm the settings.
#: Under the link's connect time-out (3 s by default), so that a silent server
#: is reported as what it is rather than as a connection that timed out.
DEFAULT_CONFIRM_TIMEOUT_S: Final = 2.0

_TCP_QUICKACK: Final[int | None] = getattr(socket, "TCP_QUICKACK", None)

_LOCAL: Final = frozenset({BINARY, SGA, COM_PORT})
# The server's WILL COM-PORT-OPTION is accepted too: RFC 2217 has the client
# offer it, but some servers (pyserial's) offer it themselves as well.
_REMOTE: Final = frozenset({BINARY, SGA, COM_PORT})
#: What the client must have agreed before it sends a COM-PORT command.
_REQUIRED: Final = ((Side.LOCAL, BINARY), (Side.REMOTE, BINARY), (Side.LOCAL, COM_PORT))
_OPTION_NAMES: Final = {BINARY: "BINARY", SGA: "SUPPRESS-GO-AHEAD", COM_PORT: "COM-PORT-OPTION"}
_SETTING_NAMES: Final = {
    ComPortCommand.SET_BAUDRATE: "baud rate",
    ComPortCommand.SET_DATASIZE: "data bits",
    ComPortCommand.SET_PARITY: "parity",
    ComPortCommand.SET_STOPSIZE: "stop bits",
    ComPortCommand.PURGE_DATA: "purge",
}


class Rfc2217Error(TransportError):
    """The RFC 2217 server did not set up the port as asked; the connection is closed.

    Attributes:
        host, port: the server.
        setting: what it refused or did not confirm (``"baud rate 19200"``,
            ``"COM-PORT-OPTION"``).
    """

    def __init__(self, message: str, host: str, port: int, setting: str) -> None:
        super().__init__(message)
        self.host = host
        self.port = port
        self.setting = setting

    def __reduce__(self) -> tuple[type[Rfc2217Error], tuple[str, str, int, str]]:
        return (type(self), (str(self), self.host, self.port, self.setting))


class Rfc2217RefusedError(Rfc2217Error):
    """The server refused an option or a setting, or confirmed another value than asked."""


# Not a TimeoutError as well, unlike ReplyTimeoutError: the link takes any
# TimeoutError out of a connector for its own connect time-out and reports
# "timed out after 3 s", which would lose which setting went unanswered.
class Rfc2217TimeoutError(Rfc2217Error):
    """The server did not answer the negotiation or a setting within the time-out."""


def rfc2217_connector(
    host: str,
    port: int,
    line: LineSettings,
    *,
    confirm_timeout_s: float = DEFAULT_CONFIRM_TIMEOUT_S,
) -> Callable[[Callable[[], asyncio.Protocol]], Any]:
    """Return a connector that opens an RFC 2217 port on *host*:*port* set to *line*."""
    if line.baudrate == 0:
        raise TransportError("an RFC 2217 port needs a baud rate")

    async def connect(protocol_factory: Callable[[], asyncio.Protocol]) -> asyncio.BaseTransport:
        loop = asyncio.get_running_loop()
        transport = Rfc2217Transport(loop, host, port, confirm_timeout_s=confirm_timeout_s)
        tcp, _ = await loop.create_connection(lambda: _TcpSide(transport), host, port)
        sock = tcp.get_extra_info("socket")
        if sock is not None:
            # Frames are tiny and latency is everything: never wait to coalesce them.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        try:
            await transport._open(line)
        except BaseException:
            tcp.abort()  # also on cancellation (the link's connect time-out): no socket left
            raise
        transport._attach(protocol_factory())
        return transport

    return connect


class _TcpSide(BufferedReads):
    """The TCP connection's protocol: hands everything to the RFC 2217 transport above it."""

    def __init__(self, owner: Rfc2217Transport) -> None:
        super().__init__()
        self._owner = owner

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not isinstance(): uvloop's transports implement the interface without
        # deriving from asyncio's classes.
        transport = cast(asyncio.Transport, transport)
        self._owner._tcp = transport

    def data_received(self, data: bytes) -> None:
        self._owner._tcp_data(data)

    def eof_received(self) -> bool | None:
        return self._owner._tcp_eof()

    def connection_lost(self, exc: Exception | None) -> None:
        self._owner._tcp_lost(exc)

    def pause_writing(self) -> None:
        self._owner._tcp_pause_writing()

    def resume_writing(self) -> None:
        self._owner._tcp_resume_writing()


class Rfc2217Transport(asyncio.Transport):
    """A serial port on an RFC 2217 server, as an asyncio transport. Use :func:`rfc2217_connector`.

    Flow control is the TCP connection's: write-buffer limits, sizes and
    pause/resume_writing pass through (the buffer holds the escaped bytes).
    A write after :meth:`close` is ignored. :meth:`write_eof` is not
    supported: a serial line has no end of file.

    ``get_extra_info`` answers ``"line_settings"`` (the settings the server
    confirmed), ``"line_state"`` and ``"modem_state"`` (the last
    notifications), ``"signature"`` (the server's, if it sent one), and
    whatever the TCP transport answers (``"socket"``, ``"peername"``...).
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        host: str,
        port: int,
        *,
        confirm_timeout_s: float = DEFAULT_CONFIRM_TIMEOUT_S,
    ) -> None:
        super().__init__()
        self._loop = loop
        self.host = host
        self.port = port
        self._confirm_timeout_s = confirm_timeout_s
        self._codec = TelnetCodec(local=_LOCAL, remote=_REMOTE)
        self._tcp: asyncio.Transport | None = None
        self._protocol: asyncio.Protocol | None = None
        self._closing = False
        self._lost = False
        #: The error that made the transport close the connection itself (a telnet violation).
        self._error: Exception | None = None
        self._negotiated: asyncio.Future[None] | None = None
        self._waiters: dict[ComPortCommand, asyncio.Future[int]] = {}
        self._exchange_lock = asyncio.Lock()
        # Reading paused by the protocol. Serial bytes that arrive meanwhile (the
        # TCP side reads on during set_line, for the server's answers) are held.
        self._paused = False
        self._held = bytearray()
        #: The settings the server confirmed last.
        self.line: LineSettings | None = None
        #: The server's last NOTIFY-LINESTATE and NOTIFY-MODEMSTATE.
        self.line_state = LineState(0)
        self.modem_state = ModemState(0)
        #: The server's signature, if it sent one.
        self.signature: str | None = None
        #: True while the server has asked the client to stop sending (FLOWCONTROL-SUSPEND).
        self.suspended = False
        #: Serial bytes discarded because they arrived before the purge at connection.
        self.discarded_bytes = 0
        #: Subnegotiations and telnet commands that meant nothing to the client.
        self.ignored_commands = 0

    def __repr__(self) -> str:
        state = "closing" if self._closing else "open"
        return f"<Rfc2217Transport {self.host}:{self.port} {self.line} {state}>"

    @property
    def _where(self) -> str:
        return f"RFC 2217 server {self.host}:{self.port}"

    # -- opening -------------------------------------------------------------------------

    async def _open(self, line: LineSettings) -> None:
        """Negotiate the options, set *line*, purge; raise an :class:`Rfc2217Error` if refused."""
        assert self._tcp is not None
        self._negotiated = self._loop.create_future()
        requests = b"".join(self._codec.request(side, option) for side, option in _REQUESTS)
        self._tcp.write(requests)
        self._check_negotiation()  # the server's own offers may have settled it already
        try:
            async with asyncio.timeout(self._confirm_timeout_s):
                await self._negotiated
        except TimeoutError:
            missing = [
                _OPTION_NAMES[o]
                for s, o in _REQUIRED
                if self._codec.state(s, o) is not OptState.YES
            ]
            raise Rfc2217TimeoutError(
                f"{self._where} did not agree {', '.join(missing)} within "
                f"{self._confirm_timeout_s:g} s (is it an RFC 2217 port, not a raw one?)",
                self.host,
                self.port,
                missing[0],
            ) from None
        await self._configure(line, purge=True)

    def _check_negotiation(self) -> None:
        waiter = self._negotiated
        if waiter is None or waiter.done():
            return
        for side, option in _REQUIRED:
            state = self._codec.state(side, option)
            if state is OptState.NO:
                name = _OPTION_NAMES[option]
                how = "perform" if side is Side.REMOTE else "accept"
                waiter.set_exception(
                    Rfc2217RefusedError(
                        f"{self._where} refused to {how} {name}", self.host, self.port, name
                    )
                )
                return
        if all(self._codec.state(s, o) is OptState.YES for s, o in _REQUIRED):
            waiter.set_result(None)

    def _attach(self, protocol: asyncio.Protocol) -> None:
        """Hand the transport to *protocol*; called once, when the port is set up."""
        self._protocol = protocol
        protocol.connection_made(self)

    # -- line settings -------------------------------------------------------------------

    async def set_line(self, line: LineSettings) -> None:
        """Set the server's port to *line* and wait until the server confirms every setting.

        Raises:
            Rfc2217RefusedError: the server confirmed another value (the
                connection stays open; :attr:`line` is not changed).
            Rfc2217TimeoutError: no confirmation within the time-out.
            TransportError: the transport is closing or closed.
        """
        await self._configure(line, purge=False)

    async def _configure(self, line: LineSettings, *, purge: bool) -> None:
        if line.baudrate == 0:
            raise TransportError("an RFC 2217 port needs a baud rate")
        asked = line_commands(line)
        if purge:
            # After the settings: what reached the server's buffers at the old
            # settings is noise at the new ones.
            asked.append((ComPortCommand.PURGE_DATA, PURGE_BOTH))
        async with self._exchange_lock:
            answers = await self._exchange(asked)
        for (command, value), answer in zip(asked, answers, strict=True):
            if answer != value:
                setting = _describe(command, value)
                raise Rfc2217RefusedError(
                    f"{self._where} refused {setting}: it answered {_describe(command, answer)}",
                    self.host,
                    self.port,
                    setting,
                )
        self.line = line

    async def _exchange(self, asked: list[tuple[ComPortCommand, int]]) -> list[int]:
        """Send every command at once; return the server's answers in the same order."""
        tcp = self._tcp
        if tcp is None or self._closing or self._lost:
            raise TransportError(f"{self._where}: the connection is closed")
        # Each waiter is registered before its command is written, and removed
        # in `finally`: an answer can neither come too early nor outlive the call.
        waiters = [self._loop.create_future() for _ in asked]
        for (command, _), waiter in zip(asked, waiters, strict=True):
            self._waiters[command] = waiter
        if self._paused:
            tcp.resume_reading()  # the answers must get through; serial bytes are held
        try:
            tcp.write(b"".join(com_port_command(command, value) for command, value in asked))
            async with asyncio.timeout(self._confirm_timeout_s):
                return [await waiter for waiter in waiters]
        except TimeoutError:
            # The one awaited when the time ran out was cancelled by it; later ones are pending.
            pending = next(i for i, w in enumerate(waiters) if w.cancelled() or not w.done())
            setting = _describe(*asked[pending])
            raise Rfc2217TimeoutError(
                f"{self._where} did not confirm {setting} within {self._confirm_timeout_s:g} s",
                self.host,
                self.port,
                setting,
            ) from None
        finally:
            for command, _ in asked:
                self._waiters.pop(command, None)
            for waiter in waiters:
                if not waiter.done():
                    waiter.cancel()
                elif not waiter.cancelled():
                    waiter.exception()  # retrieved: the first failure is the one raised
            if self._paused and not self._lost and not tcp.is_closing():
                tcp.pause_reading()

    # -- from the TCP connection ---------------------------------------------------------

    def _tcp_data(self, data: bytes) -> None:
        if self._waiters or not self._negotiated_done():
            self._ack_now()
        try:
            events = self._codec.feed(data)
        except TelnetError as exc:
            _log.warning("%s: %s; closing", self._where, exc)
            self._error = exc
            self.abort()
            return
        answer = self._codec.data_to_send()
        if answer and self._tcp is not None:
            self._tcp.write(answer)
        for event in events:
            self._handle(event)

    def _negotiated_done(self) -> bool:
        return self._negotiated is not None and self._negotiated.done()

    def _ack_now(self) -> None:
        """Acknowledge what just arrived at once, while answers are awaited (Linux only).

        ser2net (gensio) writes its answers without TCP_NODELAY unless its accepter
        says ``tcp(nodelay)``, and it answers PURGE-DATA at once but the settings a
        moment later: Nagle then holds those until the purge's answer is
        acknowledged, which the kernel delays by 40 ms when the client has nothing
        to send: the connection would wait that long for its settings. Quick-ack
        mode lapses by itself, hence once per chunk.
        """
        sock = self._tcp.get_extra_info("socket") if self._tcp is not None else None
        if sock is not None and _TCP_QUICKACK is not None:
            sock.setsockopt(socket.IPPROTO_TCP, _TCP_QUICKACK, 1)

    def _handle(self, event: TelnetEvent) -> None:
        if isinstance(event, Payload):
            self._deliver(event.data)
        elif isinstance(event, ComPortReply):
            waiter = self._waiters.pop(event.command, None)
            if waiter is not None and not waiter.done():
                waiter.set_result(event.value)
            else:
                _log.debug("%s: unasked answer %s %d", self._where, event.command.name, event.value)
        elif isinstance(event, OptionChanged):
            name = _OPTION_NAMES.get(event.option, str(event.option))
            state = "on" if event.enabled else "off"
            _log.debug("%s: %s option %s %s", self._where, event.side.value, name, state)
            self._check_negotiation()
        elif isinstance(event, ModemStateChanged):
            self.modem_state = event.state
            _log.debug("%s: modem state %s", self._where, event.state)
        elif isinstance(event, LineStateChanged):
            self.line_state = event.state
            _log.debug("%s: line state %s", self._where, event.state)
        elif isinstance(event, FlowControl):
            # Nothing is held back for it: a master on a bus writes one short
            # request at a time, and the server's buffer is what it protects.
            self.suspended = event.suspended
            _log.debug(
                "%s: flow control %s", self._where, "suspend" if event.suspended else "resume"
            )
        elif isinstance(event, Signature):
            self.signature = event.text
        else:
            self.ignored_commands += 1
            if isinstance(event, BadSubnegotiation):
                _log.debug(
                    "%s: ignored subnegotiation of option %d (%s): %s",
                    self._where,
                    event.option,
                    event.reason,
                    event.payload.hex(" "),
                )
            else:
                _log.debug("%s: ignored %r", self._where, event)

    def _deliver(self, data: bytes) -> None:
        if self._protocol is None:
            # Before connection_made: the purge is for these (nothing has been sent yet).
            self.discarded_bytes += len(data)
            _log.debug("%s: discarded before the purge: %s", self._where, data.hex(" "))
        elif self._paused:
            self._held += data
        else:
            self._protocol.data_received(data)

    def _tcp_eof(self) -> bool | None:
        if self._protocol is not None:
            return self._protocol.eof_received()
        return None

    def _tcp_lost(self, exc: Exception | None) -> None:
        self._lost = True
        self._closing = True
        gone = TransportError(f"{self._where} closed the connection")
        for waiter in self._waiters.values():
            if not waiter.done():
                waiter.set_exception(gone)
        if self._negotiated is not None and not self._negotiated.done():
            self._negotiated.set_exception(gone)
        if self._protocol is not None:
            self._protocol.connection_lost(exc or self._error)

    def _tcp_pause_writing(self) -> None:
        if self._protocol is not None:
            self._protocol.pause_writing()

    def _tcp_resume_writing(self) -> None:
        if self._protocol is not None:
            self._protocol.resume_writing()

    # -- asyncio.Transport ---------------------------------------------------------------

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        own = {
            "line_settings": self.line,
            "line_state": self.line_state,
            "modem_state": self.modem_state,
            "signature": self.signature,
        }
        if name in own:
            value = own[name]
            return default if value is None else value
        if self._tcp is None:
            return default
        return self._tcp.get_extra_info(name, default)

    def write(self, data: bytes | bytearray | memoryview) -> None:
        if self._closing or self._tcp is None or not data:
            return
        self._tcp.write(escape(bytes(data)))

    def can_write_eof(self) -> bool:
        return False

    def is_closing(self) -> bool:
        return self._closing

    def close(self) -> None:
        if self._closing:
            return
        self._closing = True
        if self._tcp is not None:
            self._tcp.close()  # flushes what is buffered, then connection_lost

    def abort(self) -> None:
        self._closing = True
        if self._tcp is not None:
            self._tcp.abort()

    def set_protocol(self, protocol: asyncio.BaseProtocol) -> None:
        assert isinstance(protocol, asyncio.Protocol)
        self._protocol = protocol

    def get_protocol(self) -> asyncio.BaseProtocol:
        assert self._protocol is not None, "not connected yet"
        return self._protocol

    def is_reading(self) -> bool:
        return not self._paused and not self._closing

    def pause_reading(self) -> None:
        if self._paused or self._closing:
            return
        self._paused = True
        if self._tcp is not None:
            self._tcp.pause_reading()

    def resume_reading(self) -> None:
        if not self._paused or self._closing:
            return
        self._paused = False
        if self._tcp is not None:
            self._tcp.resume_reading()
        if self._held:
            # Not from inside resume_reading(): the protocol may be in the middle of a call.
            self._loop.call_soon(self._deliver_held)

    def _deliver_held(self) -> None:
        if self._paused or not self._held or self._protocol is None:
            return
        data = bytes(self._held)
        self._held.clear()
        self._protocol.data_received(data)

    def set_write_buffer_limits(self, high: int | None = None, low: int | None = None) -> None:
        if self._tcp is not None:
            self._tcp.set_write_buffer_limits(high, low)

    def get_write_buffer_size(self) -> int:
        return self._tcp.get_write_buffer_size() if self._tcp is not None else 0

    def get_write_buffer_limits(self) -> tuple[int, int]:
        return self._tcp.get_write_buffer_limits() if self._tcp is not None else (0, 0)


#: What the client asks at connection; it accepts the same of the server's offers.
_REQUESTS: Final = (
    (Side.LOCAL, BINARY),
    (Side.REMOTE, BINARY),
    (Side.LOCAL, SGA),
    (Side.REMOTE, SGA),
    (Side.LOCAL, COM_PORT),
)


def _describe(command: ComPortCommand, value: int) -> str:
    """``"baud rate 19200"``, ``"parity E"``: a setting as a message names it."""
    name = _SETTING_NAMES.get(command, command.name)
    if command is ComPortCommand.SET_PARITY:
        letters = {1: "N", 2: "O", 3: "E", 4: "mark", 5: "space"}
        return f"{name} {letters.get(value, value)}"
    if command is ComPortCommand.SET_STOPSIZE and value == 3:
        return f"{name} 1.5"
    if command is ComPortCommand.PURGE_DATA:
        return "purge of both buffers" if value == PURGE_BOTH else f"purge {value}"
    return f"{name} {value}"
