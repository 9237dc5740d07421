"""TCP round trips: our client against pymodbus's and a bare asyncio client.

**The headline: the same minimal responder for every client.** Each
protocol's server is a bare asyncio protocol in a process of its own
(:mod:`benchmarks._servers`) that answers each request with one fixed,
valid reply, with no model and no parsing beyond finding the request's end:

- ``sj300-minimal`` answers node 1's 14-byte status reply (the library's own
  reply encoding) to our ``Drive.read_status()`` (8-byte request, the reply
  parsed, BCC-checked and decoded to :class:`~sj300_async.InverterStatus`);
- ``modbus-minimal`` answers a 4-register read (17 bytes, the request's
  transaction id copied in) to pymodbus's ``read_holding_registers(count=4)``
  (12-byte request, decoded to a response with 4 registers);
- ``echo``, the floor: a bare ``asyncio.Protocol`` client writes 8 bytes and
  waits on a future for a fixed 14-byte answer, no framing, no checks;
- ``echo`` again, the same client on asyncio's ``BufferedProtocol`` read
  path, reading into one reused buffer as our adapter does: asyncio's
  plain-protocol reads allocate 256 KiB each, which on glibc may cost an
  ``mmap``/``mremap``/``munmap`` per read (see :mod:`benchmarks._floor`).
  The targets stay against the plain floor, as issue 18 defines it; ours
  against this one shows what our stack costs over the same read path.

So the servers cost alike and the rows differ by the clients' stacks only.
All the clients run in this process on one event loop, connected before
timing; a timed run is N sequential requests, each awaited before the next;
they alternate, rotating their order, best of each. Besides wall time,
the client's CPU time per round trip (``time.process_time()`` of this
process, which runs nothing else meanwhile). The targets (issue 18): ours at
least 0.90 of the floor's requests/s, and our client CPU per round trip at
most 0.7 of pymodbus's, both from the same run.

**The second table: each stack on its own server.** Our client and simulator
against pymodbus's client and server, at two request sizes matched on the
wire:

- small: our ``Drive.read_status()`` (8-byte request, 14-byte reply, decoded
  to :class:`~sj300_async.InverterStatus`) against pymodbus's
  ``read_holding_registers(count=1)`` (12-byte request, 11-byte reply);
- large: our ``Drive.read_monitor()`` (8 bytes, 110-byte reply, decoded to
  :class:`~sj300_async.MonitorData`) against
  ``read_holding_registers(count=50)`` (12 bytes, 109-byte reply).

These rows time the two servers as much as the clients (issue 18: most of
issue 7's ratio came from the servers), so they carry no target now.
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
import statistics
import time
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from importlib.metadata import version
from typing import Any

from pymodbus.client import AsyncModbusTcpClient

from sj300_async import Drive, LineSettings, open_bus

from ._floor import EchoClient, connect_echo, echo_round_trips
from ._harness import Config, Result, Section, Timing, compare, interleave, new_runner
from ._servers import MODBUS_REGISTERS, ServerProcess

__all__ = [
    "REQUESTS",
    "TITLE",
    "USES_EVENT_LOOP",
    "Minimal",
    "Rate",
    "Side",
    "measure",
    "measure_minimal",
    "run",
]

#: No RS-485 line behind the simulator's socket: no wire time, so no guard interval.
INSTANT_LINE = LineSettings(baudrate=0)

TITLE = "tcp"
USES_EVENT_LOOP = True
#: Sequential requests per timed run, full and ``--quick``.
REQUESTS = 2_000
QUICK_REQUESTS = 50
#: Issue 18's aims, same minimal responder: our requests/s at least this share of the
#: bare asyncio floor's, and our client CPU per round trip at most this share of pymodbus's.
TARGET_VS_FLOOR = 0.90
TARGET_CPU_VS_PYMODBUS = 0.7

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


def _floor(client: EchoClient, read: str, n: int) -> _Batch:
    kind = b"S" if read == "status" else b"M"
    return lambda: echo_round_trips(client, kind, n)


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
            echo = runner.run(connect_echo(echo_server.port))
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


@dataclass(frozen=True, slots=True)
class Side:
    """One client against its minimal responder: its timed runs and the server's CPU."""

    label: str
    timing: Timing
    requests: int
    #: The server process's CPU seconds per request, mean over every run (warm-up included).
    server_cpu_s: float

    @property
    def rps(self) -> float:
        """Requests per second of the fastest run."""
        return self.requests / self.timing.best_wall_s

    @property
    def wall_s(self) -> float:
        """Wall seconds per round trip, fastest run."""
        return self.timing.best_wall_s / self.requests

    @property
    def cpu_s(self) -> float:
        """This process's CPU seconds per round trip, in the run that took the least."""
        return self.timing.best_cpu_s / self.requests


@dataclass(frozen=True, slots=True)
class Minimal:
    """The headline: the three clients, each against the same kind of minimal responder."""

    floor: Side
    ours: Side
    pymodbus: Side
    #: The floor's client on the buffered read path, as ours reads (no target).
    floor_buffered: Side

    @property
    def ours_vs_floor(self) -> float:
        """Our requests/s as a share of the floor's (target >= 0.90)."""
        return self.ours.rps / self.floor.rps

    @property
    def ours_vs_buffered_floor(self) -> float:
        """Our requests/s as a share of the buffered floor's (the same read path as ours)."""
        return self.ours.rps / self.floor_buffered.rps

    @property
    def cpu_vs_pymodbus(self) -> float:
        """Our client CPU per round trip as a share of pymodbus's (target <= 0.7)."""
        return self.ours.cpu_s / self.pymodbus.cpu_s


def _peer_minimal(client: AsyncModbusTcpClient, n: int) -> _Batch:
    async def requests() -> int:
        for _ in range(n):
            response = await client.read_holding_registers(0, count=MODBUS_REGISTERS, device_id=1)
            if response.isError() or len(response.registers) != MODBUS_REGISTERS:
                raise RuntimeError(f"pymodbus: unexpected response {response}")
        return n

    return requests


def _runs(runner: asyncio.Runner, batch: _Batch) -> Callable[[], int]:
    return lambda: runner.run(batch())


def measure_minimal(config: Config) -> Minimal:
    """Time the floor, ours and pymodbus, each against its minimal responder, interleaved.

    Raises:
        RuntimeError: a server did not start, or a request went unanswered.
    """
    n = QUICK_REQUESTS if config.quick else REQUESTS
    uvloop = config.loop == "uvloop"
    with (
        ServerProcess("echo", uvloop=uvloop) as floor_server,
        ServerProcess("sj300-minimal", uvloop=uvloop) as ours_server,
        ServerProcess("modbus-minimal", uvloop=uvloop) as peer_server,
        ServerProcess("echo", uvloop=uvloop) as buffered_floor_server,
        new_runner(config.loop) as runner,
    ):
        servers = (floor_server, ours_server, peer_server, buffered_floor_server)
        stack = contextlib.AsyncExitStack()
        try:
            echo = runner.run(connect_echo(floor_server.port))
            buffered_echo = runner.run(connect_echo(buffered_floor_server.port, buffered=True))
            url = f"tcp://127.0.0.1:{ours_server.port}"
            bus = runner.run(stack.enter_async_context(open_bus(url, line=INSTANT_LINE)))
            client = runner.run(_connect_peer(peer_server.port))
            stack.callback(client.close)
            batches = (
                _floor(echo, "status", n),
                _ours(bus.drive(1), "status", n),
                _peer_minimal(client, n),
                _floor(buffered_echo, "status", n),
            )
            before = [server.cpu_seconds() for server in servers]
            timings = interleave([_runs(runner, batch) for batch in batches], config.repeats)
            server_s = [s.cpu_seconds() - b for s, b in zip(servers, before, strict=True)]
            expected = n * (config.repeats + 1)  # every timed run and the warm-up
            if bus.stats.transactions.replies != expected:
                raise RuntimeError(f"ours: {bus.stats.transactions.replies} of {expected} replies")
        finally:
            runner.run(stack.aclose())
    labels = (
        "bare asyncio client (future per request, no parsing)",
        "sj300_async `drive.read_status()`",
        f"pymodbus {version('pymodbus')} `read_holding_registers(count={MODBUS_REGISTERS})`",
        "bare asyncio client on the buffered read path (as ours reads)",
    )
    floor, ours, peer, buffered_floor = (
        Side(label, timing, n, seconds / expected)
        for label, timing, seconds in zip(labels, timings, server_s, strict=True)
    )
    return Minimal(floor, ours, peer, buffered_floor)


def _spread(numerators: Sequence[float], denominators: Sequence[float]) -> str:
    ratios = sorted(a / b for a, b in zip(numerators, denominators, strict=True))
    return (
        f"{ratios[0]:.2f} to {ratios[-1]:.2f}, median {statistics.median(ratios):.2f} "
        f"over {len(ratios)}"
    )


def _minimal_notes(m: Minimal, n: int, repeats: int) -> tuple[str, ...]:
    us = 1e6
    sides = (m.floor, m.ours, m.pymodbus, m.floor_buffered)
    servers = ("`echo`", "`sj300-minimal`", "`modbus-minimal`", "`echo`")
    lines = [
        "**Same minimal responder** (the headline): each client against a bare asyncio server "
        "in its own process that answers every request with one fixed valid reply "
        "(`python -m benchmarks._servers echo | sj300-minimal | modbus-minimal`). "
        f"{n:,} sequential round trips per timed run on 127.0.0.1, the four clients "
        f"interleaved (order rotating), best of {repeats} each; client CPU is "
        "`time.process_time()` of this process over a run, the least of the runs.",
        "",
        "| client | server | req/s | vs floor | wall µs/rt | client CPU µs/rt "
        "| CPU vs pymodbus | server CPU µs/rt |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for side, server in zip(sides, servers, strict=True):
        lines.append(
            f"| {side.label} | {server} | {side.rps:,.0f} | {side.rps / m.floor.rps:.2f} "
            f"| {side.wall_s * us:.1f} | {side.cpu_s * us:.1f} "
            f"| {side.cpu_s / m.pymodbus.cpu_s:.2f} | {side.server_cpu_s * us:.1f} |"
        )

    def verdict(ok: bool) -> str:
        return "met" if ok else "**not met**"

    lines += [
        "",
        f"Targets, this run: ours / floor = {m.ours_vs_floor:.2f} (>= {TARGET_VS_FLOOR:g}: "
        f"{verdict(m.ours_vs_floor >= TARGET_VS_FLOOR)}); our client CPU / pymodbus's = "
        f"{m.cpu_vs_pymodbus:.2f} (<= {TARGET_CPU_VS_PYMODBUS:g}: "
        f"{verdict(m.cpu_vs_pymodbus <= TARGET_CPU_VS_PYMODBUS)}); ours / pymodbus = "
        f"{m.ours.rps / m.pymodbus.rps:.2f}x in requests/s. "
        f"Over the floor per round trip: ours +{(m.ours.wall_s - m.floor.wall_s) * us:.1f} µs "
        f"wall, +{(m.ours.cpu_s - m.floor.cpu_s) * us:.1f} µs client CPU; pymodbus "
        f"+{(m.pymodbus.wall_s - m.floor.wall_s) * us:.1f} µs wall, "
        f"+{(m.pymodbus.cpu_s - m.floor.cpu_s) * us:.1f} µs client CPU.",
        "",
        "Spread, repeat by repeat (the sides of a repeat run next to each other): "
        f"ours / floor {_spread(m.floor.timing.wall_s, m.ours.timing.wall_s)}; our client "
        f"CPU / pymodbus's {_spread(m.ours.timing.cpu_s, m.pymodbus.timing.cpu_s)}.",
        "",
        "Against the same read path (no target): the floor's client on asyncio's buffered "
        "read path, reading into one reused buffer as our adapter does, makes "
        f"{m.floor_buffered.rps:,.0f} req/s at {m.floor_buffered.cpu_s * us:.1f} µs client CPU; "
        f"ours / that floor = {m.ours_vs_buffered_floor:.2f} "
        f"(repeat by repeat {_spread(m.floor_buffered.timing.wall_s, m.ours.timing.wall_s)}), "
        f"+{(m.ours.cpu_s - m.floor_buffered.cpu_s) * us:.1f} µs client CPU over it. "
        "The plain floor's reads allocate 256 KiB each: "
        f"{(m.floor.cpu_s - m.floor_buffered.cpu_s) * us:+.1f} µs client CPU per round trip "
        "against the buffered floor in this run (the cost depends on whether glibc serves "
        "that size by `mmap`: the allocator line of the run's environment says how it was "
        "set up, `benchmarks/_allocator.py` why).",
    ]
    return tuple(lines)


def _minimal_results(m: Minimal) -> list[Result]:
    us = 1e6
    peer = f"pymodbus {version('pymodbus')}"
    return [
        Result(
            "tcp: read_status vs bare asyncio floor, same minimal responder",
            m.ours.rps,
            m.floor.rps,
            "requests/s",
            TARGET_VS_FLOOR,
            against="bare asyncio floor",
            percent=True,
        ),
        Result(
            "tcp: client CPU per round trip, read_status vs read_holding_registers(count=4), "
            "minimal responders",
            m.ours.cpu_s * us,
            m.pymodbus.cpu_s * us,
            "µs",
            1 / TARGET_CPU_VS_PYMODBUS,
            higher_is_better=False,
            against=peer,
            as_multiple=True,
        ),
        Result(
            "tcp: read_status vs read_holding_registers(count=4), minimal responders",
            m.ours.rps,
            m.pymodbus.rps,
            "requests/s",
            against=peer,
        ),
        Result(
            "tcp: read_status vs bare asyncio floor on the same (buffered) read path",
            m.ours.rps,
            m.floor_buffered.rps,
            "requests/s",
            against="buffered asyncio floor",
            percent=True,
        ),
        Result(
            "tcp floor: bare asyncio round trip vs pymodbus, minimal responders",
            m.floor.rps,
            m.pymodbus.rps,
            "requests/s",
            against=peer,
        ),
        Result(
            "tcp floor: client CPU per bare asyncio round trip vs pymodbus, minimal responders",
            m.floor.cpu_s * us,
            m.pymodbus.cpu_s * us,
            "µs",
            higher_is_better=False,
            against=peer,
            as_multiple=True,
        ),
    ]


def run(config: Config) -> Section:
    """Measure sequential TCP round trips: the minimal responders, then each stack's server."""
    n = QUICK_REQUESTS if config.quick else REQUESTS
    minimal = measure_minimal(config)
    rates = measure(config)
    notes: tuple[str, ...] = (
        *_minimal_notes(minimal, n, config.repeats),
        "",
        "**Each stack on its own server** (the second table; these rows time the servers "
        "as much as the clients, so they carry no target):",
        "",
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
    results = _minimal_results(minimal)
    for r in rates:
        results += [
            Result(f"tcp: {r.label}", r.ours_rps, r.peer_rps, "requests/s"),
            Result(
                f"tcp floor: bare asyncio round trip, {r.label.split()[0]} sizes",
                r.floor_rps,
                r.peer_vs_floor_rps,
                "requests/s",
            ),
        ]
    return Section(TITLE, notes, tuple(results))
