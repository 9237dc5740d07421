"""The bus as a drive sees it: requests of one protocol in, the data of their answers out.

A drive class holds a :class:`Channel` typed in its protocol's request type,
so the whole transaction path is typed: ``Channel[Request].transact(request)``
runs the request through the bus's arbiter and returns the positive answer's
data, as the dialect's :meth:`~._dialect.Dialect.accept` extracted it. The
channel is where a closed or read-only bus refuses a request, before it
queues for the line.
"""

from __future__ import annotations

from collections.abc import Coroutine, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import TYPE_CHECKING, Any, Generic, Protocol

from ..wire import BusClosedError, LocalProtocolError, ReadOnlyError
from ._dialect import Dialect, RequestT
from ._stats import BusStats, TransactionStats

if TYPE_CHECKING:
    from ._arbiter import Arbiter

__all__ = ["Channel", "cap_retries", "retries_at_most"]

#: The current task's cap on a call's retries (see :func:`retries_at_most`).
_RETRIES_CAP: ContextVar[int | None] = ContextVar("sj300_async_retries_cap", default=None)


@contextmanager
def retries_at_most(retries: int) -> Iterator[None]:
    """Within the block, this task's calls make at most ``retries + 1`` attempts.

    For code that reaches the line through a drive's methods, which take no
    ``retries`` (the poller caps its reads with it). A call's own ``retries=``
    and the bus's setting still apply when they are lower.
    """
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise LocalProtocolError(f"retries must be an int >= 0, got {retries!r}")
    token = _RETRIES_CAP.set(retries)
    try:
        yield
    finally:
        _RETRIES_CAP.reset(token)


def cap_retries(retries: int) -> None:
    """From now on, the current task's calls make at most ``retries + 1`` attempts.

    :func:`retries_at_most` for a task that keeps the cap for its whole life
    (the poller's polling task): set once, it costs nothing per call. The
    task's context goes with the task.
    """
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise LocalProtocolError(f"retries must be an int >= 0, got {retries!r}")
    _RETRIES_CAP.set(retries)


class BusState(Protocol):
    """What a channel reads of its bus (the bus itself)."""

    @property
    def description(self) -> str: ...

    @property
    def read_only(self) -> bool: ...

    @property
    def closed(self) -> bool: ...

    @property
    def stats(self) -> BusStats: ...


class Channel(Generic[RequestT]):
    """A typed gate to one bus's arbiter (made by the bus, handed to its drives)."""

    __slots__ = ("_arbiter", "_bus", "_dialect", "_retries")

    def __init__(
        self,
        bus: BusState,
        arbiter: Arbiter[RequestT, object],
        dialect: Dialect[RequestT, object],
        retries: int,
    ) -> None:
        self._bus = bus
        self._arbiter = arbiter
        self._dialect = dialect
        self._retries = retries

    @property
    def description(self) -> str:
        """The bus's description, e.g. ``tcp://127.0.0.1:4001``."""
        return self._bus.description

    @property
    def read_only(self) -> bool:
        """True when the bus refuses every request that changes a drive."""
        return self._bus.read_only

    def retries_allowed(self) -> int:
        """The retries a call of the current task gets: the bus's, under any cap
        (:func:`retries_at_most`). For a drive that makes its own retries."""
        cap = _RETRIES_CAP.get()
        return self._retries if cap is None else min(cap, self._retries)

    @property
    def connects(self) -> int:
        """How many times the bus's link has connected: a drive that keeps state
        of the far end (FR-700's parameter bank) forgets it on a new connection."""
        return self._bus.stats.connects

    @property
    def dialect(self) -> Dialect[RequestT, object]:
        """The bus's protocol."""
        return self._dialect

    def check(self, request: RequestT) -> None:
        """Refuse *request* now if the bus is closed, or read-only and it writes.

        Raises:
            BusClosedError: the bus is closed (nothing sent).
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        bus = self._bus
        if bus.closed:
            raise BusClosedError(f"bus {bus.description} is closed")
        if bus.read_only and self._dialect.writes(request):
            raise ReadOnlyError(f"bus {bus.description} is read-only: {request.label} refused")

    def transact(
        self,
        request: RequestT,
        stats: TransactionStats,
        *,
        wait_s: float = 0.0,
        timeout_s: float | None = None,
        retries: int | None = None,
        urgent: bool = False,
    ) -> Coroutine[Any, Any, bytes]:
        """Run a request; return (a coroutine of) the data of its positive answer.

        A request that expects no answer is written, and ``b""`` comes back
        (:meth:`send` says so in its type).

        Not a coroutine function: it checks the call and returns the arbiter's
        coroutine for the caller to await, so a transaction's every resume
        passes through one frame less (``Drive._data`` is done the same way;
        ``python -m benchmarks.profile_tcp`` counts the instructions of a TCP
        round trip). The refusals below are raised by the call itself, before
        any ``await``.

        *retries* replaces the bus's retries for this call (None: the bus's);
        :func:`retries_at_most` caps either for a whole block of calls.

        Raises:
            NakError: the drive refused the request.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            BusClosedError: the bus is closed (nothing sent).
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        # check() written out: this runs once per transaction.
        bus = self._bus
        if bus.closed or (bus.read_only and self._dialect.writes(request)):
            self.check(request)  # raises the right error
        if retries is None:
            retries = self._retries
        elif isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise LocalProtocolError(f"retries must be an int >= 0, got {retries!r}")
        cap = _RETRIES_CAP.get()
        if cap is not None and cap < retries:
            retries = cap
        return self._arbiter.transact(
            request, stats, wait_s=wait_s, timeout_s=timeout_s, retries=retries, urgent=urgent
        )

    async def send(
        self, request: RequestT, stats: TransactionStats, *, urgent: bool = False
    ) -> None:
        """Write a request that gets no answer (a broadcast, a reset), resting the line after it.

        Raises:
            LocalProtocolError: the request expects an answer (use :meth:`transact`).
            TransportError: the link is down, or a write failed.
            BusClosedError: the bus is closed (nothing sent).
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        self.check(request)
        if request.expects_reply:
            raise LocalProtocolError(f"{request.label} expects a reply: run it with transact()")
        await self._arbiter.send(request, stats, urgent=urgent)
