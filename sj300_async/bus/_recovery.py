"""Putting the line in order after an attempt: a mixin of the arbiter.

After an answer the line rests, after the host's acknowledgement if the
protocol has one (rules 2 and 7); after a failure it is drained before the
next write (rule 5), and the node that missed its answer is resynchronized
before its next request (rule 9). :mod:`._arbiter`'s docstring states the
rules; this module holds how the arbiter keeps them once an attempt is over.

:class:`LineRecovery` has no state of its own: it is a part of
:class:`~._arbiter.Arbiter`, whose ``__init__`` sets up the attributes
declared here (a mixin costs a call nothing: the methods are the arbiter's).
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING, Any, Generic

from ..wire import (
    LineSettings,
    NakError,
    RemoteProtocolError,
    ReplyTimeoutError,
    SJ300Error,
    TransportError,
)
from ._attempts import Outstanding, Pending, SyncMissed
from ._dialect import Dialect, ReplyT, RequestT
from ._link import Link
from ._protocol import LineProtocol
from ._stats import BusStats, TransactionStats
from ._timing import LATE_REPLY_HORIZON, BusTiming

__all__ = ["LineRecovery"]

_log = logging.getLogger("sj300_async.arbiter")

#: Failed requests an unsynced node remembers at most (the oldest go first).
_PENDING_MAX = 8


class LineRecovery(Generic[RequestT, ReplyT]):
    """The arbiter's rest, drain, acknowledgement and resync (rules 2, 5, 7 and 9)."""

    # The arbiter's state this part works on (see Arbiter.__init__).
    link: Link
    dialect: Dialect[RequestT, ReplyT]
    stats: BusStats
    _loop: asyncio.AbstractEventLoop
    _line: LineSettings
    _timing: BusTiming
    _guard_s: float
    _outstanding: Outstanding[RequestT, ReplyT] | None
    _unsynced: dict[int, list[Pending[RequestT]]]
    _rest_until: float
    _drain_quiet: float | None
    _failed_at: float
    _failed_sent: float
    _last_rx: float
    _early_out: Outstanding[RequestT, ReplyT] | None
    _early_count: int
    _early_by: float
    _early_refused: tuple[int, float] | None

    if TYPE_CHECKING:  # the arbiter's own methods that a sync uses as any attempt does

        def _request_timing(self, request: RequestT, wait_s: float) -> tuple[float, float]: ...

        def _arm_deadline(self, deadline: float) -> None: ...

    # -- after an attempt ------------------------------------------------------------

    def _finish(
        self, out: Outstanding[RequestT, ReplyT], answered: bool, acknowledged: bool
    ) -> None:
        """The line after an attempt or a sync: rest after an answer, else drain next."""
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
                    self._loop.time() + self.dialect.rest_after_acknowledgement_s(),
                )
        else:
            quiet = self._timing.drain_quiet(out.timeout, self._line)
            self._drain_quiet = max(self._drain_quiet or 0.0, quiet)
            self._failed_at = self._loop.time()

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
                _log.warning(
                    "line did not go quiet for %.3f s (the failed request's time-out) "
                    "within %.1f s (drain_max_s); going on",
                    quiet,
                    self._timing.drain_max_s,
                )
                break
            await asyncio.sleep(min(ready, give_up) - now)
        protocol = self.link.protocol
        if protocol is not None:
            protocol.reset_parser()
        self._drain_quiet = None

    def _no_answer(
        self,
        out: Outstanding[RequestT, ReplyT],
        stats: TransactionStats,
        totals: TransactionStats,
        node: int,
        what: str,
        timeout: float,
        timed_out: type[ReplyTimeoutError],
    ) -> SJ300Error:
        """An attempt that got no valid answer, counted: corrupted frames only, or nothing."""
        if out.bad_frame is not None:
            self._count(stats, totals, "protocol_errors")
            return RemoteProtocolError(
                f"node {node:02d}: no valid answer to {what}, only a corrupted frame "
                f"({out.bad_frame.reason.value}: {out.bad_frame.body!r})"
            )
        self._count(stats, totals, "timeouts")
        if self._early_out is out:  # it did answer, too soon (rule 8): the call's error says so
            self._early_out = None
            self._early_refused = (self._early_count, self._early_by)
        return timed_out(
            f"node {node:02d} did not answer {what} within {timeout * 1000:.0f} ms",
            1,
            None,
            timeout,
        )

    @staticmethod
    def _count(stats: TransactionStats, totals: TransactionStats, name: str) -> None:
        setattr(stats, name, getattr(stats, name) + 1)
        if stats is not totals:
            setattr(totals, name, getattr(totals, name) + 1)

    # -- resync (rule 9) -------------------------------------------------------------

    def _missed(self, request: RequestT, timeout: float) -> None:
        """*request* got no valid answer: its node is unsynced until a sync answers."""
        expires = self._loop.time() + LATE_REPLY_HORIZON * timeout
        pending = self._unsynced.setdefault(request.node, [])
        for i, entry in enumerate(pending):
            if entry.request.frame == request.frame:
                pending[i] = Pending(request, max(entry.expires, expires))
                return
        pending.append(Pending(request, expires))
        if len(pending) > _PENDING_MAX:
            del pending[0]

    def _same_link(self, protocol: LineProtocol[Any]) -> LineProtocol[Any]:
        """The link's protocol, if it is still *protocol*: a request never moves to a new
        connection. One that waited (queued, draining, resting) while the link
        dropped and came back fails as if it had dropped a moment later, and
        the new connection's first request is one made for it (a pending stop
        that must go before any poll: the gateway's lapse).

        Raises:
            TransportError: the link is down, or is another connection now.
        """
        current = self.link.require()
        if current is not protocol:
            raise TransportError(
                f"{self.link.description} reconnected while the request waited; it was not sent"
            )
        return current

    async def _sync(
        self, node: int, stats: TransactionStats, wait_s: float, timeout_s: float | None
    ) -> None:
        """Resynchronize *node* before its next request (rule 9), holding the line.

        Raises:
            ReplyTimeoutError: the sync got no positive answer in time (it joins
                the pending requests; the attempt may be retried).
            RemoteProtocolError: only a corrupted frame came.
            TransportError: the link is down or dropped.
        """
        loop = self._loop
        now = loop.time()
        pending = [entry for entry in self._unsynced[node] if entry.expires > now]
        if not pending:
            del self._unsynced[node]  # every reply that might have come is past the horizon
            return
        self._unsynced[node] = pending
        dialect = self.dialect
        sync = dialect.sync_request(node, [entry.request for entry in pending])
        if sync is None:
            await self._wait_out(node, pending)
            return
        protocol = self.link.require()
        if self._rest_until > now:
            await asyncio.sleep(self._rest_until - now)
            protocol = self._same_link(protocol)
            now = loop.time()
        if protocol.write_paused:
            await protocol.wait_writable()
            protocol = self._same_link(protocol)
            now = loop.time()
        timeout, floor = self._request_timing(sync, wait_s)
        if timeout_s:
            timeout = timeout_s
        totals = self.stats.transactions
        out: Outstanding[RequestT, ReplyT] = Outstanding(
            sync, loop.create_future(), stats, timeout, now + timeout, now + floor
        )
        self._outstanding = out
        self._arm_deadline(out.deadline)
        answered = acknowledged = False
        try:
            protocol.write(sync.frame)
            self.stats.resyncs += 1
            stats.requests += 1
            if stats is not totals:
                totals.requests += 1
            _log.debug("node %02d missed an answer: sync with %s", node, sync.label)
            while True:
                reply = await out.waiter
                if reply is None:
                    break  # the deadline passed
                try:
                    dialect.accept(sync, reply)
                except NakError:
                    # A NAK may be the late answer to any pending request: it
                    # proves nothing. The sync's own answer must still come.
                    self.stats.stray_frames += 1
                    stats.discarded_frames += 1
                    _log.debug("NAK while syncing node %02d: not the sync's answer", node)
                    out.waiter = loop.create_future()
                    continue
                answered = True
                break
            if not answered:
                self._failed_sent = now
                raise self._no_answer(
                    out, stats, totals, node, f"the sync request ({sync.label})", timeout,
                    SyncMissed,
                )  # fmt: skip
            del self._unsynced[node]  # in order: whatever was late is behind us
            totals.record_answer(stats, self._last_rx - now)
            assert reply is not None
            ack = dialect.acknowledgement(sync, reply)
            if ack is not None:
                acknowledged = await self._acknowledge(protocol, ack)
        except TransportError:
            self._count(stats, totals, "transport_errors")
            raise
        except asyncio.CancelledError:
            self._count(stats, totals, "cancelled")
            raise
        finally:
            self._finish(out, answered, acknowledged)
            if not answered:
                self._missed(sync, timeout)

    async def _wait_out(self, node: int, pending: list[Pending[RequestT]]) -> None:
        """No sync request of a shape of its own: wait until the late replies are past
        the horizon (:data:`LATE_REPLY_HORIZON` time-outs after each failure),
        discarding what arrives meanwhile."""
        until = max(entry.expires for entry in pending)
        self.stats.drains += 1
        _log.debug(
            "node %02d missed an answer and no sync request can tell its late replies "
            "from an answer: waiting %.3f s",
            node,
            until - self._loop.time(),
        )
        delay = until - self._loop.time()
        if delay > 0:
            await asyncio.sleep(delay)
        protocol = self.link.protocol
        if protocol is not None:
            protocol.reset_parser()
        self._unsynced.pop(node, None)
