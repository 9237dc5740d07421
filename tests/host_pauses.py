"""Host pauses, for tests that judge by time: kept out (the collector) or measured (the loop).

:class:`LoopStalls` measures when the loop could not run, whatever the cause;
:class:`LoopLag` measures how long the loop's *own* work held it, the bound the
attack tests (issue 41) judge the gateway by.

Keep the cyclic garbage collector's pauses out of a run that judges frames by their timing.

The bus's plausibility floor judges a frame by when the host *read* it. A
host paused for longer than the margin between a duplicated reply and the
floor (a generation-2 collection in a pytest process of 3,000 tests takes
tens of milliseconds) reads the copy as late as the answer itself, and no
host can tell them apart: docs/RELIABILITY.md lists it among what stays
undetectable. The duplicate runs test the bus under the adversary's line,
not that limit, so they run with the collector frozen and off (objects made
during the run are collected once it ends).
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import threading
import time
from collections.abc import Iterator
from types import TracebackType

__all__ = ["LoopLag", "LoopStalls", "no_collector_pauses"]


@contextlib.contextmanager
def no_collector_pauses() -> Iterator[None]:
    """Collect now, then keep the cyclic collector off until the block ends."""
    was_enabled = gc.isenabled()
    gc.collect()
    gc.freeze()  # what exists now is never scanned again during the block
    gc.disable()
    try:
        yield
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()


class LoopStalls:
    """When this process's event loop could not run, so a timing bound can leave it out.

    A callback every *period_s* records how late it ran: a tick *late* seconds
    late at *t* means nothing on the loop ran in ``[t - late, t]`` (a
    collection, the scheduler giving both cores to the suite's other worker).
    :meth:`within` is how much of a span such stalls covered: a call that took
    too long *only* by that much was the host's pause, not the library's
    wait. A library that waited on something that never came leaves the
    ticks on time, so the bound still fails it.
    """

    def __init__(self, period_s: float = 0.005) -> None:
        self._period = period_s
        self._loop = asyncio.get_running_loop()
        #: (start, end) of every stall longer than a millisecond, in loop time.
        self.stalls: list[tuple[float, float]] = []
        self._due = self._loop.time() + period_s
        self._handle = self._loop.call_at(self._due, self._tick)

    def _tick(self) -> None:
        now = self._loop.time()
        if now - self._due > 0.001:
            self.stalls.append((self._due, now))
        self._due = now + self._period
        self._handle = self._loop.call_at(self._due, self._tick)

    def within(self, start: float, end: float) -> float:
        """Seconds of ``[start, end]`` (loop time) during which the loop was stalled."""
        return sum(max(0.0, min(end, b) - max(start, a)) for a, b in self.stalls)

    def close(self) -> None:
        self._handle.cancel()


class LoopLag:
    """How long the loop was held by this thread's own work: a callback every *period_s*.

    The gateway, an attack's client side and the test share this process's loop,
    and the suite's other worker shares the machine's two cores. A tick late while
    this thread did not run (the scheduler gave its core to another process) is the
    machine's load, not the loop held: clean runs saw ticks 265 ms and 750 ms late
    so. Each tick's lateness therefore counts up to the processor time this thread
    spent since the last tick, which is at least any stall the loop's own work made
    (a password check run on the loop is processor time of this thread). The
    lateness on the clock is kept beside it, and the cyclic collector's time on
    this thread (:attr:`collecting_s`), so that a failure says which it was.
    """

    def __init__(self, period_s: float = 0.01) -> None:
        self._period = period_s
        self._loop = asyncio.get_running_loop()
        self._thread = threading.get_ident()
        #: Each tick's lateness, bounded by this thread's processor time.
        self.late: list[float] = []
        #: Each tick's lateness on the clock.
        self.late_on_the_clock: list[float] = []
        #: Seconds this thread spent in the cyclic collector, and its longest collection.
        self.collecting_s = 0.0
        self.longest_collection_s = 0.0
        self._collection_started: float | None = None
        gc.callbacks.append(self._on_collection)
        self._due = self._loop.time() + period_s
        self._cpu = time.thread_time()
        self._handle: asyncio.TimerHandle | None = self._loop.call_at(self._due, self._tick)

    def _tick(self) -> None:
        now, cpu = self._loop.time(), time.thread_time()
        late = now - self._due
        self.late_on_the_clock.append(late)
        self.late.append(min(late, cpu - self._cpu))
        self._due, self._cpu = now + self._period, cpu
        self._handle = self._loop.call_at(self._due, self._tick)

    def _on_collection(self, phase: str, info: dict[str, int]) -> None:
        if threading.get_ident() != self._thread:
            return
        if phase == "start":
            self._collection_started = time.perf_counter()
        elif self._collection_started is not None:
            took = time.perf_counter() - self._collection_started
            self.collecting_s += took
            self.longest_collection_s = max(self.longest_collection_s, took)
            self._collection_started = None

    def _stop(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
            gc.callbacks.remove(self._on_collection)

    def close(self) -> float:
        """Stop probing (again is harmless); the greatest lateness the loop's own work
        made, checked to have been measured."""
        self._stop()
        assert self.late, "the probe never ran"
        return max(self.late)

    def describe(self) -> str:
        """The figures, for a failure's message or the run's output."""
        return (
            f"loop held {max(self.late, default=0.0) * 1000:.1f} ms at most "
            f"(on the clock {max(self.late_on_the_clock, default=0.0) * 1000:.1f} ms; "
            f"{len(self.late)} ticks; collector {self.collecting_s * 1000:.1f} ms, "
            f"longest {self.longest_collection_s * 1000:.1f} ms)"
        )

    def __enter__(self) -> LoopLag:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop()
