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
told that no serial line is behind the socket (``line=LineSettings(baudrate=0)``),
which is true here; by default it assumes 19200 baud behind a device server,
which would only lengthen its response time-outs (and any configured guard).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from importlib.metadata import version
from typing import Any, cast

from pymodbus.client import AsyncModbusTcpClient

from sj300_async import Drive, LineSettings, open_bus

from ._harness import Config, Result, Section, compare, new_runner
from ._servers import ECHO_REPLIES, ServerProcess

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


class _EchoClient(asyncio.Protocol):
    """The floor's client: writes a request, waits for the whole fixed-size reply."""

    def __init__(self) -> None:
        self._transport: asyncio.Transport | None = None
        self._waiter: asyncio.Future[None] | None = None
        self._missing = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # A cast, not isinstance(): uvloop's transports do not derive from asyncio's.
        self._transport = cast(asyncio.Transport, transport)
        sock = transport.get_extra_info("socket")
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # as our transport does

    def data_received(self, data: bytes) -> None:
        self._missing -= len(data)
        if self._missing <= 0 and self._waiter is not None:
            self._waiter.set_result(None)

    async def ask(self, kind: bytes) -> None:
        assert self._transport is not None
        self._waiter = asyncio.get_running_loop().create_future()
        self._missing = len(ECHO_REPLIES[kind])
        self._transport.write(kind + b"0104\r\n\x00")  # 8 bytes, as our requests
        await self._waiter


def _floor(client: _EchoClient, read: str, n: int) -> _Batch:
    async def requests() -> int:
        kind = b"S" if read == "status" else b"M"
        for _ in range(n):
            await client.ask(kind)
        return n

    return requests


async def _connect_echo(port: int) -> _EchoClient:
    loop = asyncio.get_running_loop()
    _transport, client = await loop.create_connection(_EchoClient, "127.0.0.1", port)
    return client


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
    #: A bare asyncio round trip of the same sizes, and pymodbus timed against it.
    floor_rps: float
    peer_vs_floor_rps: float
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
        ServerProcess("echo", uvloop=uvloop) as echo_server,
        new_runner(config.loop) as runner,
    ):
        stack = contextlib.AsyncExitStack()
        try:
            url = f"tcp://127.0.0.1:{ours_server.port}"
            bus = runner.run(stack.enter_async_context(open_bus(url, line=INSTANT_LINE)))
            client = runner.run(_connect_peer(peer_server.port))
            stack.callback(client.close)
            echo = runner.run(_connect_echo(echo_server.port))
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
                # The floor, interleaved with pymodbus again: the ratio any asyncio
                # stack could reach on this machine at this size.
                t_floor, t_peer_again = compare(
                    _CpuMeter().timed(runner, _floor(echo, read, n)),
                    _CpuMeter().timed(runner, _peer(client, count, n)),
                    config.repeats,
                )
                rates.append(
                    Rate(
                        label,
                        n / t_ours,
                        n / t_peer,
                        n / t_floor,
                        n / t_peer_again,
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
        "",
        "The floor rows time what no asyncio stack can beat on this machine: a bare "
        "`asyncio.Protocol` client writing 8 bytes and waiting for a fixed 14- or 110-byte "
        "answer from a bare protocol server (`python -m benchmarks._servers echo`) with no "
        "framing, no checks, no decoding, interleaved with pymodbus again. Its ratio is the "
        "most any stack on the same loop could show against pymodbus here: "
        + ", ".join(f"{r.floor_rps / r.peer_vs_floor_rps:.2f}x ({r.label})" for r in rates)
        + ".",
    )
    results: list[Result] = []
    for r in rates:
        results += [
            Result(f"tcp: {r.label}", r.ours_rps, r.peer_rps, "requests/s", TARGET_RATIO),
            Result(
                f"tcp floor: bare asyncio round trip, {r.label.split()[0]} sizes",
                r.floor_rps,
                r.peer_vs_floor_rps,
                "requests/s",
            ),
        ]
    return Section(TITLE, notes, tuple(results))
