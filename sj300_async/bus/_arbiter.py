"""The bus arbiter: exactly one transaction on the half-duplex line at a time.

A transaction runs in the caller's own task, while it holds the line
(:class:`LineQueue`): cancelling the caller cancels exactly its own
transaction, with no worker task to leak or to desynchronize. The rules,
each of which has its own test:

1. The line is taken in arrival order; ``urgent`` requests (stop) go first.
2. Before writing, the line must be clean: after a failed transaction it is
   drained (see :mod:`._timing`), and after every reply or broadcast it rests
   for the guard interval.
3. The reply waiter is registered *before* the request is written, so an
   answer can never arrive unobserved.
4. While waiting, every frame that is not an answer to this request (another
   node, the wrong shape for the command) is counted and discarded; the wait
   goes on until the deadline. A corrupted frame is remembered: if no valid
   answer comes, the attempt fails with :class:`RemoteProtocolError` rather
   than a plain time-out.
5. An attempt that ends without its answer — time-out, corrupted answer,
   transport error, or the caller's cancellation — leaves the line dirty: the
   next transaction drains it first.
6. Retries (time-outs, corrupted answers, NAK 01..08; never NAK 11/13/16, and
   never a transport error, which must fail promptly) release the line and
   queue again at the back, so one failing drive cannot starve the others.
7. A protocol that lets the host answer a reply (FR-700) gets its answer
   sent after the dialect's answer delay: an acknowledgement after a good
   reply (the line then rests as the dialect says), and, once per attempt,
   a re-output request after a corrupted one, which pushes the deadline
   back by a whole response time-out so the repeated reply can arrive.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Any, Generic

from ..wire._errors import NakError, RemoteProtocolError, ReplyTimeoutError, TransportError
from ..wire._events import BadFrame, Discarded
from ..wire._line import LineSettings
from ._dialect import Dialect, ReplyT, RequestT
from ._linequeue import LineQueue
from ._link import Link
from ._protocol import LineProtocol
from ._stats import BusStats, TransactionStats
from ._timing import BusTiming

__all__ = ["Arbiter"]

_log = logging.getLogger("sj300_async.arbiter")

#: Distinct requests whose response time-out is remembered (see _response_timeout).
_TIMEOUT_CACHE_SIZE = 256


@dataclass(slots=True)
class _Outstanding(Generic[RequestT, ReplyT]):
    """The transaction currently on the line."""

    request: RequestT
    #: Resolves to the answer, or to None when the deadline passes.
    waiter: asyncio.Future[ReplyT | None]
    stats: TransactionStats
    #: The response time-out of this attempt, and the loop time it ends at.
    timeout: float
    deadline: float
    bad_frame: BadFrame | None = None
    #: The scheduled re-output request (rule 7), at most one per attempt.
    reoutput: asyncio.TimerHandle | None = None


class Arbiter(Generic[RequestT, ReplyT]):
    """Serializes transactions on one line and enforces the timing rules."""

    def __init__(
        self,
        link: Link,
        line: LineSettings,
        timing: BusTiming,
        stats: BusStats,
        dialect: Dialect[RequestT, ReplyT],
    ) -> None:
        self.link = link
        self.dialect = dialect
        self._line = line
        self._timing = timing
        self._guard_s = timing.guard(line)
        # Response time-outs by (frame, wait): computed once per distinct request
        # (see _response_timeout). A poll repeats a handful of frames.
        self._timeouts: dict[tuple[bytes, float], float] = {}
        self.stats = stats
        self.queue = LineQueue()
        self._loop = asyncio.get_running_loop()
        self._outstanding: _Outstanding[RequestT, ReplyT] | None = None
        # Loop time before which nothing may be written (guard interval).
        self._rest_until = 0.0
        # After a failure: how long the line must be quiet before the next write.
        self._drain_quiet: float | None = None
        self._failed_at = 0.0
        self._last_rx = 0.0
        # One deadline timer for every attempt (see _arm_deadline), and the
        # loop time it is due at.
        self._deadline_timer: asyncio.TimerHandle | None = None
        self._deadline_due = 0.0

    @property
    def line(self) -> LineSettings:
        """The line's settings (fixed for the arbiter's life: its timing derives from them)."""
        return self._line

    @property
    def timing(self) -> BusTiming:
        """The timing policy (fixed for the arbiter's life)."""
        return self._timing

    # -- LineListener ------------------------------------------------------------

    def bytes_received(self, now: float) -> None:
        self._last_rx = now

    def event_received(self, event: ReplyT | BadFrame | Discarded, now: float) -> None:
        out = self._outstanding
        if isinstance(event, Discarded):
            return  # counted by the protocol adapter
        if isinstance(event, BadFrame):
            if out is not None and out.bad_frame is None:
                out.bad_frame = event
            if out is not None and out.reoutput is None and not out.waiter.done():
                self._request_reoutput(out, event, now)
            return
        if out is None or out.waiter.done():
            self.stats.unsolicited_frames += 1
            _log.debug("unsolicited frame discarded: %s", event)
            return
        if self.dialect.answers(out.request, event):
            out.waiter.set_result(event)
            return
        self.stats.stray_frames += 1
        out.stats.discarded_frames += 1
        _log.debug("stray frame while waiting for node %02d: %s", out.request.node, event)

    def _request_reoutput(
        self, out: _Outstanding[RequestT, ReplyT], bad_frame: BadFrame, now: float
    ) -> None:
        frame = self.dialect.reoutput_request(out.request, bad_frame)
        if frame is None:
            return
        delay = self.dialect.answer_delay_s()
        out.reoutput = self._loop.call_at(now + delay, self._send_reoutput, out, frame)
        # The repeated reply needs a whole exchange's time again. Deadlines only
        # move later: the armed timer fires first and re-arms for this one.
        out.deadline = max(out.deadline, now + delay + out.timeout)

    def _send_reoutput(self, out: _Outstanding[RequestT, ReplyT], frame: bytes) -> None:
        if self._outstanding is not out or out.waiter.done():
            return  # the attempt is over: nothing to ask for any more
        protocol = self.link.protocol
        if protocol is None:
            return  # the link is down: the waiter fails on its own
        protocol.write(frame)
        self.stats.reoutput_requests += 1
        _log.debug("asked node %02d to send its reply again", out.request.node)

    def connection_lost(self, exc: BaseException | None) -> None:
        out = self._outstanding
        if out is not None and not out.waiter.done():
            out.waiter.set_exception(
                TransportError(f"connection lost while waiting for node {out.request.node:02d}")
            )

    # -- the deadline timer -------------------------------------------------------

    def _arm_deadline(self, deadline: float) -> None:
        """Make sure the deadline timer fires no later than *deadline*.

        A timer per attempt would cost a handle, a heap push and a cancelled
        entry in the loop's heap for every transaction, and nearly every one
        is cancelled. Instead one timer stays armed: attempts start in order
        and their deadlines grow, so the timer armed for an earlier attempt
        fires first, and re-arms for the attempt then outstanding.
        """
        timer = self._deadline_timer
        if timer is not None:
            if self._deadline_due <= deadline:
                return
            timer.cancel()  # a shorter time-out than the one armed
        self._deadline_due = deadline
        self._deadline_timer = self._loop.call_at(deadline, self._deadline_passed)

    def _deadline_passed(self) -> None:
        self._deadline_timer = None
        out = self._outstanding
        if out is None or out.waiter.done():
            return  # nothing to time out: the next attempt arms a new timer
        if out.deadline > self._deadline_due:
            self._arm_deadline(out.deadline)  # armed for an earlier attempt
        else:
            out.waiter.set_result(None)  # the attempt's time is up

    # -- transactions ----------------------------------------------------------------

    async def transact(
        self,
        request: RequestT,
        stats: TransactionStats,
        *,
        wait_s: float = 0.0,
        timeout_s: float | None = None,
        retries: int = 0,
        urgent: bool = False,
    ) -> bytes:
        """Run *request* on the line; return the data of its positive answer.

        A request that expects no answer (a broadcast) is written, the line
        rests after it, and ``b""`` comes back (:meth:`send` says so).

        Raises:
            NakError: the drive refused (after retries for transmission errors).
            ReplyTimeoutError: no answer in time, on every attempt.
            RemoteProtocolError: only corrupted answers, on every attempt.
            TransportError: the link is down or dropped (never retried).
            BusClosedError: the bus is closed.
        """
        attempt = 0
        while True:
            self.link.require()  # fail promptly, before queueing, while the link is down
            await self.queue.acquire(urgent)
            try:
                return await self._attempt(request, stats, wait_s, timeout_s)
            except (ReplyTimeoutError, RemoteProtocolError, NakError) as exc:
                if attempt >= retries or not self.dialect.retryable(exc):
                    raise
                attempt += 1
                stats.retries += 1
                if stats is not self.stats.transactions:
                    self.stats.transactions.retries += 1
                _log.debug("retry %d of %s: %s", attempt, request.frame.hex(" "), exc)
            finally:
                self.queue.release()

    async def send(
        self, request: RequestT, stats: TransactionStats, *, urgent: bool = False
    ) -> None:
        """Write a request that gets no answer; the line rests after it as the timing says.

        Raises:
            TransportError: the link is down or dropped.
        """
        await self.transact(request, stats, urgent=urgent)

    async def _attempt(
        self,
        request: RequestT,
        stats: TransactionStats,
        wait_s: float,
        timeout_s: float | None,
    ) -> bytes:
        protocol = self.link.require()
        loop = self._loop
        if self._drain_quiet is not None:
            await self._drain()
            protocol = self.link.require()
        now = loop.time()
        if self._rest_until > now:
            await asyncio.sleep(self._rest_until - now)
            protocol = self.link.require()
            now = loop.time()
        if not protocol.writable:
            await protocol.wait_writable()
            protocol = self.link.require()  # the link may have dropped while we waited
            now = loop.time()
        totals = self.stats.transactions
        if not request.expects_reply:
            protocol.write(request.frame)
            self._count(stats, totals, "broadcasts")
            self._rest_until = loop.time() + self._timing.after_broadcast(request, self._line)
            return b""

        dialect = self.dialect
        timeout = timeout_s or self._response_timeout(request, wait_s)
        waiter: asyncio.Future[ReplyT | None] = loop.create_future()
        sent = now
        out = _Outstanding(request, waiter, stats, timeout, sent + timeout)
        self._outstanding = out  # registered before the write: no answer goes unseen
        self._arm_deadline(out.deadline)
        answered = acknowledged = False
        try:
            protocol.write(request.frame)
            stats.requests += 1
            if stats is not totals:
                totals.requests += 1
            reply = await waiter
            if reply is None:  # the deadline passed
                if out.bad_frame is not None:
                    self._count(stats, totals, "protocol_errors")
                    raise RemoteProtocolError(
                        f"node {request.node:02d}: no valid answer to {request.label}, "
                        f"only a corrupted frame "
                        f"({out.bad_frame.reason.value}: {out.bad_frame.body!r})"
                    )
                self._count(stats, totals, "timeouts")
                raise ReplyTimeoutError(
                    f"node {request.node:02d} did not answer {request.label} "
                    f"within {timeout * 1000:.0f} ms"
                )
            answered = True
            latency = self._last_rx - sent  # when the answer arrived, not when we resumed
            stats.replies += 1
            stats.record_latency(latency)
            if stats is not totals:
                totals.replies += 1
                totals.record_latency(latency)
            try:
                data = dialect.accept(request, reply)
            except NakError as refusal:
                stats.naks[refusal.code] += 1
                if stats is not totals:
                    totals.naks[refusal.code] += 1
                raise
            ack = dialect.acknowledgement(request, reply)
            if ack is not None:
                acknowledged = await self._acknowledge(protocol, ack)
            return data
        except TransportError:
            self._count(stats, totals, "transport_errors")
            raise
        except asyncio.CancelledError:
            self._count(stats, totals, "cancelled")
            raise
        finally:
            if out.reoutput is not None:
                out.reoutput.cancel()
            self._outstanding = None
            if answered:
                # The guard runs from the answer's arrival: the time this task took
                # to resume already counts towards it.
                self._rest_until = self._last_rx + self._guard_s
                if acknowledged:
                    self._rest_until = max(
                        self._rest_until,
                        self._loop.time() + dialect.rest_after_acknowledgement_s(),
                    )
            else:
                quiet = self._timing.drain_quiet(timeout, self._line)
                self._drain_quiet = max(self._drain_quiet or 0.0, quiet)
                self._failed_at = self._loop.time()

    def _response_timeout(self, request: RequestT, wait_s: float) -> float:
        """The computed response time-out of *request* with the device waiting *wait_s*.

        It depends only on the request (its frame says everything about it),
        the wait, and the arbiter's fixed line and timing, so it is cached.
        The cache starts over when it grows large (a stream of distinct
        parameter writes), so it stays bounded.
        """
        key = (request.frame, wait_s)
        timeout = self._timeouts.get(key)
        if timeout is None:
            if len(self._timeouts) >= _TIMEOUT_CACHE_SIZE:
                self._timeouts.clear()
            dialect = self.dialect
            timeout = self._timeouts[key] = self._timing.response_timeout(
                request,
                self._line,
                wait_s + dialect.processing_s(request),
                dialect.reply_frame_length(request),
            )
        return timeout

    async def _acknowledge(self, protocol: LineProtocol[Any], ack: bytes) -> bool:
        """Send the host's acknowledgement after the answer delay; True when it went out.

        The protocol makes it optional, so a link lost meanwhile only skips it.
        """
        delay = self.dialect.answer_delay_s()
        if delay > 0:
            await asyncio.sleep(delay)
        if not protocol.connected:
            return False
        protocol.write(ack)
        return True

    async def _drain(self) -> None:
        """Wait until the line has been quiet long enough; discard what arrives meanwhile."""
        assert self._drain_quiet is not None
        quiet = self._drain_quiet
        start = self._loop.time()
        give_up = start + self._timing.drain_max_s
        self.stats.drains += 1
        while True:
            now = self._loop.time()
            ready = max(self._last_rx, self._failed_at) + quiet
            if now >= ready:
                break
            if now >= give_up:
                _log.warning("line did not go quiet within %.1f s; going on", quiet)
                break
            await asyncio.sleep(min(ready, give_up) - now)
        protocol = self.link.protocol
        if protocol is not None:
            protocol.reset_parser()
        self._drain_quiet = None

    @staticmethod
    def _count(stats: TransactionStats, totals: TransactionStats, name: str) -> None:
        setattr(stats, name, getattr(stats, name) + 1)
        if stats is not totals:
            setattr(totals, name, getattr(totals, name) + 1)
