"""The poller: keep a picture of many drives on many buses up to date.

Each bus gets one polling task (in an anyio task group) that walks its
drives every ``interval_s``. Every read is its own transaction on the bus's
arbiter, so a command from another task waits for at most the transaction
on the line — never for a whole cycle — and a stop waits for nothing queued.

Health: a drive goes offline after ``offline_after`` consecutive failed
polls. A failing drive's share of the line is bounded, so the drives that
answer keep their pace while others fail:

- A drive that answers is read with at most ``retries`` retries per read
  (default 0, never more than the bus's): the next cycle is the poll's
  retry, and a drive goes offline only after ``offline_after`` failed polls.
  Its poll stops at the first failed read, but for a parameter the drive
  refuses (below). (``retries=1`` rides out a lost
  reply within the poll, at the price of two more time-outs per failing
  drive in its first failed cycle.)
- A drive whose last poll failed (failing, or offline) is first *probed*:
  one attempt (no retry) of its protocol's cheap read-only request (the
  dialect's ``sync_request``, e.g. SJ300's command 09, FR-700's status
  read) with the bus's computed response time-out for that request. Only
  if it answers is the drive polled in full, in the same cycle. A probe
  that gets no answer costs one time-out plus the drain after it (one
  time-out of quiet): about two time-outs of a short request.
- An offline drive is probed at most every ``offline_probe_interval_s``
  (default 0.5 s), and a cycle makes at most one offline probe that goes
  unanswered: the offline drives due wait their turn, longest-waiting
  first, except that a probe that is answered lets the next one go in the
  same cycle (drives that come back together, after a power cut, are all
  back within a cycle).

So per cycle, failing drives take at most two short-request time-outs each
while being declared offline (``offline_after`` cycles), and two in all once
offline; with one offline drive, it is back online within about one cycle
(or ``offline_probe_interval_s``, the longer) of answering again.
tests/poller/test_poller_pace.py measures the pace the drives that answer
keep while others are declared offline, and once they are.
Docs: docs/RELIABILITY.md, "The poller when drives fail".

Errors from :meth:`Poller.on_sample` callbacks are logged (logger
``sj300_async.poller``, ERROR, with the traceback) and counted in
:attr:`BusPollStats.callback_errors`; polling goes on. With
``callback_errors="raise"`` the first one stops the poller instead, and
leaves the ``async with`` block with it.

A drive that has never answered is not known to be there: ``answered`` (on
:class:`DriveHealth` and on each :class:`Sample`) stays False until its
first reply (a refusal counts: the drive is there). ``online`` describes the
polling (a drive starts online, is polled in full and goes offline after
``offline_after`` failures); a drive is up only when it is ``online`` *and*
has ``answered``, which is how ``sj300 monitor`` shows it.

A parameter the drive refuses (a NAK to its read: the drive is there, and
has no such parameter, or will not give it) is *unavailable*, not a failed
poll: it is named in the sample's ``unavailable``, left out of its
``parameters``, and the poll goes on with the next read; the drive's health
is not touched. The first refusal of a parameter is logged at WARNING, once
per drive and parameter until it reads again (then at INFO). A NAK to the
status or monitor read fails the poll as any other error does.

Every protocol's drives are polled the same way: the poller calls the
drive's ``read_status``, ``read_monitor`` and ``read_parameter``.
``parameters`` may mix protocols' codes (SJ300's ``"F002"``, FR-700's
``"Pr.7"``); each bus reads the ones its dialect recognises.

Results go to callbacks (:meth:`Poller.on_sample`) and to any number of
async iterators (:meth:`Poller.samples`). An iterator whose consumer falls
behind holds at most ``buffer`` samples; older ones are dropped and counted
in :attr:`Poller.dropped_samples` — never silently. A drive's sample is
published once the next drive's request is on the line (the cycle's last one
at the cycle's end), so that the line does not wait for the callbacks; with
``callback_errors="raise"``, at once. Its drive's health is up to date
before.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncGenerator, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Final, Literal, get_args

import anyio
import anyio.abc

from ._poll_results import BusPollStats, DriveHealth, Sample
from .bus import Bus, TransactionStats, cap_retries, get_dialect, protocol_names, retries_at_most
from .fr700 import Fr700Monitor, Fr700Status
from .sj300 import InverterStatus, MonitorData
from .wire import LocalProtocolError, NakError, SJ300Error

__all__ = ["BusPollStats", "DriveHealth", "Poller", "Sample"]

_log = logging.getLogger("sj300_async.poller")

Read = Literal["status", "monitor"]
_READS: Final = ("status", "monitor")
#: What the poller does with an exception from an ``on_sample`` callback.
CallbackErrors = Literal["log", "raise"]


#: A drive's poll, done and not yet published: the fields of its :class:`Sample`
#: but the bus (node, timestamp, online, status, monitor, parameters, error,
#: latency_s, answered, started, unavailable). A tuple: it is built on the line's
#: critical path, between a reply and the next request, where a class costs more.
_Poll = tuple[
    int,
    float,
    bool,
    InverterStatus | Fr700Status | None,
    MonitorData | Fr700Monitor | None,
    dict[str, float],
    str | None,
    float | None,
    bool,
    float,
    frozenset[str],
]
#: The usual ``unavailable``: shared, so that a poll builds no set.
_NONE_UNAVAILABLE: Final[frozenset[str]] = frozenset()


@dataclass(slots=True)
class _Target:
    bus: Bus[Any]
    nodes: list[int]
    #: The poller's parameters this bus's protocol has.
    parameters: tuple[str, ...] = ()
    stats: BusPollStats = field(default_factory=BusPollStats)
    health: dict[int, DriveHealth] = field(default_factory=dict)
    #: The probes' transaction counters (they go through no drive object).
    probe_stats: TransactionStats = field(default_factory=TransactionStats)
    #: The drive objects of ``nodes`` (``bus.drive(node)``, looked up once).
    drives: dict[int, Any] = field(default_factory=dict)
    #: Polls done and not yet published (see ``Poller._poll_bus``).
    unpublished: list[_Poll] = field(default_factory=list)
    #: Holds on the bus's polls (:meth:`Poller.hold`); polls go on at 0.
    holds: int = 0
    #: Set while ``holds`` is 0.
    resumed: asyncio.Event = field(default_factory=asyncio.Event)


_END: Final = object()


class Poller:
    """Polls drives on one or more buses (see the module docstring).

    Use as an async context manager; polling runs while inside it::

        poller = Poller(interval_s=0.5)
        poller.add(bus, [1, 2, 3])
        async with poller:
            async for sample in poller.samples():
                print(sample.node, sample.monitor)

    The share of the line failing drives take (details in the module
    docstring): a failing drive costs at most one unanswered attempt of a
    short request plus the drain after it (two of its time-outs) per cycle
    until it is offline; offline drives cost at most that once per cycle in
    all (one unanswered probe per cycle, each drive at most every
    ``offline_probe_interval_s``).

    Args:
        interval_s: the time from one cycle's start to the next's (a cycle
            that overruns it is followed at once).
        reads: what each poll reads (``"status"``, ``"monitor"``).
        parameters: parameter codes to read too (each bus reads its protocol's).
        offline_after: consecutive failed polls that make a drive offline.
        offline_probe_interval_s: the least time between two probes of one
            offline drive.
        retries: retries per read of a drive that answers (capped by the bus's).
        buffer: samples an iterator holds before dropping the oldest.
        callback_errors: ``"log"`` (default): an exception from an
            ``on_sample`` callback is logged and counted in
            :attr:`BusPollStats.callback_errors`, and polling goes on;
            ``"raise"``: it stops the poller (and leaves the ``async with``).
    """

    def __init__(
        self,
        *,
        interval_s: float = 0.5,
        reads: Iterable[Read] = _READS,
        parameters: Iterable[str] = (),
        offline_after: int = 3,
        offline_probe_interval_s: float = 0.5,
        retries: int = 0,
        buffer: int = 1000,
        callback_errors: CallbackErrors = "log",
    ) -> None:
        reads = tuple(reads)
        if unknown := set(reads) - set(_READS):
            raise LocalProtocolError(f"unknown reads {sorted(unknown)}; choose from {_READS}")
        if not interval_s >= 0:
            raise LocalProtocolError(f"interval_s must be >= 0, got {interval_s!r}")
        if isinstance(offline_after, bool) or not isinstance(offline_after, int):
            raise LocalProtocolError(f"offline_after must be an int, got {offline_after!r}")
        if offline_after < 1 or not offline_probe_interval_s >= 0 or buffer < 1:
            raise LocalProtocolError("offline_after and buffer must be >= 1, probe interval >= 0")
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise LocalProtocolError(f"retries must be an int >= 0, got {retries!r}")
        if callback_errors not in get_args(CallbackErrors):
            raise LocalProtocolError(
                f"callback_errors must be 'log' or 'raise', got {callback_errors!r}"
            )
        self.interval_s = interval_s
        self.reads: tuple[Read, ...] = reads
        self.parameters = tuple(_parameter_name(c) for c in parameters)
        self.offline_after = offline_after
        self.offline_probe_interval_s = offline_probe_interval_s
        #: Retries per read of a drive that answers (capped by the bus's own).
        self.retries = retries
        self.buffer = buffer
        self.callback_errors: CallbackErrors = callback_errors
        #: Samples dropped because an iterator's consumer fell behind.
        self.dropped_samples = 0
        self._targets: dict[int, _Target] = {}
        self._callbacks: list[Callable[[Sample], None]] = []
        self._queues: list[asyncio.Queue[object]] = []
        self._stack: contextlib.AsyncExitStack | None = None
        self._task_group: anyio.abc.TaskGroup | None = None

    # -- configuration ---------------------------------------------------------

    def add(self, bus: Bus[Any], nodes: Iterable[int]) -> None:
        """Poll *nodes* on *bus* (may be called while running: the bus starts at once)."""
        nodes = sorted(set(nodes))
        drives = {node: bus.drive(node) for node in nodes}  # validates the node numbers
        target = self._targets.get(id(bus))
        if target is None:
            own = tuple(p for p in self.parameters if bus.dialect.parameter_code(p) == p)
            target = _Target(bus, [], parameters=own)
            self._targets[id(bus)] = target
            if self._task_group is not None:
                self._task_group.start_soon(self._poll_bus, target)
        for node in nodes:
            if node not in target.nodes:
                target.nodes.append(node)
                target.health[node] = DriveHealth()
                target.drives[node] = drives[node]
        target.nodes.sort()

    def hold(self, bus: Bus[Any] | str) -> None:
        """Start no drive's poll (or probe) on *bus* until :meth:`release`.

        A drive's poll already under way goes on with its reads: a caller
        whose request must be the first on the line holds before the line
        can take requests, e.g. from :meth:`~sj300_async.Bus.on_connected`
        (the gateway's pending stop when the link comes back). The drives'
        health stands still while held: hold briefly. Holds nest: polls go
        on once every hold is released.
        """
        target = self._target(bus)
        target.holds += 1
        target.resumed.clear()

    def release(self, bus: Bus[Any] | str) -> None:
        """Release one :meth:`hold` of *bus*."""
        target = self._target(bus)
        if target.holds <= 0:
            raise LocalProtocolError("release() without a hold")
        target.holds -= 1
        if not target.holds:
            target.resumed.set()

    def on_sample(self, callback: Callable[[Sample], None]) -> Callable[[], None]:
        """Call *callback* with every sample; returns a function that unregisters it."""
        self._callbacks.append(callback)
        return lambda: self._callbacks.remove(callback)

    def health(self, bus: Bus[Any] | str, node: int) -> DriveHealth:
        """The health record of *node* on *bus* (a Bus or its description).

        Raises:
            KeyError: the drive is not polled.
        """
        return self._target(bus).health[node]

    def bus_stats(self, bus: Bus[Any] | str) -> BusPollStats:
        """Polling statistics of *bus* (a Bus or its description)."""
        return self._target(bus).stats

    def _target(self, bus: Bus[Any] | str) -> _Target:
        # Targets are keyed by the Bus object: two buses may share a description
        # (two sim:// buses with the same nodes). By description, the first matches.
        if not isinstance(bus, str):
            return self._targets[id(bus)]
        for target in self._targets.values():
            if target.bus.description == bus:
                return target
        raise KeyError(bus)

    # -- running -------------------------------------------------------------------

    async def __aenter__(self) -> Poller:
        if self._stack is not None:
            raise RuntimeError("the poller is already running")
        stack = contextlib.AsyncExitStack()
        # The task group lives in an exit stack rather than around the caller's
        # body, so an exception from the body is not wrapped in an ExceptionGroup.
        self._task_group = await stack.enter_async_context(anyio.create_task_group())
        self._stack = stack
        for target in self._targets.values():
            self._task_group.start_soon(self._poll_bus, target)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        stack, self._stack = self._stack, None
        task_group, self._task_group = self._task_group, None
        if task_group is not None:
            task_group.cancel_scope.cancel()
        try:
            if stack is not None:
                await stack.aclose()
        finally:
            # Last: a polling task publishes what it has polled as it ends
            # (see _poll_bus), and no sample may follow the end.
            for queue in self._queues:
                _put_dropping(queue, _END)

    async def samples(self) -> AsyncGenerator[Sample, None]:
        """Yield samples as they are polled, until the poller stops."""
        queue: asyncio.Queue[object] = asyncio.Queue(self.buffer)
        self._queues.append(queue)
        try:
            while True:
                item = await queue.get()
                if item is _END:
                    return
                assert isinstance(item, Sample)
                yield item
        finally:
            self._queues.remove(queue)

    # -- polling -------------------------------------------------------------------

    async def _poll_bus(self, target: _Target) -> None:
        # The loop's clock, read directly: it is what anyio.current_time()
        # returns on asyncio (the only backend the buses run on), without
        # the backend lookup on each of the several reads per poll.
        loop = asyncio.get_running_loop()
        clock = loop.time
        # This task's reads make at most 1 + self.retries attempts: set once for
        # the task's life, not in a block per drive poll that every poll pays for.
        cap_retries(self.retries)
        reads = self.reads + target.parameters
        # A poll's sample is published once the next drive's first request is on
        # the line, from a loop callback, not between the reply and the next
        # request: on a line polled back to back, that is the one stretch where
        # the host's work costs line time (the wire benchmark's notes measure
        # that turnaround).
        # The callback is scheduled in this task's step, so the loop runs it
        # before this task can resume, whatever resumes it (a reply, an error,
        # a cancellation): a stopped poller has published every poll it
        # finished before ``__aexit__`` ends the iterators. The cycle's last
        # sample goes out at the cycle's end, before the statistics count it.
        # With callback_errors="raise" samples go out at once, so that a failing
        # callback stops the poller before its next request.
        defer = self.callback_errors == "log"
        while True:
            start = clock()
            for node in list(target.nodes):
                if target.holds:
                    await target.resumed.wait()
                health = target.health.get(node)
                if health is None or not health.online:
                    continue  # offline drives: probed below
                poll, _ = await self._poll_drive(target, node, health, reads, clock)
                if not defer:
                    self._publish(target, poll)
                    continue
                target.unpublished.append(poll)
                if len(target.unpublished) == 1:  # else one is on its way
                    loop.call_soon(self._publish_polled, target)
            self._publish_polled(target)
            # Offline drives due for a probe, longest-waiting first: at most one
            # unanswered probe per cycle (an answered one lets the next go).
            now = clock()
            due = sorted(
                (h.next_probe, node)
                for node, h in target.health.items()
                if not h.online and now >= h.next_probe and node in target.nodes
            )
            for _, node in due:
                if target.holds:
                    await target.resumed.wait()
                health = target.health[node]
                poll, answered = await self._poll_drive(target, node, health, reads, clock)
                self._publish(target, poll)
                if not answered:
                    break
            elapsed = clock() - start
            stats = target.stats
            stats.cycles += 1
            stats.last_cycle_s = elapsed
            stats.total_cycle_s += elapsed
            stats.max_cycle_s = max(stats.max_cycle_s, elapsed)
            # Never spin: even an overrun cycle yields to other tasks.
            await anyio.sleep(max(0.0, self.interval_s - elapsed))

    async def _poll_drive(
        self,
        target: _Target,
        node: int,
        health: DriveHealth,
        reads: tuple[str, ...],
        clock: Callable[[], float],
    ) -> tuple[_Poll, bool]:
        """Poll one drive (probing it first if its last poll failed); (poll, answered).

        The drive's health is up to date on return; the poll is not published.
        """
        drive = target.drives[node]
        started = clock()
        status: InverterStatus | Fr700Status | None = None
        monitor: MonitorData | Fr700Monitor | None = None
        parameters: dict[str, float] = {}
        unavailable = _NONE_UNAVAILABLE
        error: str | None = None
        spent = 0.0
        ok_reads = 0
        answered = True
        if health.consecutive_failures:  # failing or offline: one cheap attempt first
            error = await self._probe(target, node, health, drive)
            answered = error is None
        if error is None:  # (retries capped for this task in _poll_bus)
            for read in reads:
                begin = clock()
                try:
                    if read == "status":
                        status = await drive.read_status()
                    elif read == "monitor":
                        monitor = await drive.read_monitor()
                    else:
                        parameters[read] = await drive.read_parameter(read)
                except NakError as exc:
                    health.answered = True  # a refusal: the drive is there
                    if read in _READS:
                        error = f"{type(exc).__name__}: {exc}"
                        break
                    # A parameter it will not give: unavailable, and on to the next read.
                    unavailable = unavailable | {read}
                    continue
                except SJ300Error as exc:
                    error = f"{type(exc).__name__}: {exc}"
                    break  # a failing drive gets no more of the line this cycle
                spent += clock() - begin
                ok_reads += 1
                health.answered = True
            if health.unavailable or unavailable:
                self._note_unavailable(target, node, health, unavailable, parameters)
        now = clock()
        self._update_health(target, node, health, error, now)
        latency_s = spent / ok_reads if ok_reads else None
        poll = (node, now, health.online, status, monitor, parameters, error, latency_s,
                health.answered, started, unavailable)  # fmt: skip
        return poll, answered

    @staticmethod
    def _note_unavailable(
        target: _Target,
        node: int,
        health: DriveHealth,
        refused: frozenset[str],
        read: Mapping[str, float],
    ) -> None:
        """Log each parameter the drive newly refuses, once, and each that reads again."""
        bus = target.bus.description
        for code in sorted(refused - health.unavailable):
            _log.warning(
                "%s node %02d: parameter %s unavailable (the drive refuses to read it); "
                "the drive stays online",
                bus, node, code,
            )  # fmt: skip
        back = {code for code in health.unavailable if code in read}
        for code in sorted(back):
            _log.info("%s node %02d: parameter %s reads again", bus, node, code)
        health.unavailable = (health.unavailable - back) | refused

    async def _probe(
        self, target: _Target, node: int, health: DriveHealth, drive: Any
    ) -> str | None:
        """One attempt of the protocol's cheap read-only request; the error, None if answered."""
        bus = target.bus
        if not health.online:
            target.stats.probes += 1
        request = bus.dialect.sync_request(node, ())
        wait_s = getattr(drive, "wait_time_s", 0.0)
        try:
            if request is None:  # the protocol has no request of its own shape: a status read
                with retries_at_most(0):
                    await drive.read_status()
            else:
                await bus.channel.transact(
                    request,
                    target.probe_stats,
                    wait_s=wait_s if isinstance(wait_s, float | int) else 0.0,
                    retries=0,
                )
        except NakError:
            health.answered = True  # a refusal: the drive is there
        except SJ300Error as exc:
            return f"{type(exc).__name__}: {exc}"
        return None

    def _update_health(
        self, target: _Target, node: int, health: DriveHealth, error: str | None, now: float
    ) -> None:
        health.polls += 1
        if error is None:
            if not health.online:
                _log.info("%s node %02d back online", target.bus.description, node)
            health.online = True
            health.consecutive_failures = 0
            health.last_ok = now
            return
        health.failures += 1
        health.consecutive_failures += 1
        health.last_error = error
        target.stats.errors += 1
        if health.online and health.consecutive_failures >= self.offline_after:
            health.online = False
            _log.warning("%s node %02d offline: %s", target.bus.description, node, error)
        if not health.online:
            health.next_probe = now + self.offline_probe_interval_s

    def _publish_polled(self, target: _Target) -> None:
        """Publish the polls *target*'s task has done and not published yet, in order."""
        unpublished = target.unpublished
        while unpublished:
            self._publish(target, unpublished.pop(0))

    def _publish(self, target: _Target, poll: _Poll) -> None:
        (node, now, online, status, monitor, parameters, error, latency_s, answered, started,
         unavailable) = poll  # fmt: skip
        sample = Sample(
            bus=target.bus.description,
            node=node,
            timestamp=now,
            online=online,
            status=status,
            monitor=monitor,
            parameters=parameters,
            error=error,
            latency_s=latency_s,
            answered=answered,
            started=started,
            unavailable=unavailable,
        )
        for callback in list(self._callbacks):
            try:
                callback(sample)
            except Exception:
                if self.callback_errors == "raise":
                    raise
                target.stats.callback_errors += 1
                _log.exception(
                    "%s node %02d: on_sample callback %r raised; polling goes on",
                    sample.bus,
                    sample.node,
                    callback,
                )
        for queue in self._queues:
            if _put_dropping(queue, sample):
                self.dropped_samples += 1


def _parameter_name(code: str) -> str:
    """The code as its protocol names it (``"f002"`` -> ``"F002"``, ``"pr7"`` -> ``"Pr.7"``).

    Raises:
        LocalProtocolError: no registered protocol has such a parameter.
    """
    for name in protocol_names():
        own = get_dialect(name).parameter_code(code)
        if own is not None:
            return own
    raise LocalProtocolError(f"{code!r} is not a parameter code of any protocol")


def _put_dropping(queue: asyncio.Queue[object], item: object) -> bool:
    """Put *item*, dropping the oldest entry when full; True if one was dropped."""
    dropped = False
    if queue.full():
        queue.get_nowait()
        dropped = True
    queue.put_nowait(item)
    return dropped
