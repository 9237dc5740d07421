"""Reconnect cycles: the TCP device server dies and comes back, again and again, under load.

A poller reads four drives as fast as it may and a client task asks its own
questions, both through one TCP bus. Each cycle kills the simulator's TCP
server — half the time closing its connections (FIN), half the time
resetting them (RST, as a crashed bridge or a cut cable does) — keeps it
down for a moment, and starts it again on the same port. The client must
recover every time, every request during an outage must fail promptly with
a typed error (never hang), and after the last cycle no file descriptor,
task or timer may be left and memory must not have grown with the cycles.
"""

from __future__ import annotations

import asyncio
import functools
import random
import socket
import struct
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import pytest
from host_pauses import LoopStalls

import sj300_async as sj
from sj300_async.simulator import SimulatorServer, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .rel_leaks import Baseline, CountingLogs, ErrorLog, MemoryWatch, bus_idle
from .rel_sizes import Sizes

pytestmark = pytest.mark.soak

NODES = (1, 2, 3, 4)
TIMEOUT_S = 0.2
#: A request during an outage must fail within this (it fails at once while the link is down),
#: less the time this process's loop could not run meanwhile (host_pauses.LoopStalls): a clean
#: run saw one fail 0.46 s after its write, its 200 ms timer held up by the host.
PROMPT_S = TIMEOUT_S + 0.05
#: Recovery (restart -> a good answer again) must take less than this.
RECOVERY_BOUND_S = 2.0
POLICY = sj.ReconnectPolicy(initial_s=0.01, max_s=0.05, connect_timeout_s=0.5)


async def kill(server: SimulatorServer, reset: bool) -> None:
    """Stop the server; with *reset*, its connections end in RST instead of FIN."""
    if reset:
        # The simulator has no public "crash"; set SO_LINGER 0 so close() resets.
        for connection in list(server._connections):
            transport = connection._transport
            sock = transport.get_extra_info("socket") if transport else None
            if sock is not None:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    server.close()
    await server.wait_closed()


async def until(condition: Callable[[], bool], timeout: float, what: str) -> float:
    """Wait for *condition*; return how long it took. Fails the test after *timeout*."""
    loop = asyncio.get_running_loop()
    start = loop.time()
    while not condition():
        if loop.time() - start > timeout:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(0.002)
    return loop.time() - start


class Client:
    """Asks a question every few milliseconds and times every failure."""

    def __init__(self, bus: sj.Bus[sj.Drive, sj.Broadcast], seed: int, stalls: LoopStalls) -> None:
        self.bus = bus
        self.stalls = stalls
        self.rng = random.Random(seed)
        self.last_ok = 0.0
        self.outcomes: Counter[str] = Counter()
        self.slowest_failure_s = 0.0
        self.slow: list[str] = []
        self.wrong: list[str] = []
        self.untyped: list[str] = []

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            node = self.rng.choice(NODES)
            start = loop.time()
            try:
                address = await self.bus.drive(node).read_parameter_raw("C072")
            except sj.SJ300Error as exc:
                end = loop.time()
                took = end - start
                stalled = self.stalls.within(start, end)
                self.outcomes[type(exc).__name__] += 1
                self.slowest_failure_s = max(self.slowest_failure_s, took)
                if took - stalled > PROMPT_S:
                    self.slow.append(
                        f"{type(exc).__name__} after {took:.3f} s, the loop stalled "
                        f"{stalled:.3f} s of it: {exc}"
                    )
            except Exception as exc:
                self.untyped.append(repr(exc))
            else:
                self.outcomes["ok"] += 1
                self.last_ok = loop.time()
                if address != node:
                    self.wrong.append(f"node {node} answered C072 = {address}")
            await asyncio.sleep(0.003)


async def run_cycles(cycles: int, seed: int) -> dict[str, Any]:
    rng = random.Random(seed)
    loop = asyncio.get_running_loop()
    baseline = Baseline.take()
    errors = ErrorLog()
    errors.install()
    samples: Counter[str] = Counter()
    last_good: dict[int, float] = {}
    recoveries: list[float] = []
    modes: Counter[str] = Counter()

    def on_sample(sample: sj.Sample) -> None:
        samples["ok" if sample.error is None else "failed"] += 1
        if sample.error is None:
            last_good[sample.node] = sample.timestamp
            # An offline drive is probed with a status read only: no C072 then.
            if sample.parameters.get("C072", sample.node) != sample.node:
                samples["wrong_node"] += 1

    started = time.perf_counter()
    with MemoryWatch() as memory, CountingLogs() as logs:
        sim = SimulatedBus(NODES)
        server = await serve_tcp(sim)
        port = server.port
        url = f"tcp://127.0.0.1:{port}"
        async with sj.open_bus(url, timeout=TIMEOUT_S, retries=0, reconnect=POLICY) as bus:
            poller = sj.Poller(
                interval_s=0.005,
                parameters=["C072"],
                offline_after=2,
                offline_probe_interval_s=0.02,
            )
            poller.add(bus, NODES)
            poller.on_sample(on_sample)
            stalls = LoopStalls()
            client = Client(bus, seed, stalls)

            def recovered(since: float) -> bool:
                return client.last_ok > since and all(last_good.get(n, 0) > since for n in NODES)

            def answered(since: float) -> bool:
                return client.last_ok > since

            async with poller:
                asking = asyncio.create_task(client.run(), name="reconnect client")
                restarted = loop.time()
                for cycle in range(cycles):
                    # Up: every drive polled well and the client answered, since the restart.
                    recoveries.append(
                        await until(
                            functools.partial(recovered, restarted),
                            RECOVERY_BOUND_S,
                            f"recovery in cycle {cycle}",
                        )
                    )
                    if cycle == min(10, cycles // 2):
                        memory.mark("warm")
                    await asyncio.sleep(rng.uniform(0.0, 0.05))
                    reset = rng.random() < 0.5
                    modes["RST" if reset else "FIN"] += 1
                    await kill(server, reset)
                    await until(lambda: not bus.connected, 2.0, "the bus to notice")
                    await asyncio.sleep(rng.uniform(0.02, 0.1))  # requests fail meanwhile
                    server = await serve_tcp(sim, port=port)
                    restarted = loop.time()
                recoveries.append(
                    await until(
                        functools.partial(answered, restarted), RECOVERY_BOUND_S, "last recovery"
                    )
                )
                asking.cancel()
                await asyncio.gather(asking, return_exceptions=True)
                stalls.close()
            idle = bus_idle(bus)
            connects, disconnects = bus.stats.connects, bus.stats.disconnects
        server.close()
        await server.wait_closed()
        memory.mark("end")
    leaks = await baseline.leaks()
    return {
        "reconnect_cycles": cycles,
        "seed": seed,
        "elapsed_s": round(time.perf_counter() - started, 1),
        "kills": dict(modes),
        "connects": connects,
        "disconnects": disconnects,
        "recovery_s": {
            "mean": round(sum(recoveries) / len(recoveries), 3),
            "max": round(max(recoveries), 3),
        },
        "client_requests": dict(client.outcomes.most_common()),
        "slowest_failure_s": round(client.slowest_failure_s, 3),
        "loop_stalled_s": round(sum(b - a for a, b in stalls.stalls), 3),
        "poller_samples": dict(samples),
        "library_log_records": dict(logs.counts),
        "memory_mib_peak_traced": memory.final_peak_mib,
        "memory_growth_kib_after_warmup": memory.growth_kib("warm", "end"),
        "leaks": len(leaks),
        "_details": {
            "slow": client.slow[:10],
            "wrong": client.wrong[:10],
            "untyped": client.untyped[:10],
            "idle": idle,
            "leaks": leaks,
            "loop_errors": errors.errors[:10],
        },
    }


async def test_reconnect_cycles(sizes: Sizes, soak_seed: int, soak_figures: dict[str, Any]) -> None:
    figures = await run_cycles(sizes.reconnect_cycles, soak_seed)
    details = figures.pop("_details")
    soak_figures["reconnect_cycles"] = figures
    assert details["untyped"] == []
    assert details["slow"] == [], "requests during an outage must fail promptly"
    assert details["wrong"] == []
    assert figures["poller_samples"].get("wrong_node", 0) == 0
    assert details["idle"] == []
    assert details["leaks"] == []
    assert details["loop_errors"] == []
    assert figures["connects"] == sizes.reconnect_cycles + 1
    assert figures["disconnects"] == sizes.reconnect_cycles
    assert figures["client_requests"].get("TransportError", 0) > 0
    # Memory does not grow with the cycles (a leak of one connection's objects per
    # cycle would show as tens of KiB per cycle).
    assert figures["memory_growth_kib_after_warmup"] < 256


async def test_connection_lost_while_writing_is_paused_fails_typed() -> None:
    """A device server that stops reading, then drops: the waiting request fails typed."""
    async with sj.open_bus("sim://?nodes=1", timeout=0.2) as bus:
        protocol = bus.link.protocol
        assert protocol is not None
        protocol.pause_writing()  # what the transport does when its write buffer is full
        request = asyncio.create_task(bus.drive(1).read_status())
        await asyncio.sleep(0.01)
        bus.link.drop()
        with pytest.raises(sj.TransportError):
            await request
