"""Each transport opened bare, for its own asyncio transport contract (test_asyncio_transport.py).

``open_raw_line(kind)`` yields a :class:`RawLine`: the transport's connector
and the far end of the line, which records what arrives and sends what the
test asks, and can stop reading (so the host's writes back up):

- loopback: a recording peer behind ``loopback_connector``
- tcp:      an asyncio server behind ``tcp_connector``
- pty:      the master side of a pseudo-terminal behind ``serial_connector``
- ser2net:  end A of a socat pty pair, ser2net serving end B, ``tcp_connector``
- rfc2217:  the same, ser2net's accepter speaking RFC 2217, ``rfc2217_connector``
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import tty
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from waiting import wait_for

from sj300_async import LineSettings
from sj300_async.transports import (
    loopback_connector,
    rfc2217_connector,
    serial_connector,
    tcp_connector,
)

from .bridges import socat_ser2net

KINDS = ("loopback", "tcp", "pty", "ser2net", "rfc2217")

Connector = Callable[[Callable[[], asyncio.Protocol]], Awaitable[asyncio.BaseTransport]]


class Recorder(asyncio.Protocol):
    """A protocol that records every call the transport makes on it."""

    def __init__(self) -> None:
        self.transport: asyncio.BaseTransport | None = None
        self.received = bytearray()
        self.events: list[str] = []
        self.lost_exc: BaseException | None = None
        self.lost = asyncio.Event()
        #: The transport's write buffer size when connection_lost came (None: no buffer).
        self.buffered_at_lost: int | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport
        self.events.append("made")

    def data_received(self, data: bytes) -> None:
        self.received += data
        if not self.events or self.events[-1] != "data":
            self.events.append("data")

    def connection_lost(self, exc: BaseException | None) -> None:
        self.lost_exc = exc
        if isinstance(self.transport, asyncio.WriteTransport):
            self.buffered_at_lost = self.transport.get_write_buffer_size()
        self.events.append("lost")
        self.lost.set()

    def pause_writing(self) -> None:
        self.events.append("pause_writing")

    def resume_writing(self) -> None:
        self.events.append("resume_writing")


class Far:
    """The far end of a line: what it received; send; stop and restart reading."""

    def __init__(self) -> None:
        self.received = bytearray()

    def send(self, data: bytes) -> None:
        raise NotImplementedError

    def pause(self) -> None:
        raise NotImplementedError

    def resume(self) -> None:
        raise NotImplementedError


class LoopbackFar(Far):
    """The loopback's peer (it cannot stop reading: the loopback has no buffer to back up)."""

    def __init__(self) -> None:
        super().__init__()
        self._send: Callable[[bytes], None] | None = None
        self.closed = False

    def factory(self, send: Callable[[bytes], None]) -> LoopbackFar:
        self._send = send
        return self

    def data_received(self, data: bytes) -> None:
        self.received += data

    def close(self) -> None:
        self.closed = True

    def send(self, data: bytes) -> None:
        assert self._send is not None, "not connected"
        self._send(data)

    def pause(self) -> None:
        pass

    def resume(self) -> None:
        pass


class StreamFar(Far):
    """The server side of a TCP connection."""

    def __init__(self) -> None:
        super().__init__()
        self.connected = asyncio.Event()
        self._reading = asyncio.Event()
        self._reading.set()
        self._writer: asyncio.StreamWriter | None = None
        self._task: asyncio.Task[None] | None = None

    async def on_connect(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writer = writer
        self.connected.set()
        try:
            while True:
                await self._reading.wait()
                chunk = await reader.read(65536)
                if not chunk:
                    break
                self.received += chunk
        finally:
            writer.close()

    def send(self, data: bytes) -> None:
        assert self._writer is not None, "not connected"
        self._writer.write(data)

    def pause(self) -> None:
        self._reading.clear()

    def resume(self) -> None:
        self._reading.set()


class FdFar(Far):
    """A terminal's far side (a pty master, or the other end of a socat pair), non-blocking."""

    def __init__(self, fd: int) -> None:
        super().__init__()
        self.fd = fd
        self._loop = asyncio.get_running_loop()
        os.set_blocking(fd, False)
        self._reading = False
        self.resume()

    def _read(self) -> None:
        try:
            self.received += os.read(self.fd, 65536)
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:  # EIO: the other side is closed
            self.pause()

    def send(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            written = os.write(self.fd, view)
            view = view[written:]

    def pause(self) -> None:
        if self._reading:
            self._loop.remove_reader(self.fd)
            self._reading = False

    def resume(self) -> None:
        if not self._reading:
            self._loop.add_reader(self.fd, self._read)
            self._reading = True


@dataclass
class RawLine:
    kind: str
    connect: Connector
    far: Far
    #: What get_extra_info must answer (name -> expected value or a predicate).
    extra: dict[str, Any] = field(default_factory=dict)
    #: True when the transport buffers writes and calls pause_writing/resume_writing.
    buffers_writes: bool = True

    async def open(self, recorder: Recorder | None = None) -> tuple[asyncio.Transport, Recorder]:
        if recorder is None:
            recorder = Recorder()
        transport = await self.connect(lambda: recorder)
        assert isinstance(transport, asyncio.Transport)
        # As the bus's link does: pyserial-asyncio-fast returns before it has
        # called connection_made (and registered its reader) with call_soon.
        await wait_for(lambda: recorder.events[:1] == ["made"], "connection_made")
        assert recorder.transport is transport
        if isinstance(self.far, StreamFar):
            await asyncio.wait_for(self.far.connected.wait(), 5)
        if self.kind == "ser2net":
            # ser2net opens its serial device when the connection comes, and
            # bytes sent towards it before then are lost: wait until one of
            # ours has crossed the whole bridge.
            transport.write(b"\x00")
            await wait_for(lambda: self.far.received == b"\x00", "the bridge to carry a byte")
            self.far.received.clear()
        return transport, recorder


@contextlib.asynccontextmanager
async def open_raw_line(kind: str) -> AsyncIterator[RawLine]:
    if kind == "loopback":
        peer = LoopbackFar()
        yield RawLine(
            kind,
            loopback_connector(peer.factory),
            peer,
            extra={"peername": "loopback", "peer": peer},
            buffers_writes=False,
        )
    elif kind == "tcp":
        far = StreamFar()
        server = await asyncio.start_server(far.on_connect, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        async with server:
            yield RawLine(kind, tcp_connector("127.0.0.1", port), far, extra={"port": port})
            server.close()
    elif kind == "pty":
        master, slave = os.openpty()
        tty.setraw(slave)
        path = os.ttyname(slave)
        try:
            yield RawLine(
                kind,
                serial_connector(path, LineSettings(19200)),
                FdFar(master),
                extra={"path": path},
            )
        finally:
            asyncio.get_running_loop().remove_reader(master)
            os.close(slave)
            os.close(master)
    else:
        rfc2217 = kind == "rfc2217"
        async with socat_ser2net(rfc2217=rfc2217) as (a, port):
            fd = os.open(a, os.O_RDWR | os.O_NOCTTY)
            tty.setraw(fd)
            if rfc2217:
                # Connected once the server has confirmed the line: ser2net has the
                # device open by then, so no byte needs to cross first (see open()).
                connect = rfc2217_connector("127.0.0.1", port, LineSettings(19200))
            else:
                connect = tcp_connector("127.0.0.1", port)
            try:
                yield RawLine(kind, connect, FdFar(fd), extra={"port": port})
            finally:
                asyncio.get_running_loop().remove_reader(fd)
                os.close(fd)
