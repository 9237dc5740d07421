"""In-memory loopback transport: a real asyncio.Transport wired to an in-process peer.

The peer (normally the simulator's ``SimulatorEndpoint``) is built from a
``send`` callable and must offer ``data_received(bytes)`` and ``close()``.
Bytes in each direction pass through optional :class:`LineFaults` and a FIFO
pipe that delivers them in order and never re-entrantly: nothing reaches
the host inside its own ``write`` or inside the peer's ``data_received``. A
chunk the peer sends from its own loop callback (the simulator's replies)
is delivered at once when nothing is queued ahead, as a socket's reader
callback would deliver it.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from ._faults import LineFaults

__all__ = ["LoopbackTransport", "Peer", "PeerFactory", "loopback_connector"]


class Peer(Protocol):
    """The far end of a loopback line."""

    def data_received(self, data: bytes) -> None:
        """Bytes from the host."""

    def close(self) -> None:
        """The line is closed: stop sending."""


#: Builds the peer, given the function it calls to send bytes to the host.
PeerFactory = Callable[[Callable[[bytes], None]], Peer]


class _Pipe:
    """Delivers chunks in order, each no earlier than its due time."""

    def __init__(self, loop: asyncio.AbstractEventLoop, sink: Callable[[bytes], None]) -> None:
        self._loop = loop
        self._sink = sink
        self._queue: deque[tuple[float, bytes]] = deque()
        self._timer: asyncio.TimerHandle | asyncio.Handle | None = None
        self._last_due = 0.0

    @property
    def idle(self) -> bool:
        """True when nothing is queued or scheduled."""
        return not self._queue and self._timer is None

    def push(self, delay: float, data: bytes) -> None:
        due = max(self._loop.time() + delay, self._last_due)
        self._last_due = due
        self._queue.append((due, data))
        if self._timer is None:
            self._schedule()

    def _schedule(self) -> None:
        due = self._queue[0][0]
        if due <= self._loop.time():
            self._timer = self._loop.call_soon(self._flush)
        else:
            self._timer = self._loop.call_at(due, self._flush)

    def _flush(self) -> None:
        self._timer = None
        now = self._loop.time()
        queue = self._queue
        while queue and queue[0][0] <= now:
            self._sink(queue.popleft()[1])
        if queue:
            self._schedule()

    def cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._queue.clear()


class LoopbackTransport(asyncio.Transport):
    """An asyncio transport whose other end is an in-process peer."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        protocol: asyncio.Protocol,
        peer_factory: PeerFactory,
        *,
        to_peer: LineFaults | None = None,
        to_host: LineFaults | None = None,
    ) -> None:
        super().__init__(extra={"peername": "loopback"})
        self._loop = loop
        self._protocol = protocol
        self._to_peer_faults = to_peer
        self._to_host_faults = to_host
        self._closing = False
        self._reading = True
        # What arrived while reading was paused (pause_reading), in order.
        self._held: list[bytes] = []
        # True while the peer is inside data_received: what it sends meanwhile
        # must wait for a later loop turn (no re-entrant delivery to the host).
        self._in_peer = False
        self._peer = peer_factory(self._from_peer)
        self._to_peer = _Pipe(loop, self._deliver_to_peer)
        self._to_host = _Pipe(loop, self._deliver_to_host)

    # -- bytes ---------------------------------------------------------------

    def write(self, data: bytes | bytearray | memoryview) -> None:
        if self._closing:
            return  # as a socket transport does after close(): the bytes go nowhere
        chunk = bytes(data)
        if self._to_peer_faults is None:
            if self._to_peer.idle:
                # Nothing queued ahead: hand it over now, saving a loop turn per
                # request. Safe: whatever the peer sends back reaches the host
                # through the other pipe, on a later loop turn.
                self._deliver_to_peer(chunk)
            else:
                self._to_peer.push(0.0, chunk)
            return
        for delay, piece in self._to_peer_faults.apply(chunk):
            self._to_peer.push(delay, piece)

    def _from_peer(self, data: bytes) -> None:
        if self._closing:
            return
        if self._to_host_faults is None:
            if self._in_peer or not self._to_host.idle:
                self._to_host.push(0.0, data)
            else:
                # Sent from its own loop callback, nothing queued ahead: deliver
                # now, as a socket's reader callback would (one loop turn less).
                self._deliver_to_host(data)
            return
        for delay, piece in self._to_host_faults.apply(data):
            self._to_host.push(delay, piece)

    def _deliver_to_peer(self, data: bytes) -> None:
        if self._closing:
            return
        self._in_peer = True
        try:
            self._peer.data_received(data)
        finally:
            self._in_peer = False

    def _deliver_to_host(self, data: bytes) -> None:
        if self._closing:
            return
        if not self._reading:
            self._held.append(data)  # delivered, in order, when reading resumes
            return
        self._protocol.data_received(data)

    def inject(self, data: bytes) -> None:
        """Deliver *data* to the host as if it came from the line (tests: stray frames)."""
        self._to_host.push(0.0, data)

    # -- asyncio.Transport contract ----------------------------------------------

    def can_write_eof(self) -> bool:
        return False

    def get_write_buffer_size(self) -> int:
        return 0

    def get_write_buffer_limits(self) -> tuple[int, int]:
        return (0, 0)

    def set_write_buffer_limits(self, high: int | None = None, low: int | None = None) -> None:
        pass  # nothing is ever buffered: writes never pause

    def is_closing(self) -> bool:
        return self._closing

    def is_reading(self) -> bool:
        return self._reading and not self._closing

    def pause_reading(self) -> None:
        self._reading = False

    def resume_reading(self) -> None:
        if self._reading:
            return
        self._reading = True
        held, self._held = self._held, []
        for data in held:
            self._to_host.push(0.0, data)  # after this call returns, as a socket would

    def close(self) -> None:
        self._shutdown(None)

    def abort(self) -> None:
        self._shutdown(None)

    def drop(self, exc: Exception | None = None) -> None:
        """Break the line as a dropped connection would (tests)."""
        self._shutdown(exc or ConnectionResetError("loopback line dropped"))

    def _shutdown(self, exc: Exception | None) -> None:
        if self._closing:
            return
        self._closing = True
        self._to_peer.cancel()
        self._to_host.cancel()
        self._peer.close()
        self._loop.call_soon(self._protocol.connection_lost, exc)

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        if name == "peer":
            return self._peer
        return super().get_extra_info(name, default)


def loopback_connector(
    peer_factory: PeerFactory,
    *,
    to_peer: LineFaults | None = None,
    to_host: LineFaults | None = None,
) -> Callable[[Callable[[], asyncio.Protocol]], Any]:
    """Return a connector that opens a :class:`LoopbackTransport` to a new peer."""

    async def connect(protocol_factory: Callable[[], asyncio.Protocol]) -> LoopbackTransport:
        loop = asyncio.get_running_loop()
        protocol = protocol_factory()
        transport = LoopbackTransport(
            loop, protocol, peer_factory, to_peer=to_peer, to_host=to_host
        )
        protocol.connection_made(transport)
        return transport

    return connect
