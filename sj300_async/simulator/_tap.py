"""A listen-only tap on the simulated line: every byte, both directions, to each listener.

``sj300 simulate --tap tcp://HOST:PORT`` gives the passive sniffer
(``sj300 sniff``) something to listen to without hardware. On RS-485 a
listen-only transceiver hears one line: the host's requests and the drives'
replies, in the order they crossed it, with nothing to say which is which.
The tap is that: each chunk the simulator receives or sends goes to every
connected listener as it is, in order, unmarked.

A listener can say nothing on the line: whatever one sends is read and
thrown away, and counted (:attr:`TapServer.bytes_from_listeners`), so a test
can prove a sniffer never transmits. A listener that does not keep up is
cut off (its socket buffer holds more than :data:`MAX_BACKLOG` bytes) and
counted, rather than slowing the line or growing memory.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Final, cast

__all__ = ["MAX_BACKLOG", "TapServer", "serve_tap"]

_log = logging.getLogger("sj300_async.simulator.tap")

#: Bytes a listener may fall behind before it is cut off.
MAX_BACKLOG: Final = 1 << 20


class _Listener(asyncio.Protocol):
    def __init__(self, server: TapServer) -> None:
        self._server = server
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.Transport, transport)
        self._server._listeners.add(self)
        self._server.listeners_seen += 1
        _log.debug("tap listener connected: %s", transport.get_extra_info("peername"))

    def data_received(self, data: bytes) -> None:
        self._server.bytes_from_listeners += len(data)  # listen-only: never on the line
        _log.debug("tap listener sent %d bytes, ignored: %s", len(data), data.hex(" "))

    def connection_lost(self, exc: Exception | None) -> None:
        self._server._listeners.discard(self)


class TapServer:
    """The tap's TCP server (see the module docstring). Use :func:`serve_tap`."""

    def __init__(self) -> None:
        self._listeners: set[_Listener] = set()
        self._server: asyncio.Server | None = None
        #: Bytes listeners sent (thrown away): a listen-only tap hears nothing from them.
        self.bytes_from_listeners = 0
        #: Bytes mirrored to listeners, each counted once however many listen.
        self.bytes_mirrored = 0
        #: Listeners cut off for falling more than MAX_BACKLOG bytes behind.
        self.listeners_cut_off = 0
        #: Listeners that ever connected.
        self.listeners_seen = 0

    @property
    def host(self) -> str:
        assert self._server is not None
        return str(self._server.sockets[0].getsockname()[0])

    @property
    def port(self) -> int:
        assert self._server is not None
        return int(self._server.sockets[0].getsockname()[1])

    @property
    def listeners(self) -> int:
        """Listeners connected now."""
        return len(self._listeners)

    def mirror(self, direction: str, data: bytes) -> None:
        """Send *data* to every listener; *direction* is not sent (a line has none)."""
        self.bytes_mirrored += len(data)
        for listener in list(self._listeners):
            transport = listener.transport
            if transport is None or transport.is_closing():
                continue
            if transport.get_write_buffer_size() > MAX_BACKLOG:
                self.listeners_cut_off += 1
                _log.warning("tap listener fell %d bytes behind: cut off", MAX_BACKLOG)
                transport.abort()
                continue
            transport.write(data)

    def close(self) -> None:
        if self._server is not None:
            self._server.close()
        for listener in list(self._listeners):
            if listener.transport is not None:
                listener.transport.close()

    async def wait_closed(self) -> None:
        if self._server is not None:
            await self._server.wait_closed()

    async def __aenter__(self) -> TapServer:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        self.close()
        await self.wait_closed()


async def serve_tap(host: str, port: int) -> TapServer:
    """Listen for tap listeners on *host*:*port* (port 0: any free one)."""
    tap = TapServer()
    loop = asyncio.get_running_loop()
    tap._server = await loop.create_server(lambda: _Listener(tap), host, port)
    return tap
