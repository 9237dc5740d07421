"""Listening to a line without ever transmitting: the sniffer's I/O.

:func:`sniff` opens the URL's transport (a TCP tap such as ``sj300
simulate --tap``, a serial port on an RS-485 listen-only transceiver or the
second port of a socat pair, an RFC 2217 port) with a protocol that only
reads: there is no code path from here to a transport's ``write``. What it
hears goes through a :class:`LineSniffer`; its reports come out of
:meth:`Sniffing.reports`, and into a pcapng file with ``capture=``.

A dropped connection is reconnected (0.5 s, doubling to 5 s); a request
still pending is reported unanswered at its time-out even when nothing more
is heard (a timer, not the next chunk, decides).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from os import PathLike
from typing import Any, Final

from ..transports import BufferedReads
from ..wire import FrameRole, LineSettings, LocalProtocolError, PacketDirection, TransportError
from ._capture import CaptureFile, LineCapture, open_capture
from ._dialect import Dialect
from ._line_connector import AnyConnector, line_connector
from ._open import make_dialect
from ._sniffer import LineSniffer, SniffedFrame, SnifferStats, Unanswered
from ._timing import BusTiming
from ._url import parse_bus_url

__all__ = ["Sniffing", "sniff"]

_log = logging.getLogger("sj300_async.sniff")

#: Reports held for a reader that falls behind; older ones are dropped and counted.
MAX_BACKLOG: Final = 10_000
_RECONNECT_FIRST_S: Final = 0.5
_RECONNECT_MAX_S: Final = 5.0
#: A tap bridge adds its own latency, as a TCP bus does (the bus's margin).
_BRIDGE_MARGIN_S: Final = 0.1

Report = SniffedFrame | Unanswered


class _Ear(BufferedReads):
    """Hears; has no way to speak."""

    def __init__(self, owner: Sniffing) -> None:
        super().__init__()
        self._owner = owner
        self.lost: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def data_received(self, data: bytes) -> None:
        self._owner._heard(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if exc is not None:
            _log.info("%s: connection lost: %s", self._owner.description, exc)
        if not self.lost.done():
            self.lost.set_result(None)


class Sniffing:
    """A line being listened to (from :func:`sniff`)."""

    def __init__(
        self,
        sniffer: LineSniffer,
        connector: AnyConnector,
        description: str,
        capture: LineCapture | None,
    ) -> None:
        self.sniffer = sniffer
        self.description = description
        self._connector = connector
        self._capture = capture
        self._loop = asyncio.get_running_loop()
        self._queue: asyncio.Queue[Report] = asyncio.Queue(MAX_BACKLOG)
        self._timer: asyncio.TimerHandle | None = None
        self._task: asyncio.Task[None] | None = None
        #: Reports dropped because the reader fell more than MAX_BACKLOG behind.
        self.dropped_reports = 0
        #: Connections made so far (1 after the first, more after reconnects).
        self.connections = 0
        self.connected = asyncio.Event()

    @property
    def stats(self) -> SnifferStats:
        """The sniffer's counters (frames by role, flags by kind, pairs, bytes)."""
        return self.sniffer.stats

    async def reports(self) -> AsyncIterator[Report]:
        """Every report, in order, as it comes (runs until the sniffing stops)."""
        while True:
            yield await self._queue.get()

    def _heard(self, data: bytes) -> None:
        now = self._loop.time()
        self._publish(self.sniffer.feed(data, now))

    def _tick(self) -> None:
        self._timer = None
        self._publish(self.sniffer.tick(self._loop.time()))

    def _publish(self, reports: list[Report]) -> None:
        for report in reports:
            if self._capture is not None and isinstance(report, SniffedFrame):
                self._capture.write_frame(report.time, report.frame, _direction(report))
            try:
                self._queue.put_nowait(report)
            except asyncio.QueueFull:
                self.dropped_reports += 1
                _log.debug("reader behind: report dropped")
        deadline = self.sniffer.next_deadline
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if deadline is not None:
            self._timer = self._loop.call_at(deadline + 1e-4, self._tick)

    async def _run(self, first: asyncio.Future[None]) -> None:
        delay = _RECONNECT_FIRST_S
        while True:
            ear = _Ear(self)
            try:
                transport = await self._connector(lambda ear=ear: ear)  # type: ignore[misc]
            except (OSError, LocalProtocolError, TransportError) as exc:
                if not first.done():
                    first.set_exception(exc)
                    return
                _log.info("%s: reconnecting in %.1f s: %s", self.description, delay, exc)
                await asyncio.sleep(delay)
                delay = min(delay * 2, _RECONNECT_MAX_S)
                continue
            self.connections += 1
            self.connected.set()
            delay = _RECONNECT_FIRST_S
            if not first.done():
                first.set_result(None)
            try:
                await ear.lost
            finally:
                self.connected.clear()
                transport.close()
            self._publish(self.sniffer.flush(self._loop.time()))

    async def _start(self) -> None:
        first: asyncio.Future[None] = self._loop.create_future()
        self._task = asyncio.create_task(self._run(first), name=f"sniff {self.description}")
        await first

    async def _stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task


def _direction(report: SniffedFrame) -> PacketDirection:
    """What the content tells: a master wrote requests and its answers; drives the rest."""
    role = report.frame.role
    if role is FrameRole.REQUEST or role is FrameRole.HOST_ANSWER:
        return PacketDirection.OUTBOUND
    if role is FrameRole.REPLY:
        return PacketDirection.INBOUND
    return PacketDirection.UNKNOWN


@contextlib.asynccontextmanager
async def sniff(
    url: str,
    *,
    protocol: str | None = None,
    dialect: Dialect[Any, Any] | None = None,
    line: LineSettings | None = None,
    timeout: float | None = None,  # noqa: ASYNC109 - the masters' response time-out
    capture: str | PathLike[str] | CaptureFile | None = None,
) -> AsyncIterator[Sniffing]:
    """Listen to the line at *url* until the block ends; never transmit.

    Args:
        url: ``tcp://HOST:PORT`` (a tap), a serial port, ``rfc2217://``; the
            query's line settings set the time-outs (default 19200 8N1).
        protocol: the line's protocol (or the URL's ``protocol=``).
        dialect: the protocol fully configured, instead of *protocol*.
        timeout: the masters' fixed response time-out, when they use one.
        capture: also write every frame to this pcapng file (or open capture).

    Raises:
        LocalProtocolError: a bad URL, or one that cannot be listened to (sim://).
        TransportError, OSError: the first connection failed.
    """
    address = parse_bus_url(url, protocol=protocol)
    if address.scheme in ("sim", "replay"):
        raise LocalProtocolError(
            f"{address.scheme}:// has no line to listen to: sniff a tap (sj300 simulate --tap), "
            "a serial port or a bridge"
        )
    made = make_dialect(address, protocol)
    dialect = dialect or made
    line = line or address.line or LineSettings()
    timing = BusTiming() if address.scheme == "serial" else BusTiming(margin_s=_BRIDGE_MARGIN_S)
    if timeout is not None:
        timing = BusTiming(fixed_timeout_s=timeout)
    connector = line_connector(address, line)
    capture_file = open_capture(capture)
    try:
        line_capture = None
        if capture_file is not None:
            line_capture = capture_file.line(dialect, address.description, line)
        sniffing = Sniffing(
            LineSniffer(dialect, line, timing), connector, address.description, line_capture
        )
        await sniffing._start()
        try:
            yield sniffing
        finally:
            await sniffing._stop()
    finally:
        if capture_file is not None and capture_file is not capture:
            capture_file.close()
