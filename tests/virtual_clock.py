"""An event loop on a virtual clock, for tests that measure line time, not the machine.

The loop's clock stands still while callbacks run and, when nothing is ready,
jumps to the next timer instead of sleeping. Everything the stack times (the
simulator's paced wire, response time-outs, drains, the poller's cycle) reads
``loop.time()``, so a scenario on an in-memory line runs the same way on an
idle laptop and on a loaded CI machine: what it measures is the policy (how
much line time each drive gets), with the host's own CPU time taken as zero.

A test that needs the host's CPU in the figure belongs in ``benchmarks/``;
this clock is for tests whose assertion is about the schedule.

A descriptor that becomes ready still wakes the loop (the selector is polled
before the clock moves), and with no timer due the loop waits on its
descriptors for real, so a test that mixes in real I/O still runs; its
timings are then meaningless, so don't.
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Coroutine
from typing import Any, TypeVar

__all__ = ["run_on_virtual_clock"]

_T = TypeVar("_T")


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0


class _JumpingSelector(selectors.SelectSelector):
    """Answers what is ready now; otherwise moves the clock by the time-out."""

    def __init__(self, clock: _Clock) -> None:
        super().__init__()
        self._clock = clock

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        ready = super().select(0)
        if ready or (timeout is not None and timeout <= 0):
            return ready
        if timeout is None:  # no timer at all: only a descriptor can wake the loop
            return super().select(None)
        self._clock.now += timeout
        return []


class _VirtualLoop(asyncio.SelectorEventLoop):
    def __init__(self) -> None:
        self._virtual = _Clock()
        super().__init__(_JumpingSelector(self._virtual))

    def time(self) -> float:
        return self._virtual.now


def run_on_virtual_clock(coroutine: Coroutine[Any, Any, _T]) -> _T:
    """Run *coroutine* to completion on a fresh event loop with a virtual clock."""
    with asyncio.Runner(loop_factory=_VirtualLoop) as runner:
        return runner.run(coroutine)
