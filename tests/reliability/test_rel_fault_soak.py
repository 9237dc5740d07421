"""Fault soak: mixed commands to eight drives from six tasks, through a line that misbehaves.

Every request must end as the right value or a typed SJ300Error: zero wrong
values, zero untyped exceptions, and the bus in sync afterwards. The fault
model (rel_faults.py) damages both directions of the line — bytes
corrupted, dropped, inserted, duplicated, frames fragmented and delayed,
content made invalid under a matching BCC, stray frames from other nodes —
and the simulated drives drop, corrupt and delay replies past their
time-out (up to 5 time-outs, answering in order), go late or silent for a
while, and trip. The oracle (rel_oracle.py) knows what every parameter may
hold.

Two runs: on an instant line (as fast as the CPU goes), and on a line
declared at 19200 baud whose replies arrive no sooner than physics allows,
where a bridge also delivers 30 % of the replies twice (issue 14): only a
line with a speed gives the bus the plausibility floor that tells a copy
from an answer.
"""

from __future__ import annotations

import asyncio
import random
import time
from collections import Counter
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import pytest
from host_pauses import no_collector_pauses
from waiting import wait_for

import sj300_async as sj
from sj300_async import sj300 as sj3
from sj300_async.simulator.sj300 import SimulatedBus

from .rel_faults import DriveChaos, FrameFaults
from .rel_leaks import Baseline, ErrorLog, bus_idle, peak_rss_mib
from .rel_oracle import KEYS, Oracle, value_for
from .rel_sizes import Sizes

pytestmark = pytest.mark.soak

NODES = tuple(range(1, 9))
WORKERS = 6
#: Response time-out of the soak bus. Short, so that a fault costs little time.
TIMEOUT_S = 0.025
#: A node goes late or silent for EPISODE_ON_S, then behaves for EPISODE_OFF_S.
EPISODE_ON_S = 0.1
EPISODE_OFF_S = 0.4


INSTANT_LINE = sj.LineSettings(baudrate=0)


@dataclass(frozen=True)
class Setup:
    """One soak's line: its speed (baud rate 0: instant, no plausibility floor) and extra faults."""

    line: sj.LineSettings = INSTANT_LINE
    #: Per reply: a bridge delivers it twice, the copy 1..5 ms later (rel_faults.FrameFaults).
    duplicate_rate: float = 0.0
    #: Per request: a one-shot drive fault (rel_faults.DriveChaos).
    chaos_rate: float = 0.01
    chaos_kinds: tuple[str, ...] = DriveChaos.kinds


INSTANT = Setup()
#: 19200 baud, 30 % of replies duplicated, and one-shot drive faults six
#: times as often as on the instant line, very late replies weighed three
#: times, so that even the short form meets them.
DUPLICATING_19200 = Setup(
    line=sj.LineSettings(19200),
    duplicate_rate=0.3,
    chaos_rate=0.06,
    chaos_kinds=DriveChaos.kinds + ("very_late_next",) * 2,
)


class Soak:
    """One soak run: the bus, the oracle, the workers and what they counted."""

    def __init__(self, bus: sj.Bus, sim: SimulatedBus, chaos: DriveChaos, seed: int) -> None:
        self.bus = bus
        self.sim = sim
        self.chaos = chaos
        self.oracle = Oracle()
        self.outcomes: Counter[str] = Counter()
        self.untyped: list[str] = []
        self.budget = 0
        self.serials: Counter[tuple[int, str]] = Counter()
        self.seed = seed
        self.loop = asyncio.get_running_loop()

    # -- the operations (each is one Drive API call) -------------------------------

    async def read_key(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        node, code = rng.choice(keys)
        raw = await self.bus.drive(node).read_parameter_raw(code)
        self.oracle.read(node, code, raw)

    async def write_key(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        node, code = rng.choice(keys)
        self.serials[(node, code)] += 1
        raw = value_for(code, node, self.serials[(node, code)])
        drive = self.bus.drive(node)
        try:
            if code == "F001":
                await drive.set_frequency(raw / 100)
            else:
                await drive.write_parameter_raw(code, raw)
        except BaseException:
            self.oracle.write_failed(node, code, raw)
            raise
        self.oracle.wrote(node, code, raw)

    async def read_address(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        node = rng.choice(NODES)
        raw = await self.bus.drive(node).read_parameter_raw("C072")
        self.oracle.check_constant(f"node {node:02d} C072", raw, node)

    async def read_status(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        node = rng.choice(NODES)
        status = await self.bus.drive(node).read_status()
        known = status.a.known and status.b.known and status.c.known
        self.oracle.check_constant(f"node {node:02d} status codes known", known, True)

    async def read_monitor(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        node = rng.choice(NODES)
        m = await self.bus.drive(node).read_monitor()
        # Setpoints never exceed 8.99 Hz; hours cannot be negative; item 3 is 0/1/2.
        sane = 0 <= m.output_frequency_hz <= 9 and m.direction.known and m.run_time_h >= 0
        self.oracle.check_constant(f"node {node:02d} monitor {m}", sane, True)

    async def read_trips(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        node = rng.choice(NODES)
        before = self.sim.drives[node].trip_history().total_count
        history = await self.bus.drive(node).read_trip_history()
        after = self.sim.drives[node].trip_history().total_count
        ok = before <= history.total_count <= after
        self.oracle.check_constant(f"node {node:02d} trip count in [{before}, {after}]", ok, True)

    async def run_or_stop(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        drive = self.bus.drive(rng.choice(NODES))
        await (drive.run_forward() if rng.random() < 0.5 else drive.stop())

    async def reset_trip(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        # RS rising resets a trip; the next call of either kind lowers it again.
        terminals = sj.InputTerminal.RS if rng.random() < 0.5 else 0
        await self.bus.drive(rng.choice(NODES)).set_terminals(terminals)

    async def can_store(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        await self.bus.drive(rng.choice(NODES)).can_store()

    async def broadcast_stop(self, rng: random.Random, keys: list[tuple[int, str]]) -> None:
        await self.bus.broadcast.stop()

    # -- the run -------------------------------------------------------------------

    async def seed_values(self) -> None:
        """Give every key a known, node-specific value (before the faults start)."""
        for node in NODES:
            for code in KEYS:
                raw = value_for(code, node, 0)
                if code == "F001":
                    await self.bus.drive(node).set_frequency(raw / 100)
                else:
                    await self.bus.drive(node).write_parameter_raw(code, raw)
                self.oracle.settle(node, code, raw)

    async def worker(self, index: int, keys: list[tuple[int, str]]) -> None:
        rng = random.Random(self.seed * 1000 + index)
        ops: list[tuple[Callable[..., Awaitable[None]], int]] = [
            (self.read_key, 30),
            (self.write_key, 20),
            (self.read_address, 8),
            (self.read_status, 12),
            (self.read_monitor, 10),
            (self.read_trips, 3),
            (self.run_or_stop, 6),
            (self.reset_trip, 3),
            (self.can_store, 3),
            (self.broadcast_stop, 1),
        ]
        functions = [f for f, _ in ops]
        weights = [w for _, w in ops]
        while self.budget > 0:
            self.budget -= 1
            self.chaos.maybe(self.loop.time())
            op = rng.choices(functions, weights)[0]
            try:
                await op(rng, keys)
            except sj.SJ300Error as exc:
                self.outcomes[type(exc).__name__] += 1
            except Exception as exc:  # the one thing that must never happen
                self.untyped.append(f"{op.__name__}: {exc!r}")
            else:
                self.outcomes["ok"] += 1

    async def episodes(self) -> None:
        while True:
            await asyncio.sleep(EPISODE_OFF_S)
            self.chaos.toggle_episode()
            await asyncio.sleep(EPISODE_ON_S)
            self.chaos.toggle_episode()

    async def check_in_sync(self) -> list[str]:
        """Faults off: every key reads back as the drive holds it, and as the oracle allows."""
        problems = []
        for node in NODES:
            drive = self.bus.drive(node)
            if await drive.read_parameter_raw("C072") != node:
                problems.append(f"node {node:02d} does not answer as itself")
            for code in KEYS:
                got = await drive.read_parameter_raw(code)
                truth = self.sim.drives[node].parameters[code]
                if got != truth:
                    problems.append(f"node {node:02d} {code}: read {got}, the drive holds {truth}")
                if truth not in self.oracle.allowed[(node, code)]:
                    problems.append(f"node {node:02d} {code}: holds {truth}, never written")
        return problems


def line_faults(seed: int, setup: Setup) -> tuple[FrameFaults, FrameFaults]:
    to_drive = FrameFaults(
        rng=random.Random(seed + 1),
        byte_fault_rate=0.012,
        garble_rate=0.005,
        fragment_max=4,
        parser_factory=sj3.RequestParser,
    )
    to_host = FrameFaults(
        rng=random.Random(seed + 2),
        byte_fault_rate=0.012,
        garble_rate=0.005,
        stray_rate=0.02,
        fragment_max=6,
        # Within the time-out: the late-past-the-time-out delays come from the drives.
        delay_rate=0.02,
        delay_max_s=0.2 * TIMEOUT_S,
        duplicate_rate=setup.duplicate_rate,
    )
    return to_drive, to_host


async def run_soak(transactions: int, seed: int, setup: Setup = INSTANT) -> dict[str, Any]:
    baseline = Baseline.take()
    errors = ErrorLog()
    errors.install()
    sim = SimulatedBus(NODES, processing_s=0.0)
    to_drive, to_host = line_faults(seed, setup)
    armed = (to_drive.byte_fault_rate, to_host.byte_fault_rate)
    to_drive.byte_fault_rate = to_host.byte_fault_rate = 0.0  # armed after seeding
    garble, stray = (to_drive.garble_rate, to_host.garble_rate), to_host.stray_rate
    to_drive.garble_rate = to_host.garble_rate = to_host.stray_rate = 0.0
    duplicates, to_host.duplicate_rate = to_host.duplicate_rate, 0.0
    chaos = DriveChaos(
        sim, random.Random(seed + 3), TIMEOUT_S, rate=setup.chaos_rate, kinds=setup.chaos_kinds
    )
    loop = asyncio.get_running_loop()
    started = time.perf_counter()
    async with sj.open_bus(
        "sim://",
        simulator=sim,
        faults=(to_drive, to_host),
        timeout=TIMEOUT_S,
        retries=2,
        line=setup.line,
    ) as bus:
        soak = Soak(bus, sim, chaos, seed)
        await soak.seed_values()
        to_drive.byte_fault_rate, to_host.byte_fault_rate = armed
        (to_drive.garble_rate, to_host.garble_rate), to_host.stray_rate = garble, stray
        to_host.duplicate_rate = duplicates
        soak.budget = transactions
        owned: list[list[tuple[int, str]]] = [[] for _ in range(WORKERS)]
        for i, key in enumerate((n, c) for n in NODES for c in KEYS):
            owned[i % WORKERS].append(key)
        episodes = asyncio.create_task(soak.episodes())
        await asyncio.gather(*(soak.worker(i, owned[i]) for i in range(WORKERS)))
        episodes.cancel()
        await asyncio.gather(episodes, return_exceptions=True)
        elapsed = time.perf_counter() - started
        chaos.stop()
        to_drive.stop()
        to_host.stop()
        # The replies the drives still hold back go out (in order), then land
        # and are drained: the line chunks are no longer delayed, the drain
        # needs one time-out of quiet.
        await wait_for(
            lambda: loop.time() > sim.faults.held_until() + 2 * TIMEOUT_S,
            "the held replies to be out and drained",
        )
        out_of_sync = await soak.check_in_sync()
        idle = bus_idle(bus)
        stats = bus.stats
        totals = stats.transactions
    leaks = await baseline.leaks()
    faults: dict[str, int] = {}
    for prefix, counts in (("line_to_drive", to_drive.counts), ("line_to_host", to_host.counts)):
        faults.update({f"{prefix}.{k}": v for k, v in sorted(counts.items())})
    faults.update({f"drive.{k}": v for k, v in sorted(chaos.counts.items())})
    return {
        "transactions": transactions,
        "seed": seed,
        "elapsed_s": round(elapsed, 1),
        "outcomes": dict(soak.outcomes.most_common()),
        "values_checked": soak.oracle.checked,
        "wrong_values": len(soak.oracle.wrong),
        "untyped_errors": len(soak.untyped),
        "faults_injected": faults,
        # Fragmentation splits chunks without damaging them: not counted as a fault.
        "faults_injected_total": sum(
            v for k, v in faults.items() if not k.endswith(("fragmented", "unsound_skipped"))
        ),
        "simulator": {
            "replies_dropped": sim.stats.dropped_replies,
            "replies_corrupted": sim.stats.corrupted_replies,
            "replies_delayed": sim.stats.delayed_replies,
            "bad_request_frames": sim.stats.bad_frames,
            "naks_sent": {int(k): v for k, v in sorted(sim.stats.naks.items())},
        },
        "bus": {
            "requests_written": totals.requests,
            "retries": totals.retries,
            "timeouts": totals.timeouts,
            "protocol_errors": totals.protocol_errors,
            "naks": {int(k): v for k, v in sorted(totals.naks.items())},
            "bad_frames": stats.bad_frames,
            "stray_frames": stats.stray_frames,
            "unsolicited_frames": stats.unsolicited_frames,
            "discarded_bytes": stats.discarded_bytes,
            "drains": stats.drains,
            "early_frames": stats.early_frames,
            "resyncs": stats.resyncs,
        },
        "peak_rss_mib": peak_rss_mib(),
        "_details": {
            "wrong": soak.oracle.wrong[:10],
            "untyped": soak.untyped[:10],
            "out_of_sync": out_of_sync,
            "idle": idle,
            "leaks": leaks,
            "loop_errors": errors.errors[:10],
        },
    }


def check_soak(figures: dict[str, Any], details: dict[str, Any], soak_seed: int) -> None:
    """What every soak must show (the figures without their details)."""
    assert details["wrong"] == [], f"wrong values (seed {soak_seed})"
    assert details["untyped"] == [], f"untyped exceptions (seed {soak_seed})"
    assert details["out_of_sync"] == [], "the bus is out of sync after the soak"
    assert details["idle"] == []
    assert details["leaks"] == []
    assert details["loop_errors"] == []
    outcomes = figures["outcomes"]
    assert sum(outcomes.values()) == figures["transactions"]
    assert outcomes["ok"] > 0.5 * figures["transactions"], "the soak mostly measured failures"
    assert figures["bus"]["resyncs"] > 0


async def test_fault_soak(sizes: Sizes, soak_seed: int, soak_figures: dict[str, Any]) -> None:
    figures = await run_soak(sizes.transactions, soak_seed)
    details = figures.pop("_details")
    soak_figures["fault_soak"] = figures
    check_soak(figures, details, soak_seed)
    assert figures["bus"]["early_frames"] == 0  # an instant line has no floor
    # Every kind of fault was really injected.
    faults = figures["faults_injected"]
    for kind in ("corrupted", "dropped", "inserted", "duplicated", "bcc_valid_garbage"):
        assert faults.get(f"line_to_host.{kind}", 0) + faults.get(f"line_to_drive.{kind}", 0) > 0
    assert faults.get("line_to_host.stray_frames", 0) > 0
    assert faults.get("line_to_host.delayed", 0) > 0
    drive_faults = [k for k in faults if k.startswith("drive.")]
    assert len(drive_faults) >= 4, drive_faults
    assert figures["bus"]["stray_frames"] + figures["bus"]["unsolicited_frames"] > 0


async def test_fault_soak_with_duplicated_and_very_late_replies(
    sizes: Sizes, soak_seed: int, soak_figures: dict[str, Any]
) -> None:
    with no_collector_pauses():  # a host pause defeats any floor (tests/host_pauses.py)
        figures = await run_soak(sizes.reply_transactions, soak_seed, DUPLICATING_19200)
    details = figures.pop("_details")
    soak_figures["fault_soak_19200_duplicates"] = figures
    check_soak(figures, details, soak_seed)
    faults = figures["faults_injected"]
    assert faults["line_to_host.duplicated_replies"] > 0.2 * figures["transactions"]
    assert faults["drive.very_late_next"] > 0
    # Every copy reached the bus as a whole frame and was discarded: as early
    # (the floor: the next request went to the same node, for the same shape;
    # tests/bus/test_duplicates_and_late_replies.py has that case alone), stray
    # (another node or shape) or unsolicited (between transactions).
    bus = figures["bus"]
    discarded = bus["early_frames"] + bus["stray_frames"] + bus["unsolicited_frames"]
    assert discarded >= faults["line_to_host.duplicated_replies"]
