"""The TCP server: a simulated bus behind a serial device server.

Like a serial-to-Ethernet gateway in raw TCP mode, it moves bytes and
nothing else: no framing of its own, one byte stream per connection. Every
connection gets its own :class:`SimulatorEndpoint` on the same bus, and the
same :class:`PacedLine`: clients share one line, as they would share the
gateway's one serial port. Unless told otherwise, no reply is faster than
the quickest exchange on a 19200-baud line, the fastest the drives run
(:class:`~._pacing.PlausibleLine`): a host's plausibility check would
refuse it.

It listens on loopback unless given another host: a simulator reachable
from the network is a choice, not a default.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from types import TracebackType
from typing import cast

from ..transports import BufferedReads
from ._endpoint import SimulatorEndpoint
from ._model import BusModel
from ._pacing import LinePacing, PacedLine, server_line

__all__ = ["SimulatorServer", "serve_tcp"]

_log = logging.getLogger("sj300_async.simulator")


class _Connection(BufferedReads):
    """One client of the device server."""

    def __init__(self, server: SimulatorServer) -> None:
        super().__init__()
        self._server = server
        self._transport: asyncio.Transport | None = None
        self._endpoint: SimulatorEndpoint | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not isinstance(): uvloop's transports implement the interface without
        # deriving from asyncio's classes.
        transport = cast(asyncio.Transport, transport)
        self._transport = transport
        send: Callable[[bytes], object] = transport.write
        tap = self._server.tap
        if tap is not None:

            def send(data: bytes) -> None:
                tap("tx", data)
                transport.write(data)

        # The loop calls data_received from the socket's reader: answer at once.
        self._endpoint = SimulatorEndpoint(
            self._server.bus, send=send, line=self._server.line, defer=False
        )
        self._server._connections.add(self)
        _log.debug("client connected: %s", transport.get_extra_info("peername"))

    def data_received(self, data: bytes) -> None:
        assert self._endpoint is not None
        if self._server.tap is not None:
            self._server.tap("rx", data)
        self._endpoint.data_received(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if self._endpoint is not None:
            self._endpoint.close()
        self._server._connections.discard(self)
        _log.debug("client disconnected (%s)", exc or "closed")

    def close(self) -> None:
        if self._endpoint is not None:
            self._endpoint.close()
        if self._transport is not None:
            self._transport.close()


class SimulatorServer:
    """A listening TCP simulator: ``port``, :meth:`close`, :meth:`wait_closed`.

    Use :func:`serve_tcp` to make one. Also an async context manager.
    """

    def __init__(
        self, bus: BusModel, line: PacedLine | None, tap: Callable[[str, bytes], None] | None = None
    ) -> None:
        self.bus = bus
        self.line = line
        #: Called with every chunk as it crosses the line: ``("rx", host bytes)``
        #: as they arrive, ``("tx", reply bytes)`` as they are sent (a line log;
        #: for clients connected after it is set).
        self.tap = tap
        #: The address the listener is bound to.
        self.host = ""
        #: The bound port (the real one when 0 was asked for).
        self.port = 0
        self._server: asyncio.Server | None = None
        self._connections: set[_Connection] = set()

    @property
    def sockets(self) -> tuple[object, ...]:
        """The listening sockets."""
        return () if self._server is None else tuple(self._server.sockets)

    @property
    def connections(self) -> int:
        """Clients connected now."""
        return len(self._connections)

    def close(self) -> None:
        """Stop listening and close every client connection. Idempotent."""
        if self._server is not None:
            self._server.close()
        for connection in list(self._connections):
            connection.close()

    async def wait_closed(self) -> None:
        """Wait until the listener is closed."""
        if self._server is not None:
            await self._server.wait_closed()

    async def __aenter__(self) -> SimulatorServer:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
        await self.wait_closed()


async def serve_tcp(
    bus: BusModel,
    host: str = "127.0.0.1",
    port: int = 0,
    pacing: LinePacing | None = None,
    *,
    line: PacedLine | None = None,
    tap: Callable[[str, bytes], None] | None = None,
) -> SimulatorServer:
    """Listen for TCP clients and serve *bus* to each of them.

    Args:
        host: address to bind; loopback by default.
        port: TCP port; 0 picks a free one (read :attr:`SimulatorServer.port`).
        pacing: pace the line at these settings; default: no reply sooner than
            the request and a short frame cross a 19200-baud line
            (:class:`~._pacing.PlausibleLine`);
            ``LineSettings(baudrate=0)``: answer at once.
        line: share this paced line (e.g. with a pty server); overrides *pacing*.
        tap: see :attr:`SimulatorServer.tap`.

    Raises:
        OSError: the address cannot be bound (e.g. the port is in use).
    """
    server = SimulatorServer(bus, server_line(pacing, line), tap)
    loop = asyncio.get_running_loop()
    listener = await loop.create_server(lambda: _Connection(server), host, port)
    server._server = listener
    bound = listener.sockets[0].getsockname()
    server.host, server.port = str(bound[0]), int(bound[1])
    return server
