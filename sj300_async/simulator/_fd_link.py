"""Serving a simulated bus on a terminal file descriptor (a pty master, a serial device).

The event loop watches the descriptor: what it reads goes to a
:class:`SimulatorEndpoint`, what the endpoint sends is written back, without
blocking. Bytes queued for a peer that does not read are held (up to 64 KiB,
then the oldest are dropped, counted and logged), as a UART's buffer would.
A read or write error stops the link with a warning rather than spinning
the loop on a descriptor that stays "ready".
"""

from __future__ import annotations

import asyncio
import logging
import os
from types import TracebackType
from typing import Final, Self

from ._endpoint import SimulatorEndpoint
from ._model import BusModel
from ._pacing import PacedLine

__all__ = ["FdLink", "FdServer"]

_log = logging.getLogger("sj300_async.simulator")

_READ_SIZE: Final = 4096
_MAX_PENDING: Final = 64 * 1024


class FdLink:
    """One non-blocking descriptor carrying a simulated line. The caller owns the descriptor."""

    def __init__(
        self,
        fd: int,
        name: str,
        bus: BusModel,
        line: PacedLine | None,
        loop: asyncio.AbstractEventLoop,
    ) -> None:
        self._fd = fd
        self._name = name
        self._loop = loop
        #: Bytes for the peer dropped because nobody read them (buffer full or a write failure).
        self.dropped_bytes = 0
        self._pending = bytearray()
        self._writing = False
        self._closed = False
        os.set_blocking(fd, False)
        self._endpoint = SimulatorEndpoint(bus, send=self._write, line=line, loop=loop, defer=False)
        loop.add_reader(fd, self._on_readable)

    def close(self) -> None:
        """Stop serving: pending replies are cancelled, the loop stops watching. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._endpoint.close()
        self._loop.remove_reader(self._fd)
        if self._writing:
            self._loop.remove_writer(self._fd)
            self._writing = False

    def _on_readable(self) -> None:
        try:
            data = os.read(self._fd, _READ_SIZE)
        except BlockingIOError:
            return
        except OSError as exc:
            _log.warning("%s: read failed (%s), no longer reading", self._name, exc)
            self._loop.remove_reader(self._fd)
            return
        if data:
            self._endpoint.data_received(data)

    def _write(self, data: bytes) -> None:
        if self._closed:
            return
        self._pending += data
        overflow = len(self._pending) - _MAX_PENDING
        if overflow > 0:
            self.dropped_bytes += overflow
            _log.debug("%s: nobody reads, %d old bytes dropped", self._name, overflow)
            del self._pending[:overflow]
        self._flush()

    def _flush(self) -> None:
        while self._pending:
            try:
                written = os.write(self._fd, self._pending)
            except BlockingIOError:
                break
            except OSError as exc:
                self.dropped_bytes += len(self._pending)
                _log.warning(
                    "%s: write failed (%s), %d bytes dropped", self._name, exc, len(self._pending)
                )
                self._pending.clear()
                break
            del self._pending[:written]
        want_writer = bool(self._pending)
        if want_writer and not self._writing:
            self._loop.add_writer(self._fd, self._flush)
        elif not want_writer and self._writing:
            self._loop.remove_writer(self._fd)
        self._writing = want_writer


class FdServer:
    """Common life cycle of the servers that own descriptors (pty, serial device).

    Subclasses set ``_link`` and ``_closed`` and release their descriptors in
    :meth:`_close_fds`.
    """

    _link: FdLink
    _closed: bool

    @property
    def dropped_bytes(self) -> int:
        """Bytes for the client dropped because nobody read them."""
        return self._link.dropped_bytes

    def _close_fds(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Stop serving and close the descriptors. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._link.close()
        self._close_fds()

    async def wait_closed(self) -> None:
        """Nothing to wait for: :meth:`close` releases everything at once (kept for symmetry)."""

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
