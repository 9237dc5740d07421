"""Latency: the library's own time per transaction on the in-memory loopback, p50 and p99.

Each of N sequential ``read_status()`` calls on
``open_bus("sim://?nodes=1", simulator=SimulatedBus(nodes=[1], processing_s=0))``
is timed from the call to the decoded :class:`~sj300_async.InverterStatus`.
That round trip holds the whole stack and the simulated drive, with no wire
time and no emulated processing time. The simulator's share is timed apart
(its sans-IO core, :meth:`SimulatedBus.receive`, on the same request; see
:mod:`benchmarks._sim`) and subtracted from each percentile: it barely
varies from one request to the next, so the tail belongs to the library and
the event loop (and the garbage collector, which stays on).
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass

from sj300_async import Drive, open_bus
from sj300_async.sj300 import requests

from ._floor import memory_round_trips
from ._harness import Config, Result, Section, new_runner
from ._sim import instant_simulator, simulator_cost

__all__ = ["TITLE", "TRANSACTIONS", "USES_EVENT_LOOP", "Latencies", "measure", "run"]

TITLE = "latency"
USES_EVENT_LOOP = True
#: Timed transactions, full and ``--quick``; each run starts with WARM_UP untimed ones.
TRANSACTIONS = 20_000
QUICK_TRANSACTIONS = 300
WARM_UP = 1_000
QUICK_WARM_UP = 20


@dataclass(frozen=True, slots=True)
class Latencies:
    """Round-trip times in seconds, sorted, and the simulator's share of each."""

    round_trips_s: tuple[float, ...]
    sim_s: float
    #: The in-memory asyncio floor's transactions timed the same way, sorted.
    floor_s: tuple[float, ...] = ()

    def percentile(self, p: float) -> float:
        """The *p*-th percentile (0..100) of the round trips, nearest rank."""
        values = self.round_trips_s
        rank = min(len(values), max(1, math.ceil(p / 100 * len(values))))
        return values[rank - 1]

    def floor(self, p: float) -> float:
        """The *p*-th percentile of the in-memory floor's transactions."""
        values = self.floor_s
        rank = min(len(values), max(1, math.ceil(p / 100 * len(values))))
        return values[rank - 1]

    def overhead(self, p: float) -> float:
        """The *p*-th percentile with the simulator's share taken out."""
        return self.percentile(p) - self.sim_s


async def _time_each(drive: Drive, n: int, warm_up: int) -> list[float]:
    for _ in range(warm_up):
        await drive.read_status()
    times: list[float] = []
    append = times.append
    clock = time.perf_counter
    for _ in range(n):
        start = clock()
        await drive.read_status()
        append(clock() - start)
    return times


async def _time_floor(n: int, warm_up: int) -> list[float]:
    """The in-memory floor (:func:`~._floor.memory_round_trips`), each transaction timed."""
    await memory_round_trips(warm_up)
    times: list[float] = []
    append = times.append
    clock = time.perf_counter
    for _ in range(n):
        start = clock()
        await memory_round_trips(1)
        append(clock() - start)
    return times


def measure(config: Config) -> Latencies:
    """Time every transaction; return the sorted round trips and the simulator's share.

    Raises:
        RuntimeError: the bus did not count one reply per transaction.
    """
    n, warm_up = (QUICK_TRANSACTIONS, QUICK_WARM_UP) if config.quick else (TRANSACTIONS, WARM_UP)
    with new_runner(config.loop) as runner:
        stack = contextlib.AsyncExitStack()
        try:
            opened = open_bus("sim://?nodes=1", simulator=instant_simulator([1]))
            bus = runner.run(stack.enter_async_context(opened))
            times = runner.run(_time_each(bus.drive(1), n, warm_up))
            floor = runner.run(_time_floor(n, warm_up))
            replies = bus.stats.transactions.replies
        finally:
            runner.run(stack.aclose())
    if replies != n + warm_up:
        raise RuntimeError(f"the bus counted {replies} replies, expected {n + warm_up}")
    rounds = 20 if config.quick else 200
    sim_s = simulator_cost([requests.read_status(1)] * 50, rounds)
    return Latencies(tuple(sorted(times)), sim_s, tuple(sorted(floor)))


def run(config: Config) -> Section:
    """Measure the distribution of the library's time per transaction."""
    lat = measure(config)
    us = 1e6
    notes = (
        f"{len(lat.round_trips_s):,} sequential `read_status()` calls on the in-memory loopback "
        "(`sim://`, the drive's `processing_s=0`), each timed from call to decoded status. "
        f"Round trip: p50 {lat.percentile(50) * us:.1f} µs, p90 {lat.percentile(90) * us:.1f}, "
        f"p99 {lat.percentile(99) * us:.1f}, p99.9 {lat.percentile(99.9) * us:.1f}, "
        f"max {lat.round_trips_s[-1] * us:.0f} µs. "
        f"The simulator's sans-IO core takes {lat.sim_s * us:.1f} µs of each (timed apart) "
        "and is subtracted; the simulator's scheduling of the reply on the event loop "
        "is not, so the overhead is, if anything, overstated.",
        "",
        "The same run's in-memory asyncio floor (a future per transaction answered on the "
        "loop's next turn), timed the same way right after: "
        f"p50 {lat.floor(50) * us:.2f} µs, p99 {lat.floor(99) * us:.2f} µs.",
    )
    results = (
        *(
            Result(
                f"latency: library overhead per transaction, p{p}", lat.overhead(p) * us, None, "µs"
            )
            for p in (50, 99)
        ),
        Result(
            "latency: library overhead per transaction, p50 vs in-memory asyncio floor, same run",
            lat.overhead(50) * us,
            lat.floor(50) * us,
            "µs",
            higher_is_better=False,
            against="in-memory floor",
            as_multiple=True,
        ),
    )
    return Section(TITLE, notes, results)
