"""Cancellation storm: tasks cancelled at random moments, on a line paced at 38400 bps.

Each round starts a request to each of several drives from its own task,
lets a random time pass (from a few event-loop steps to a whole
transaction), and cancels a random subset. Pacing makes every moment of a
transaction last long enough to be hit: queued, while the request is still
crossing the line (mid-write), while the drive thinks, while the reply is
arriving (mid-reply). Every cancellation must end its task cancelled (never
swallowed or wrapped), every other task must get the right value or a typed
error, and afterwards every drive answers correctly and no task, timer or
file descriptor is left behind.
"""

from __future__ import annotations

import asyncio
import random
import time
from collections import Counter
from typing import Any

import pytest

import sj300_async as sj
from sj300_async import bus as sjbus
from sj300_async import sj300 as sj3

from .rel_leaks import Baseline, ErrorLog, bus_idle, peak_rss_mib
from .rel_oracle import KEYS, Oracle, value_for
from .rel_sizes import Sizes

pytestmark = pytest.mark.soak

NODES = tuple(range(1, 9))
BAUD = 38400
URL = f"sim://?nodes=1-8&pace=1&baudrate={BAUD}"
CHAR_S = 10 / BAUD

# Where a victim was when it was cancelled.
BEFORE_WRITE = "before the write (queued, draining or resting)"
MID_WRITE = "mid-write (request still on the line)"
AWAITING = "awaiting the reply"
MID_REPLY = "mid-reply (part of the reply received)"
ON_THE_LINE = (MID_WRITE, AWAITING, MID_REPLY)


class Storm:
    def __init__(self, bus: sj.Bus[sj.Drive, sj.Broadcast], seed: int) -> None:
        self.bus = bus
        self.rng = random.Random(seed)
        self.oracle = Oracle()
        self.serial = 0
        self.last_tx: tuple[float, int] = (0.0, 0)
        self.phases: Counter[str] = Counter()
        self.outcomes: Counter[str] = Counter()
        self.untyped: list[str] = []
        self.swallowed: list[str] = []
        self.too_late = 0
        self.cancellations = 0

    def trace(self, record: sjbus.TraceRecord) -> None:
        if record.direction == "tx":
            self.last_tx = (record.timestamp, len(record.data))

    async def seed_values(self) -> None:
        for node in NODES:
            for code in KEYS:
                raw = value_for(code, node, 0)
                await self.bus.drive(node).write_parameter_raw(code, raw)
                self.oracle.settle(node, code, raw)

    async def request(self, node: int) -> None:
        """One random Drive call to *node*, checked against the oracle."""
        rng = self.rng
        drive = self.bus.drive(node)
        pick = rng.random()
        if pick < 0.3:
            code = rng.choice(KEYS)
            self.oracle.read(node, code, await drive.read_parameter_raw(code))
        elif pick < 0.5:
            code = rng.choice(KEYS)
            self.serial += 1
            raw = value_for(code, node, self.serial)
            try:
                await drive.write_parameter_raw(code, raw)
            except BaseException:  # a typed error or the cancellation: it may have happened
                self.oracle.write_failed(node, code, raw)
                raise
            self.oracle.wrote(node, code, raw)
        elif pick < 0.6:
            self.oracle.check_constant("C072", await drive.read_parameter_raw("C072"), node)
        elif pick < 0.65:
            status = await drive.read_status()
            self.oracle.check_constant("status known", status.a.known and status.c.known, True)
        elif pick < 0.92:
            monitor = await drive.read_monitor()
            self.oracle.check_constant("direction known", monitor.direction.known, True)
        elif pick < 0.98:
            await (drive.run_forward() if rng.random() < 0.5 else drive.stop())
        else:
            await drive.read_trip_history()

    def phase(self, node: int) -> str:
        out = self.bus._arbiter._outstanding
        if out is None or out.request.node != node:
            return BEFORE_WRITE
        sent_at, length = self.last_tx
        if asyncio.get_running_loop().time() < sent_at + length * CHAR_S:
            return MID_WRITE
        parser = self.bus._parser
        assert isinstance(parser, sj3.ReplyParser)  # the SJ300 dialect's
        if parser.buffered > 0:
            return MID_REPLY
        return AWAITING

    def choose_victims(self, nodes: list[int]) -> list[int]:
        """A random subset; more often than chance, the request on the line is in it."""
        rng = self.rng
        out = self.bus._arbiter._outstanding
        if out is not None and out.request.node in nodes and rng.random() < 0.6:
            others = [n for n in nodes if n != out.request.node]
            return [out.request.node, *rng.sample(others, rng.randint(0, len(others)))]
        return rng.sample(nodes, rng.randint(1, len(nodes)))

    async def round(self) -> None:
        rng = self.rng
        nodes = rng.sample(NODES, rng.randint(2, len(NODES)))
        tasks = {n: asyncio.create_task(self.request(n), name=f"storm {n}") for n in nodes}
        if rng.random() < 0.25:
            for _ in range(rng.randint(0, 6)):
                await asyncio.sleep(0)
        else:
            await asyncio.sleep(rng.uniform(0.0, 0.03))
        victims = set()
        for node in self.choose_victims(nodes):
            phase = self.phase(node)
            if tasks[node].cancel():
                victims.add(node)
                self.phases[phase] += 1
                self.cancellations += 1
            else:
                self.too_late += 1
        await asyncio.wait(tasks.values())
        for node, task in tasks.items():
            if node in victims:
                if not task.cancelled():
                    self.swallowed.append(f"node {node}: {task!r}")
                continue
            exc = task.exception()
            if exc is None:
                self.outcomes["ok"] += 1
            elif isinstance(exc, sj.SJ300Error):
                self.outcomes[type(exc).__name__] += 1
            else:
                self.untyped.append(repr(exc))

    async def check_in_sync(self) -> list[str]:
        problems = []
        sim = self.bus.simulator
        assert sim is not None
        for node in NODES:
            drive = self.bus.drive(node)
            if await drive.read_parameter_raw("C072") != node:
                problems.append(f"node {node:02d} does not answer as itself")
            for code in KEYS:
                got = await drive.read_parameter_raw(code)
                truth = sim.drives[node].parameters[code]
                if got != truth or truth not in self.oracle.allowed[(node, code)]:
                    problems.append(f"node {node:02d} {code}: read {got}, holds {truth}")
        return problems


async def run_storm(cancellations: int, seed: int) -> dict[str, Any]:
    baseline = Baseline.take()
    errors = ErrorLog()
    errors.install()
    started = time.perf_counter()
    storm: Storm
    timing = sj.BusTiming(margin_s=0.01)
    async with sj.open_bus(URL, timing=timing, retries=1) as bus:
        storm = Storm(bus, seed)
        bus.trace = storm.trace
        await storm.seed_values()
        rounds = 0
        while storm.cancellations < cancellations:
            await storm.round()
            rounds += 1
        elapsed = time.perf_counter() - started
        out_of_sync = await storm.check_in_sync()
        idle = bus_idle(bus)
        arbiter_cancelled = bus.stats.transactions.cancelled
        drains = bus.stats.drains
        unsolicited = bus.stats.unsolicited_frames
    leaks = await baseline.leaks()
    on_line = sum(storm.phases[p] for p in ON_THE_LINE)
    return {
        "cancellations": storm.cancellations,
        "seed": seed,
        "rounds": rounds,
        "elapsed_s": round(elapsed, 1),
        "cancelled_where": dict(storm.phases.most_common()),
        "cancel_too_late_task_done": storm.too_late,
        "swallowed_cancellations": len(storm.swallowed),
        "other_tasks": dict(storm.outcomes.most_common()),
        "values_checked": storm.oracle.checked,
        "wrong_values": len(storm.oracle.wrong),
        "untyped_errors": len(storm.untyped),
        "bus": {
            "cancelled_on_the_line": arbiter_cancelled,
            "drains": drains,
            "late_replies_discarded": unsolicited,
        },
        "leaks": len(leaks),
        "peak_rss_mib": peak_rss_mib(),
        "_details": {
            "on_line": on_line,
            "wrong": storm.oracle.wrong[:10],
            "untyped": storm.untyped[:10],
            "swallowed": storm.swallowed[:10],
            "out_of_sync": out_of_sync,
            "idle": idle,
            "leaks": leaks,
            "loop_errors": errors.errors[:10],
        },
    }


async def test_cancellation_storm(
    sizes: Sizes, soak_seed: int, soak_figures: dict[str, Any]
) -> None:
    figures = await run_storm(sizes.cancellations, soak_seed)
    details = figures.pop("_details")
    soak_figures["cancellation_storm"] = figures
    assert details["swallowed"] == [], "a cancellation was swallowed"
    assert details["wrong"] == []
    assert details["untyped"] == []
    assert details["out_of_sync"] == []
    assert details["idle"] == []
    assert details["leaks"] == []
    assert details["loop_errors"] == []
    # The arbiter counted exactly the cancellations that hit a request on the line.
    assert figures["bus"]["cancelled_on_the_line"] == details["on_line"]
    # The storm reached every moment of a transaction.
    where = figures["cancelled_where"]
    for phase in (BEFORE_WRITE, MID_WRITE, AWAITING, MID_REPLY):
        assert where.get(phase, 0) > 0, f"no cancellation {phase}: {where}"
