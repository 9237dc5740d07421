"""The in-memory server: a simulated bus on the event loop's clock, talking through a callable.

:class:`SimulatorEndpoint` is what every server wraps: bytes from the host
go to :meth:`SimulatorEndpoint.data_received`, replies leave through the
``send`` callable at the time the bus says. It needs no transport, so the
library's loopback transport uses it directly; the TCP and pty servers hand
it their write function.

Without pacing, host bytes reach the bus at once and each reply is sent
after its delay. With pacing (a :class:`PacedLine`), host bytes reach the
bus when their last character has crossed the line, and replies are
delivered a few characters at a time (or one at a time: the line's
``group_s``), never before those characters' wire time has passed.

Each delivery has a timer at its absolute time (``call_at``: a late timer
does not make the next one later). A timer that fires late finds later
deliveries due as well, and sends everything due by then, consecutive
bytes in one call: as a UART hands over every character whose stop bit has
ended, and one write for a loop that woke late instead of one per character.
Nothing goes out before its time.

All deliveries go through one queue ordered by (time, sequence), so two
deliveries due at the same instant keep their order: the event loop's
timer heap alone does not promise that.
"""

from __future__ import annotations

import asyncio
import functools
import heapq
import itertools
import logging
from collections.abc import Callable

from ._model import BusModel, Transmission
from ._pacing import LinePacing, PacedLine

__all__ = ["SimulatorEndpoint"]

_log = logging.getLogger("sj300_async.simulator")

_Job = tuple[float, int, Callable[[], object]]


class SimulatorEndpoint:
    """A simulated bus served through a send callable (see the module docstring).

    Args:
        bus: the drives; several endpoints may share one bus.
        send: called with each chunk of bytes for the host, from the event loop.
        pacing: pace the line at these settings (a :class:`PacedLine` of its own).
        line: pace on this shared line instead (overrides *pacing*).
        loop: the event loop; by default the running loop at the first call.
        defer: send a reply that is due at once from a later loop turn, never
            from inside :meth:`data_received` (the default: safe for a host that
            calls it from inside its own write). A server whose
            ``data_received`` the event loop calls passes False and answers
            at once, a loop turn sooner.
    """

    def __init__(
        self,
        bus: BusModel,
        send: Callable[[bytes], object],
        pacing: LinePacing | None = None,
        *,
        line: PacedLine | None = None,
        loop: asyncio.AbstractEventLoop | None = None,
        defer: bool = True,
    ) -> None:
        self.bus = bus
        self._send = send
        self._defer = defer
        self._line = line if line is not None else PacedLine(pacing) if pacing else None
        self._loop = loop
        self._queue: list[_Job] = []
        self._sequence = itertools.count()
        # Each job's timer by its sequence number. No closure holds its own timer: that
        # cycle (handle -> callback -> cell -> handle) made 8 objects of garbage per job
        # that only the cyclic collector frees, two jobs per drive sample.
        self._timers: dict[int, asyncio.TimerHandle] = {}
        self._closed = False

    @property
    def pacing(self) -> LinePacing | None:
        """The line settings bytes are paced at, or None."""
        return None if self._line is None else self._line.pacing

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._closed

    @property
    def pending(self) -> int:
        """Deliveries scheduled and not yet made."""
        return len(self._queue)

    def data_received(self, data: bytes | bytearray | memoryview) -> None:
        """Take bytes the host wrote; after :meth:`close` they are discarded (and logged)."""
        data = bytes(data)
        if self._closed:
            _log.debug("endpoint closed, %d host bytes discarded: %s", len(data), data.hex(" "))
            return
        now = self._get_loop().time()
        if self._line is None:
            self._schedule_replies(now, self.bus.receive(data, now))
            return
        for arrival, piece in self._line.receive(now, data):
            self._at(arrival, functools.partial(self._arrived, arrival, piece))

    def close(self) -> None:
        """Cancel every pending delivery; nothing is sent afterwards. Idempotent.

        Host bytes already on a paced line still reach the drives (at their
        arrival time), as a device server's serial side finishes sending what
        its client wrote: a broadcast written just before the client hung up
        is heard. What the drives answer goes nowhere.
        """
        self._closed = True
        for timer in self._timers.values():
            timer.cancel()
        self._timers.clear()
        if self._queue:
            _log.debug("endpoint closed with %d deliveries pending", len(self._queue))
        queued, self._queue = sorted(self._queue), []
        for _when, _seq, job in queued:
            if isinstance(job, functools.partial) and job.func == self._arrived:
                at, piece = job.args
                self.bus.receive(piece, at)

    def _get_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            self._loop = asyncio.get_running_loop()
        return self._loop

    def _arrived(self, at: float, piece: bytes) -> None:
        self._schedule_replies(at, self.bus.receive(piece, at))

    def _schedule_replies(self, now: float, transmissions: list[Transmission]) -> None:
        for t in transmissions:
            start = now + t.delay_s
            if self._line is None:
                if t.delay_s <= 0 and not self._queue:
                    # Nothing to wait for and nothing queued ahead: no timer and no
                    # heap; at once, or on the next loop turn (see *defer*).
                    if self._defer:
                        self._get_loop().call_soon(self._send_unless_closed, t.data)
                    else:
                        self._send(t.data)
                else:
                    self._at(start, functools.partial(self._send, t.data))
                continue
            for when, group in self._line.transmit(start, t.data):
                self._at(when, functools.partial(self._send, group))

    def _send_unless_closed(self, data: bytes) -> None:
        if not self._closed:
            self._send(data)

    def _at(self, when: float, job: Callable[[], object]) -> None:
        sequence = next(self._sequence)
        heapq.heappush(self._queue, (when, sequence, job))
        self._timers[sequence] = self._get_loop().call_at(when, self._fire, when, sequence)

    def _fire(self, when: float, sequence: int) -> None:
        del self._timers[sequence]
        # A loop that wakes late finds later deliveries due as well: they go now, with
        # this one.
        self._run_due(max(when, self._get_loop().time()))

    def _run_due(self, until: float) -> None:
        # Everything due by *until* (never later than now), in (time, sequence)
        # order; a job whose own timer has not fired yet but is due goes now, its
        # timer finds nothing left to do. Consecutive sends go out as one: a
        # UART hands over every character whose stop bit has ended, and a
        # paced line that delivers one character at a time (or a loop that
        # woke late) would otherwise cost a write for each.
        batch: list[bytes] = []
        while self._queue and self._queue[0][0] <= until and not self._closed:
            _when, _seq, job = heapq.heappop(self._queue)
            if isinstance(job, functools.partial) and job.func == self._send:
                batch.append(job.args[0])
                continue
            if batch:
                self._send(b"".join(batch))
                batch.clear()
            job()
        if batch and not self._closed:
            self._send(b"".join(batch))
