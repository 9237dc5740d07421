"""Host pauses, for tests that judge by time: kept out (the collector) or measured (the loop).

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
from collections.abc import Iterator

__all__ = ["LoopStalls", "no_collector_pauses"]


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
