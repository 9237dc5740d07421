"""In-memory loopback: transactions/s through the whole stack, no socket, no wire time.

``open_bus("sim://?nodes=1-8", simulator=...)``: Drive API, arbiter, protocol
adapter, loopback transport and the simulated drives, all in this process
on one event loop. The drives answer without the simulator's emulated 1 ms
processing time (``processing_s=0``), so the measurement is the software's.

Two loads: one task doing sequential ``read_status()`` calls on one drive,
and 8 tasks doing the same on 8 drives at once (the arbiter serializes them
on the one half-duplex line, as it must). The target, 50,000 transactions/s,
is an absolute number; an extra row shows the rate with the simulator's own
share taken out (see :mod:`benchmarks._sim`).
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass

from sj300_async import Bus, Drive, open_bus
from sj300_async.sj300 import requests

from ._floor import memory_round_trips
from ._harness import Config, Result, Section, best_time, interleave, new_runner
from ._sim import instant_simulator, simulator_cost

__all__ = [
    "TARGET_TPS",
    "TASKS",
    "TITLE",
    "TRANSACTIONS",
    "USES_EVENT_LOOP",
    "Rates",
    "measure",
    "run",
]

TITLE = "loopback"
USES_EVENT_LOOP = True
#: Transactions per timed run, full and ``--quick``.
TRANSACTIONS = 10_000
QUICK_TRANSACTIONS = 200
#: Concurrent tasks (one drive each) of the second load.
TASKS = 8
#: The project's aim, transactions/s through the whole stack.
TARGET_TPS = 50_000.0


async def _sequential(drive: Drive, n: int) -> None:
    for _ in range(n):
        await drive.read_status()


async def _concurrent(bus: Bus, n: int) -> None:
    async def worker(drive: Drive, count: int) -> None:
        for _ in range(count):
            await drive.read_status()

    per_task = n // TASKS
    async with asyncio.TaskGroup() as group:
        for node in range(1, TASKS + 1):
            group.create_task(worker(bus.drive(node), per_task))


@dataclass(frozen=True, slots=True)
class Rates:
    """What :func:`measure` found."""

    #: Transactions per timed run (the run with :data:`TASKS` tasks does as many).
    transactions: int
    #: Best wall time of a run: one task, and :data:`TASKS` tasks.
    one_task_s: float
    tasks_s: float
    #: Seconds the simulator's sans-IO core takes per status request.
    sim_s: float
    #: Replies the bus counted over every run, warm-ups included.
    replies: int
    #: Best wall time of as many in-memory floor transactions (interleaved with one task).
    floor_s: float = 0.0

    @property
    def one_task_tps(self) -> float:
        """Transactions/s, one task."""
        return self.transactions / self.one_task_s

    @property
    def tasks_tps(self) -> float:
        """Transactions/s, :data:`TASKS` tasks."""
        return self.transactions / self.tasks_s

    @property
    def floor_tps(self) -> float:
        """Transactions/s of the in-memory asyncio floor (a future per transaction)."""
        return self.transactions / self.floor_s

    @property
    def stack_only_tps(self) -> float:
        """Transactions/s of one task if the simulator's core took no time."""
        return self.transactions / (self.one_task_s - self.sim_s * self.transactions)


def measure(config: Config) -> Rates:
    """Time both loads on one bus; return the rates.

    Raises:
        RuntimeError: the bus did not count one reply per transaction.
    """
    n = QUICK_TRANSACTIONS if config.quick else TRANSACTIONS
    n -= n % TASKS
    nodes = range(1, TASKS + 1)
    with new_runner(config.loop) as runner:
        stack = contextlib.AsyncExitStack()
        try:
            opened = open_bus("sim://?nodes=1-8", simulator=instant_simulator(nodes))
            bus = runner.run(stack.enter_async_context(opened))
            drive = bus.drive(1)
            one_timing, floor_timing = interleave(
                [
                    lambda: runner.run(_sequential(drive, n)),
                    lambda: runner.run(memory_round_trips(n)),
                ],
                config.repeats,
            )
            one, floor = one_timing.best_wall_s, floor_timing.best_wall_s
            many = best_time(lambda: runner.run(_concurrent(bus, n)), config.repeats)
            replies = bus.stats.transactions.replies
        finally:
            runner.run(stack.aclose())
    expected = 2 * n * (config.repeats + 1)
    if replies != expected:
        raise RuntimeError(f"the bus counted {replies} replies, expected {expected}")
    rounds = 5 if config.quick else 50
    sim_s = simulator_cost([requests.read_status(node) for node in nodes], rounds * 25)
    return Rates(n, one, many, sim_s, replies, floor)


def run(config: Config) -> Section:
    """Measure transactions/s on the in-memory loopback."""
    rates = measure(config)
    notes = (
        f"{rates.transactions:,} `read_status()` transactions per timed run on "
        "`open_bus('sim://?nodes=1-8', simulator=SimulatedBus(nodes=1..8, processing_s=0))`; "
        f"one task on drive 1, then {TASKS} tasks on drives 1..{TASKS} "
        f"({rates.transactions // TASKS:,} each). The simulator runs in this process: its "
        f"sans-IO core alone takes {rates.sim_s * 1e6:.1f} µs per status request "
        f"({rates.sim_s * rates.one_task_tps:.0%} of the one-task run), "
        "taken out in the third row.",
        "",
        f"The same run's in-memory asyncio floor (a future per transaction answered on the "
        f"loop's next turn, no protocol, interleaved with the one-task runs): "
        f"{rates.floor_tps:,.0f} transactions/s; one task reaches "
        f"{rates.one_task_tps / rates.floor_tps:.2f} of it.",
    )
    results = (
        Result(
            "loopback: read_status, 1 task",
            rates.one_task_tps,
            TARGET_TPS,
            "transactions/s",
            1.0,
            against="target",
        ),
        Result(
            f"loopback: read_status, {TASKS} tasks on {TASKS} drives",
            rates.tasks_tps,
            TARGET_TPS,
            "transactions/s",
            1.0,
            against="target",
        ),
        Result(
            "loopback: read_status, 1 task, simulator's share taken out",
            rates.stack_only_tps,
            TARGET_TPS,
            "transactions/s",
            against="target",
        ),
        Result(
            "loopback: read_status, 1 task vs in-memory asyncio floor, same run",
            rates.one_task_tps,
            rates.floor_tps,
            "transactions/s",
            against="in-memory floor",
            percent=True,
        ),
    )
    return Section(TITLE, notes, results)
