"""The protocol adapter: one asyncio.Protocol for every transport.

It feeds received chunks to the sans-IO reply parser and hands every event
to a listener (the arbiter). It knows nothing of requests or time-outs. With
echo stripping on, it removes the host's own frames from the input first:
RS-485 adapters without echo suppression hand every written byte back.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Generic, Protocol, TypeVar, cast

from ..wire import BadFrame, Discarded
from ._dialect import LineParser, ReplyT
from ._stats import BusStats
from ._trace import TraceHook, TraceRecord

__all__ = ["LineListener", "LineProtocol"]

_log = logging.getLogger("sj300_async.line")


_ReplyT_contra = TypeVar("_ReplyT_contra", contravariant=True)


class LineListener(Protocol[_ReplyT_contra]):
    """What the adapter reports to (the arbiter)."""

    def event_received(self, event: _ReplyT_contra | BadFrame | Discarded, now: float) -> None:
        """A parser event; *now* is the loop time the chunk arrived."""

    def bytes_received(self, data: bytes, now: float) -> None:
        """A chunk arrived, as it arrived (for the quiet-time bookkeeping and the logs)."""

    def connection_lost(self, exc: BaseException | None) -> None:
        """The transport is gone; whatever waits for an answer must fail now."""


class LineProtocol(asyncio.Protocol, Generic[ReplyT]):
    """Adapter between an asyncio transport and the sans-IO reply parser."""

    def __init__(
        self,
        parser: LineParser[ReplyT],
        listener: LineListener[ReplyT],
        stats: BusStats,
        *,
        strip_echo: bool = False,
        trace: TraceHook | None = None,
    ) -> None:
        self._parser = parser
        self._listener = listener
        self._stats = stats
        self._strip_echo = strip_echo
        self._echo = b""
        self.trace = trace
        self._transport: asyncio.Transport | None = None
        self._loop = asyncio.get_running_loop()
        self._writable = asyncio.Event()
        self._writable.set()
        #: Set when the transport hands itself over (some transports, like
        #: pyserial-asyncio's, do so a loop iteration after they are created).
        self.made: asyncio.Future[None] = self._loop.create_future()
        #: Set when the connection is lost; carries the exception (None for a clean close).
        self.lost: asyncio.Future[BaseException | None] = self._loop.create_future()

    # -- asyncio.Protocol -----------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not isinstance(): uvloop's transports implement the interface without
        # deriving from asyncio's classes.
        transport = cast(asyncio.Transport, transport)
        self._transport = transport
        if not self.made.done():
            self.made.set_result(None)

    def data_received(self, data: bytes) -> None:
        now = self._loop.time()
        self._listener.bytes_received(data, now)
        arrived = data
        if self._echo:
            data = self._remove_echo(data)
        events = self._parser.feed(data) if data else []
        if self.trace is not None:
            self.trace(TraceRecord(now, "rx", arrived, tuple(events)))
        for event in events:
            self._account(event)
            self._listener.event_received(event, now)

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        self._writable.set()
        if not self.lost.done():
            self.lost.set_result(exc)
        self._listener.connection_lost(exc)

    def pause_writing(self) -> None:
        self._writable.clear()

    def resume_writing(self) -> None:
        self._writable.set()

    # -- for the arbiter --------------------------------------------------------

    @property
    def connected(self) -> bool:
        """True until the transport is lost or closed."""
        return self._transport is not None and not self._transport.is_closing()

    def write(self, frame: bytes) -> None:
        """Write a frame. The caller has checked :attr:`connected`."""
        assert self._transport is not None
        if self._strip_echo:
            self._echo += frame
        if self.trace is not None:
            self.trace(TraceRecord(self._loop.time(), "tx", frame))
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("tx %s", frame.hex(" "))
        self._transport.write(frame)

    @property
    def writable(self) -> bool:
        """False while the transport has asked us to pause writing."""
        return self._writable.is_set()

    async def wait_writable(self) -> None:
        """Return when the transport's write buffer is below its high-water mark."""
        if not self._writable.is_set():
            await self._writable.wait()

    def close(self) -> None:
        """Close the transport (idempotent)."""
        if self._transport is not None:
            self._transport.close()

    def abort(self) -> None:
        """Drop the connection at once, for tests and for an unrecoverable state."""
        if self._transport is not None:
            self._transport.abort()

    def reset_parser(self) -> None:
        """Forget a partial frame (after a drain); it is counted as discarded."""
        for event in self._parser.reset():
            self._account(event)
        self._echo = b""

    # -- internals ----------------------------------------------------------------

    def _remove_echo(self, data: bytes) -> bytes:
        echo = self._echo
        n = min(len(echo), len(data))
        if data[:n] == echo[:n]:
            self._echo = echo[n:]
            self._stats.echo_bytes += n
            return data[n:]
        # Not our echo: stop expecting it and let the parser judge every byte.
        self._stats.echo_mismatches += 1
        _log.debug("echo mismatch: expected %s, got %s", echo.hex(" "), data.hex(" "))
        self._echo = b""
        return data

    def _account(self, event: ReplyT | BadFrame | Discarded) -> None:
        if type(event) is Discarded:
            self._stats.discarded_bytes += len(event.data)
        elif type(event) is BadFrame:
            self._stats.bad_frames += 1
        elif _log.isEnabledFor(logging.DEBUG):
            _log.debug("rx %s", event)  # discards and bad frames are logged by the parser
