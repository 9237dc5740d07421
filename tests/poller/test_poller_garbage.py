"""A steady poll leaves the cyclic collector nothing to free.

Garbage in a reference cycle is freed only when the collector runs, and a
collection's cost grows with everything the process holds: in a gateway
with every northbound (about 9,600 objects per drive for OPC UA alone), the
simulator's timers once made 8 such objects per job, two jobs per sample,
and the collections they triggered cost more CPU than some northbounds.
Reference counting alone must free what a poll cycle makes, on the paced
simulated line (timers per delivery) and on the poller's side.
"""

from __future__ import annotations

import asyncio
import collections
import gc
from collections.abc import Iterator
from contextlib import contextmanager

from virtual_clock import run_on_virtual_clock

import sj300_async as sj

CYCLES = 40


@contextmanager
def _garbage_kept() -> Iterator[list[object]]:
    """Inside: what the cyclic collector would free is kept in the list instead."""
    gc.collect()
    gc.garbage.clear()
    gc.set_debug(gc.DEBUG_SAVEALL)
    found: list[object] = []
    try:
        yield found
        gc.collect()
        found.extend(gc.garbage)
    finally:
        gc.set_debug(0)
        gc.garbage.clear()


def test_a_steady_poll_makes_no_cyclic_garbage() -> None:
    warm, watched = run_on_virtual_clock(_poll_twice())
    assert warm >= CYCLES * 4
    assert watched >= CYCLES * 4


async def _poll_twice() -> tuple[int, int]:
    """Warm up (first reads, caches), then poll again under watch: both counts."""
    async with sj.open_bus("sim://?nodes=1-4&pace=1&baudrate=19200") as bus:
        poller = sj.Poller(interval_s=0.2)
        poller.add(bus, range(1, 5))
        counted = _Counter()
        poller.on_sample(counted)
        async with poller:
            warm = await counted.more(CYCLES * 4)
            with _garbage_kept() as garbage:
                watched = await counted.more(CYCLES * 4)
        kinds = collections.Counter(type(o).__qualname__ for o in garbage)
        assert not garbage, kinds.most_common(8)
        return warm, watched


class _Counter:
    """Counts good samples; :meth:`more` waits for *n* more of them."""

    def __init__(self) -> None:
        self.count = 0
        self._target = 0
        self._reached = asyncio.Event()

    def __call__(self, sample: sj.Sample) -> None:
        if sample.error is None:
            self.count += 1
            if self.count >= self._target:
                self._reached.set()

    async def more(self, n: int) -> int:
        start = self.count
        self._target = start + n
        self._reached.clear()
        await self._reached.wait()
        return self.count - start
