"""An event loop whose timers keep sub-millisecond time, for serving a paced line.

A paced simulated line hands each reply over when its last character has
crossed the wire; its timers *are* the wire. asyncio's default loop on Linux
waits in ``epoll_wait``, whose time-out is whole milliseconds (CPython rounds
up), so a timer due in 0.3 ms fires after 1 ms: at 19200 baud, where a
character takes 0.52 ms, every reply would reach the host up to two
characters late, and a host measured against the wire would be blamed for
the emulation's rounding. ``select()`` takes its time-out in microseconds.

The simulator's servers watch a handful of descriptors (a listener, a few
clients, a pty), far below ``select()``'s limit of 1024, so the select-based
selector costs nothing there. The library itself never needs this: a host
waits for bytes (which wake any loop at once), not for sub-millisecond timers.

Even a precise time-out is a sleep, and waking a sleeping process costs time
(the wire benchmark's notes show how late the line's deliveries come). With
``spin=True`` the loop never sleeps: it polls its descriptors until
something is ready or the next timer is due. That keeps a CPU busy, so it
is for a simulator standing in for hardware that never sleeps either (a
UART, a drive's controller) while a benchmark measures the host on the
other end, not for everyday serving.
"""

from __future__ import annotations

import asyncio
import selectors
import time

__all__ = ["precise_event_loop"]


class _SpinningSelector(selectors.SelectSelector):
    """A select() selector that polls instead of sleeping (see the module docstring)."""

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout is not None and timeout <= 0:
            return super().select(0)
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            ready = super().select(0)
            if ready or (end is not None and time.monotonic() >= end):
                return ready


def precise_event_loop(*, spin: bool = False) -> asyncio.AbstractEventLoop:
    """A new asyncio event loop whose timers fire within microseconds of their time.

    Use it as ``asyncio.Runner(loop_factory=precise_event_loop)`` for a process
    that serves a paced line (``sj300 simulate --pace`` does).

    Args:
        spin: never sleep; poll until a descriptor is ready or a timer is due
            (keeps one CPU busy; see the module docstring).
    """
    selector = _SpinningSelector() if spin else selectors.SelectSelector()
    return asyncio.SelectorEventLoop(selector)
