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
8. Plausibility: a frame shaped like the answer that arrives sooner after
   the write than the line could carry the request and the shortest reply
   (:meth:`~._timing.BusTiming.answer_floor`) is not the answer — a
   duplicate of the previous reply, or a stray — and is counted
   (``early_frames``) and discarded; the wait goes on. A call that then
   fails on time-outs says so in its :class:`ReplyTimeoutError`, with the
   URL's ways out (the peer is faster than the line: ``baudrate=0``, or the
   line's real speed).
9. Resync: after a time-out or a corrupted-only answer, the node's replies
   may still come, later than the drain waits. The node is *unsynced*: it
   remembers the requests that failed (for
   :data:`~._timing.LATE_REPLY_HORIZON` time-outs). Its next transaction
   first sends, in the same hold of the line, the dialect's sync request
   (:meth:`~._dialect.Dialect.sync_request`: read-only, of a shape no
   pending reply has) and waits for its positive answer; the node answers
   in order, so whatever came before is stale and was discarded as stray.
   Then the real request goes out. A sync that fails joins the pending
   requests, and the attempt fails as a time-out (retried as usual). With
   no sync request of a shape of its own, the arbiter waits until the
   pending replies are past the horizon instead. A healthy node never syncs.
10. A call's attempts: ``retries + 1`` at most, none started after the
    timing's ``call_deadline_s``; a call that ends in time-outs raises one
    :class:`ReplyTimeoutError` that states the attempts and the whole time.

This module runs the attempts and listens to the line (the re-output
request of rule 7 included). What the line needs once an attempt is over,
the rest, the drain, the acknowledgement and the resync, is in
:mod:`._recovery`; the records of attempts are in :mod:`._attempts`.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from ..wire import (
    BadFrame,
    BusClosedError,
    Discarded,
    LineSettings,
    NakError,
    RemoteProtocolError,
    ReplyTimeoutError,
    SJ300Error,
    TransportError,
)
from ._attempts import Outstanding, Pending, SyncMissed
from ._dialect import Dialect, ReplyT, RequestT
from ._linequeue import LineQueue
from ._link import Link
from ._protocol import LineProtocol
from ._recovery import LineRecovery
from ._stats import BusStats, TransactionStats
from ._timing import BusTiming

__all__ = ["Arbiter"]

_log = logging.getLogger("sj300_async.arbiter")

#: Distinct requests whose timing is remembered (see _request_timing).
_TIMEOUT_CACHE_SIZE = 256


class Arbiter(LineRecovery[RequestT, ReplyT]):
    """Serializes transactions on one line and enforces the timing rules.

    What happens to the line once an attempt is over (the rest, the drain,
    the acknowledgement and the resync) is in :class:`~._recovery.LineRecovery`.
    """

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
        # Does the protocol let the host answer a reply (rule 7)? Asked once:
        # SJ300 never does, and the question would cost a call per answer.
        self._acknowledges = dialect.acknowledges
        self._answers = dialect.answers
        self._line = line
        self._timing = timing
        self._guard_s = timing.guard(line)
        self._call_deadline = timing.call_deadline_s
        # (response time-out, plausibility floor) by (frame, wait): computed once
        # per distinct request (see _request_timing). A poll repeats a handful
        # of frames.
        self._timings: dict[tuple[bytes, float], tuple[float, float]] = {}
        # Nodes that missed an answer, with the requests whose replies may still come.
        self._unsynced: dict[int, list[Pending[RequestT]]] = {}
        # The last chunk received (for the log of an early frame).
        self._last_chunk = b""
        # Early answers (rule 8): the attempt they came to, how many, and the most
        # any came before the floor (seconds); a failed attempt's pair is handed
        # to its call (_early_refused). Kept off the success path: only an early
        # frame and a failure touch them.
        self._early_out: Outstanding[RequestT, ReplyT] | None = None
        self._early_count = 0
        self._early_by = 0.0
        self._early_refused: tuple[int, float] | None = None
        self.stats = stats
        self.queue = LineQueue()
        self._loop = asyncio.get_running_loop()
        self._outstanding: Outstanding[RequestT, ReplyT] | None = None
        # Loop time before which nothing may be written (guard interval).
        self._rest_until = 0.0
        # After a failure: how long the line must be quiet before the next write.
        self._drain_quiet: float | None = None
        self._failed_at = 0.0
        # The write time of the last attempt that ended without an answer (for the
        # time a failed call took: see transact).
        self._failed_sent = 0.0
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

    def bytes_received(self, data: bytes, now: float) -> None:
        self._last_rx = now
        self._last_chunk = data

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
        if self._answers(out.request, event):
            if now >= out.not_before:
                out.waiter.set_result(event)
            else:
                self._early_frame(out, event, now)
            return
        self.stats.stray_frames += 1
        out.stats.discarded_frames += 1
        _log.debug("stray frame while waiting for node %02d: %s", out.request.node, event)

    def _early_frame(self, out: Outstanding[RequestT, ReplyT], event: ReplyT, now: float) -> None:
        """A frame shaped like the answer, sooner than the line allows (rule 8): discard it."""
        self.stats.early_frames += 1
        out.stats.discarded_frames += 1
        if self._early_out is not out:
            self._early_out, self._early_count, self._early_by = out, 0, 0.0
        self._early_count += 1
        self._early_by = max(self._early_by, out.not_before - now)
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug(
                "early frame from node %02d discarded, %.1f ms sooner than the line "
                "allows an answer: %s; chunk %s",
                out.request.node,
                (out.not_before - now) * 1000,
                self.dialect.describe(event),
                self._last_chunk.hex(" "),
            )

    def _request_reoutput(
        self, out: Outstanding[RequestT, ReplyT], bad_frame: BadFrame, now: float
    ) -> None:
        frame = self.dialect.reoutput_request(out.request, bad_frame)
        if frame is None:
            return
        delay = self.dialect.answer_delay_s()
        out.reoutput = self._loop.call_at(now + delay, self._send_reoutput, out, frame)
        # The repeated reply needs a whole exchange's time again. Deadlines only
        # move later: the armed timer fires first and re-arms for this one.
        out.deadline = max(out.deadline, now + delay + out.timeout)

    def _send_reoutput(self, out: Outstanding[RequestT, ReplyT], frame: bytes) -> None:
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
            node = out.request.node
            if self.link.closed:  # the user closed the bus: not a failure of the line
                error: TransportError = BusClosedError(
                    f"bus {self.link.description} closed while waiting for node {node:02d}"
                )
            else:
                error = TransportError(f"connection lost while waiting for node {node:02d}")
            out.waiter.set_exception(error)

    def close(self) -> None:
        """Cancel the deadline timer (the bus is closing): no timer outlives the bus.

        A transaction still waiting fails through ``connection_lost`` as the link closes.
        """
        timer, self._deadline_timer = self._deadline_timer, None
        if timer is not None:
            timer.cancel()

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
            ReplyTimeoutError: no answer in time, on every attempt (or none made
                before the call deadline); it states the attempts and the time.
            RemoteProtocolError: only corrupted answers, on every attempt.
            TransportError: the link is down or dropped (never retried).
            BusClosedError: the bus is closed.
        """
        # Nothing here costs a successful call more than a few attribute reads:
        # the call's start is taken only with a deadline, else at its first failure.
        #
        # Each attempt runs in this coroutine's own frame, not in one of its
        # own: every resume of a transaction passes through one frame less, and
        # a call creates one coroutine less (issue 18). Whatever a clean line
        # never needs (drain, sync, rest, a paused transport) is in _prepare,
        # which the fast path skips after one test.
        loop = self._loop
        link = self.link
        queue = self.queue
        limit = self._call_deadline
        start = 0.0 if limit is None else loop.time()
        failed: list[SJ300Error] | None = None
        # (count, most seconds before the floor) of each failed attempt that
        # refused early answers; made with *failed*, read only when it exists.
        refusals: list[tuple[int, float]]
        protocol = link.require()  # fail promptly, before queueing, while the link is down
        while True:
            if failed is not None:  # a retry stays on its first attempt's connection
                protocol = self._same_link(protocol)
            queued = not queue.take()
            if queued:
                await queue.acquire(urgent)
            try:  # the line is ours from here: released in the finally, whatever happens
                if queued:  # the link may have dropped (or come back anew) while we queued
                    protocol = self._same_link(protocol)
                now = loop.time()
                if limit is not None and now - start >= limit:
                    break  # no attempt starts after the call's deadline
                if (
                    self._drain_quiet is not None
                    or self._rest_until > now
                    or protocol.write_paused
                    or (self._unsynced and request.node in self._unsynced)
                ):
                    protocol = await self._prepare(request, stats, wait_s, timeout_s)
                    now = loop.time()
                totals = self.stats.transactions
                # Only requests that expect an answer have a timing: a known
                # one needs no other test.
                timing = self._timings.get((request.frame, wait_s))
                if timing is None:
                    if not request.expects_reply:
                        protocol.write(request.frame)
                        self._count(stats, totals, "broadcasts")
                        self._rest_until = loop.time() + self._timing.after_broadcast(
                            request, self._line
                        )
                        return b""
                    timing = self._request_timing(request, wait_s)
                timeout = timeout_s if timeout_s else timing[0]
                waiter: asyncio.Future[ReplyT | None] = loop.create_future()
                out = Outstanding(request, waiter, stats, timeout, now + timeout, now + timing[1])
                self._outstanding = out  # registered before the write: no answer goes unseen
                if self._deadline_timer is None or self._deadline_due > out.deadline:
                    self._arm_deadline(out.deadline)
                answered = acknowledged = False
                try:
                    protocol.write(request.frame)
                    stats.requests += 1
                    if stats is not totals:
                        totals.requests += 1
                    reply = await waiter
                    if reply is None:  # the deadline passed
                        self._failed_sent = now
                        self._missed(request, timeout)  # its reply may still come: rule 9
                        raise self._no_answer(
                            out, stats, totals, request.node, request.label, timeout,
                            ReplyTimeoutError,
                        )  # fmt: skip
                    answered = True
                    # When the answer arrived, not when this task resumed.
                    totals.record_answer(stats, self._last_rx - now)
                    try:
                        data = self.dialect.accept(request, reply)
                    except NakError as refusal:
                        stats.naks[refusal.code] += 1
                        if stats is not totals:
                            totals.naks[refusal.code] += 1
                        raise
                    if self._acknowledges:
                        ack = self.dialect.acknowledgement(request, reply)
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
                    self._finish(out, answered, acknowledged)
            except (ReplyTimeoutError, RemoteProtocolError, NakError) as exc:
                if failed is None:
                    failed = []
                    refusals = []
                    if limit is None:
                        # Without a deadline the call counts from its first write.
                        refused = isinstance(exc, NakError)
                        start = loop.time() if refused else self._failed_sent
                failed.append(exc)
                if self._early_refused is not None:  # set by this attempt's _no_answer
                    refusals.append(self._early_refused)
                    self._early_refused = None
                if (
                    len(failed) > retries
                    or not self.dialect.retryable(exc)
                    or (limit is not None and loop.time() - start >= limit)
                ):
                    break
                stats.retries += 1
                if stats is not self.stats.transactions:
                    self.stats.transactions.retries += 1
                _log.debug("retry %d of %s: %s", len(failed), request.frame.hex(" "), exc)
            finally:
                queue.release()
        elapsed = loop.time() - start
        if failed and not isinstance(failed[-1], ReplyTimeoutError):
            raise failed[-1]  # the drive's NAK, a corrupted answer: as the last attempt got it
        if failed is None:
            raise self._call_timed_out(request, [], elapsed, limit, [])
        raise self._call_timed_out(request, failed, elapsed, limit, refusals)

    def _call_timed_out(
        self,
        request: RequestT,
        failed: list[SJ300Error],
        elapsed: float,
        limit: float | None,
        refusals: list[tuple[int, float]],
    ) -> ReplyTimeoutError:
        """The error of a call whose attempts failed, the last by a time-out, or that its
        deadline stopped before the first (*failed* empty); *refusals*: the early answers
        (rule 8) its attempts refused, (count, most seconds before the floor) each."""
        who = f"{self.dialect.node_noun} {request.node:02d}"
        attempts = len(failed)
        if not attempts:
            return ReplyTimeoutError(
                f"{who}: {request.label} not sent: the line was busy for the whole "
                f"call deadline of {limit:g} s ({elapsed:.2f} s)",
                0,
                elapsed,
            )
        timeouts = [
            exc.timeout_s
            for exc in failed
            if isinstance(exc, ReplyTimeoutError) and exc.timeout_s is not None
        ]
        syncs = sum(isinstance(exc, SyncMissed) for exc in failed)
        low, high = min(timeouts), max(timeouts)
        if attempts == 1:
            each = f"1 attempt of {high * 1000:.0f} ms"
        elif round(low * 1000) == round(high * 1000):
            each = f"{attempts} attempts of {high * 1000:.0f} ms each"
        else:
            each = f"{attempts} attempts of {low * 1000:.0f}..{high * 1000:.0f} ms"
        message = f"{who} did not answer {request.label}: {each}, {elapsed:.2f} s in all"
        if syncs == 1:
            message += " (one of them a sync request after a missed answer)"
        elif syncs:
            message += f" ({syncs} of them sync requests after a missed answer)"
        if limit is not None and elapsed >= limit:
            message += f"; call deadline {limit:g} s"
        if refusals:
            message += self._early_advice(refusals)
        return ReplyTimeoutError(message, attempts, elapsed, high)

    def _early_advice(self, refusals: list[tuple[int, float]]) -> str:
        """What a call that timed out says of the answers it refused as early (rule 8)."""
        count = sum(n for n, _ in refusals)
        most_ms = max(by for _, by in refusals) * 1000
        baud = max(self._line.baudrate, self._timing.plausible_baudrate)
        answers, verb = ("1 answer", "was") if count == 1 else (f"{count} answers", "were")
        return (
            f"; {answers} came up to {most_ms:.1f} ms sooner than a {baud}-baud line "
            f"can carry request and answer, and {verb} refused as early: for a peer faster "
            "than a real line (an emulator, a test double) add baudrate=0 to the URL, which "
            f"turns the check off; for a line faster than {baud} baud give its speed "
            "(baudrate=N)"
        )

    async def send(
        self, request: RequestT, stats: TransactionStats, *, urgent: bool = False
    ) -> None:
        """Write a request that gets no answer; the line rests after it as the timing says.

        Raises:
            TransportError: the link is down or dropped.
        """
        await self.transact(request, stats, urgent=urgent)

    async def _prepare(
        self,
        request: RequestT,
        stats: TransactionStats,
        wait_s: float,
        timeout_s: float | None,
    ) -> LineProtocol[Any]:
        """Make the line ready for *request*: drained after a failure (rule 5),
        its node synced (rule 9), rested (rule 2), the transport writable.
        Return the protocol to write to.

        Raises:
            ReplyTimeoutError: the node's sync request got no answer.
            RemoteProtocolError: the sync got only a corrupted frame.
            TransportError: the link is down or dropped.
        """
        protocol = self.link.require()
        if self._drain_quiet is not None:
            await self._drain()
            protocol = self._same_link(protocol)
        if self._unsynced and request.expects_reply and request.node in self._unsynced:
            await self._sync(request.node, stats, wait_s, timeout_s)  # rule 9
            protocol = self._same_link(protocol)
        now = self._loop.time()
        if self._rest_until > now:
            await asyncio.sleep(self._rest_until - now)
            protocol = self._same_link(protocol)
        if protocol.write_paused:
            await protocol.wait_writable()
            protocol = self._same_link(protocol)  # the link may have dropped while we waited
        return protocol

    def _request_timing(self, request: RequestT, wait_s: float) -> tuple[float, float]:
        """The computed response time-out of *request* with the device waiting *wait_s*,
        and its plausibility floor (rule 8), in seconds from the write.

        Both depend only on the request (its frame says everything about it),
        the wait, and the arbiter's fixed line and timing, so they are cached.
        The cache starts over when it grows large (a stream of distinct
        parameter writes), so it stays bounded.
        """
        key = (request.frame, wait_s)
        timing = self._timings.get(key)
        if timing is None:
            if len(self._timings) >= _TIMEOUT_CACHE_SIZE:
                self._timings.clear()
            dialect = self.dialect
            timing = self._timings[key] = (
                self._timing.response_timeout(
                    request,
                    self._line,
                    wait_s + dialect.processing_s(request),
                    dialect.reply_frame_length(request),
                ),
                self._timing.answer_floor(
                    request, self._line, dialect.shortest_reply_length(request)
                ),
            )
        return timing
