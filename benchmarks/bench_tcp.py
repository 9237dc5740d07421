"""TCP round trips: our client and simulator against pymodbus's client and server.

Each server runs in a process of its own (:mod:`benchmarks._servers`); both
clients run in this process, on one event loop, connected before timing
starts. A timed run is N sequential requests, each awaited before the next,
as a host polling one drive through a serial device server would send them.

Two request sizes, matched on the wire:

- small: our ``Drive.read_status()`` (8-byte request, 14-byte reply, decoded
  to :class:`~sj300_async.InverterStatus`) against pymodbus's
  ``read_holding_registers(count=1)`` (12-byte request, 11-byte reply);
- large: our ``Drive.read_monitor()`` (8 bytes, 110-byte reply, decoded to
  :class:`~sj300_async.MonitorData`) against
  ``read_holding_registers(count=50)`` (12 bytes, 109-byte reply).

Our simulator runs with ``processing_s=0``: by default it waits 1 ms before
each reply to emulate a drive's processing, which would time the emulated
drive, not the stack. pymodbus's server answers as fast as it can. Our bus is
told that no serial line is behind the socket (``line=LineSettings(baudrate=0)``):
by default it assumes 19200 baud and rests 3.5 character times (1.8 ms) after
every reply, as the RS-485 line behind a real device server needs, which would
time that rest instead of the stack.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from importlib.metadata import version
from typing import Any

from pymodbus.client import AsyncModbusTcpClient

from sj300_async import Drive, LineSettings, open_bus

from ._harness import Config, Result, Section, compare, new_runner
from ._servers import ServerProcess

__all__ = ["REQUESTS", "TITLE", "USES_EVENT_LOOP", "Rate", "measure", "run"]

#: No RS-485 line behind the simulator's socket: no wire time, so no guard interval.
INSTANT_LINE = LineSettings(baudrate=0)

TITLE = "tcp"
USES_EVENT_LOOP = True
#: Sequential requests per timed run, full and ``--quick``.
REQUESTS = 2_000
QUICK_REQUESTS = 50
#: The project's aim for requests/s, as a multiple of pymodbus.
TARGET_RATIO = 2.5

#: A timed run: N sequential requests; returns N.
_Batch = Callable[[], Coroutine[Any, Any, int]]

#: (row label, our read, registers pymodbus reads)
_SIZES: tuple[tuple[str, str, int], ...] = (
    ("read_status vs 1 register", "status", 1),
    ("read_monitor vs 50 registers", "monitor", 50),
)


def _ours(drive: Drive, read: str, n: int) -> _Batch:
    async def requests() -> int:
        call = drive.read_status if read == "status" else drive.read_monitor
        for _ in range(n):
            await call()
        return n

    return requests


def _peer(client: AsyncModbusTcpClient, count: int, n: int) -> _Batch:
    async def requests() -> int:
        for _ in range(n):
            response = await client.read_holding_registers(0, count=count, device_id=1)
            if response.isError() or len(response.registers) != count:
                raise RuntimeError(f"pymodbus: unexpected response {response}")
        return n

    return requests


async def _connect_peer(port: int) -> AsyncModbusTcpClient:
    client = AsyncModbusTcpClient("127.0.0.1", port=port)  # needs the running loop
    if not await client.connect():
        raise RuntimeError(f"pymodbus could not connect to port {port}")
    return client


class _CpuMeter:
    """Process CPU time this process spent in the batches it ran."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.requests = 0

    def timed(self, runner: asyncio.Runner, batch: _Batch) -> Callable[[], int]:
        def run_batch() -> int:
            start = time.process_time()
            done = runner.run(batch())
            self.seconds += time.process_time() - start
            self.requests += done
            return done

        return run_batch


@dataclass(frozen=True, slots=True)
class Rate:
    """One request size: the rate of each stack, and the CPU time of each side per request."""

    label: str
    ours_rps: float
    peer_rps: float
    #: Mean CPU seconds per request over every run, warm-up included: (ours, pymodbus).
    client_cpu_s: tuple[float, float]
    server_cpu_s: tuple[float, float]


def measure(config: Config) -> list[Rate]:
    """Time both stacks at each request size; return their rates and CPU shares.

    Raises:
        RuntimeError: a server did not start, or a request went unanswered.
    """
    n = QUICK_REQUESTS if config.quick else REQUESTS
    uvloop = config.loop == "uvloop"
    rates: list[Rate] = []
    with (
        ServerProcess("sj300", uvloop=uvloop) as ours_server,
        ServerProcess("pymodbus", uvloop=uvloop) as peer_server,
        new_runner(config.loop) as runner,
    ):
        stack = contextlib.AsyncExitStack()
        try:
            url = f"tcp://127.0.0.1:{ours_server.port}"
            bus = runner.run(stack.enter_async_context(open_bus(url, line=INSTANT_LINE)))
            client = runner.run(_connect_peer(peer_server.port))
            stack.callback(client.close)
            drive = bus.drive(1)
            for label, read, count in _SIZES:
                ours, peer = _CpuMeter(), _CpuMeter()
                servers_before = ours_server.cpu_seconds(), peer_server.cpu_seconds()
                t_ours, t_peer = compare(
                    ours.timed(runner, _ours(drive, read, n)),
                    peer.timed(runner, _peer(client, count, n)),
                    config.repeats,
                )
                ours_server_s = ours_server.cpu_seconds() - servers_before[0]
                peer_server_s = peer_server.cpu_seconds() - servers_before[1]
                rates.append(
                    Rate(
                        label,
                        n / t_ours,
                        n / t_peer,
                        (ours.seconds / ours.requests, peer.seconds / peer.requests),
                        (ours_server_s / ours.requests, peer_server_s / peer.requests),
                    )
                )
            # Every timed run, plus each side's untimed warm-up run, got its replies.
            expected = n * (config.repeats + 1) * len(_SIZES)
            if bus.stats.transactions.replies != expected:
                raise RuntimeError(f"ours: {bus.stats.transactions.replies} of {expected} replies")
        finally:
            runner.run(stack.aclose())
    return rates


def run(config: Config) -> Section:
    """Measure sequential TCP round trips of both stacks."""
    n = QUICK_REQUESTS if config.quick else REQUESTS
    rates = measure(config)
    notes: tuple[str, ...] = (
        f"{n:,} sequential requests per timed run, each stack's client in this process "
        "and its server in a process of its own, on 127.0.0.1.",
        "Ours: `open_bus('tcp://…')` + `Drive.read_status()` / `read_monitor()` (decoded) "
        "against `sj300_async.simulator.serve_tcp` with the drive's `processing_s=0` "
        "(its default 1 ms emulates a drive's processing and would time the emulated drive), "
        "the bus opened with `line=LineSettings(baudrate=0)` (no RS-485 line behind the "
        "socket, so no guard interval after each reply). "
        f"pymodbus {version('pymodbus')}: `AsyncModbusTcpClient.read_holding_registers` "
        "against `ModbusTcpServer` with one `SimDevice` of holding registers; "
        "1 register (12-byte request, 11-byte reply) matches our status read (8 / 14 bytes), "
        "50 registers (12 / 109 bytes) our monitor read (8 / 110 bytes).",
    )
    us = 1e6
    notes += (
        "",
        "| requests | wall µs/request ours | pymodbus | client CPU µs ours | pymodbus "
        "| server CPU µs ours | pymodbus |",
        "|---|---:|---:|---:|---:|---:|---:|",
        *(
            f"| {r.label} | {us / r.ours_rps:.0f} | {us / r.peer_rps:.0f} "
            f"| {r.client_cpu_s[0] * us:.0f} | {r.client_cpu_s[1] * us:.0f} "
            f"| {r.server_cpu_s[0] * us:.0f} | {r.server_cpu_s[1] * us:.0f} |"
            for r in rates
        ),
        "",
        "CPU per request is the mean over every run, warm-up included; the client's runs "
        "in this process, the server's in its own. What the wall time has beyond the two is "
        "the kernel's loopback and the wake-ups of two processes.",
    )
    results = tuple(
        Result(f"tcp: {r.label}", r.ours_rps, r.peer_rps, "requests/s", TARGET_RATIO) for r in rates
    )
    return Section(TITLE, notes, results)
