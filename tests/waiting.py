"""Waiting for a state instead of sleeping for a guessed time.

``await wait_for(lambda: poller.bus_stats(bus).cycles >= 2, "two cycles")``
returns as soon as the condition holds and fails the test with a clear
message when it still does not hold at the deadline. It checks the
condition first on the next loop turns (``asyncio.sleep(0)``), then every
``interval`` seconds, so work scheduled by call_soon is seen at once and a
slow state does not spin the CPU.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable

__all__ = ["process_gone", "wait_for"]


def process_gone(pid: int) -> bool:
    """No process *pid* is left (ended and reaped): the state a killed child must reach."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


async def wait_for(
    condition: Callable[[], object],
    what: str = "the condition",
    *,
    timeout: float = 5.0,
    interval: float = 0.001,
) -> None:
    """Return once ``condition()`` is true; fail with *what* after *timeout* seconds."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    for _ in range(10):  # a few loop turns first: call_soon work lands here
        if condition():
            return
        await asyncio.sleep(0)
    while not condition():
        if loop.time() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(interval)
