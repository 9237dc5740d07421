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
"""

from __future__ import annotations

import asyncio
import selectors

__all__ = ["precise_event_loop"]


def precise_event_loop() -> asyncio.AbstractEventLoop:
    """A new asyncio event loop whose timers fire within microseconds of their time.

    Use it as ``asyncio.Runner(loop_factory=precise_event_loop)`` for a process
    that serves a paced line (``sj300 simulate --pace`` does).
    """
    return asyncio.SelectorEventLoop(selectors.SelectSelector())
