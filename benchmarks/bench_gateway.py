"""Gateway: Modbus reads served from the poll cache, against pymodbus's own server.

Two figures, each from one run:

1. **Reads per second**, the gateway (:mod:`sj300_async.gateway`) against
   pymodbus's ``ModbusTcpServer`` holding the same registers. Each server
   runs in a process of its own (this module is also their script:
   ``python -m benchmarks.bench_gateway gateway|pymodbus``), so the client's
   CPU is not shared with a server's event loop, as in
   :mod:`benchmarks._servers`; each prints ``port N`` once it is ready and
   serves until its standard input closes.
2. **The gateway's added wire traffic**: requests that reached the simulated
   line while clients read, less what the poll plan made in the same time,
   per 1,000 Modbus reads. It must be 0: a read is served from the cache.

Decisions:

- **The line**: ``sim://?nodes=1-8&baudrate=19200``, the in-memory
  simulator in the gateway's process, not a ``serve_tcp`` simulator behind a
  socket. It is simpler (no third process, no port), and the polls cost the
  gateway process what they cost in real life: the bus, the arbiter, the
  decoding, the samples fed to the cache. With a baud rate and no
  ``pace=1``, replies come no sooner than a 19200-baud line could carry them
  (a realistic poll rate) without the per-character timers of a paced line,
  which would charge the gateway for work a UART does; the drives keep the
  simulator's default 1 ms of processing. 8 drives, status and monitor
  every 0.5 s (the configuration's default interval), no parameters, and no
  trip-history or set-frequency reads beside the poll (``trips_interval_s =
  0``, ``setpoint_interval_s = 0``), so that the poll plan's requests are
  exactly two per poll (see below). The simulated drives are
  stopped: the registers read are zeros, the same work for the register
  map as any other value.
- **The peer**: pymodbus's ``ModbusTcpServer`` with one ``SimDevice`` per
  unit id 1..8, each holding one ``SimData`` block of 14 holding registers
  at address 100 with the values the gateway serves there (read from the
  gateway once before timing; pymodbus 3.16's datastore API, the older
  ``ModbusServerContext`` blocks are deprecated).
- **The client**: one pymodbus ``AsyncModbusTcpClient`` per server, in this
  process, connected before timing; a timed run is N sequential
  ``read_holding_registers(100, count=14, device_id=u)``, u cycling over
  1..8, each awaited before the next and checked against the expected
  values. One sequential client is how a SCADA or an HMI polls a Modbus TCP
  gateway (one outstanding transaction per connection; several masters
  are several such connections), and it is what a master feels: the round
  trip; the target is for this row. A second row runs
  :data:`CONCURRENT_CLIENTS` such clients at once (each N / k reads),
  several masters on one gateway: there the servers' CPU per read decides
  more of the wall time (on a 2-CPU machine the clients' process is busy
  too, so it is information, without a target). Both servers get the same
  reads, and the two sides alternate their order from one repeat to the
  next (gateway first, then pymodbus first...), best of the repeats after
  one untimed run each.
- **Counting the line's requests**: the simulator's own counter
  (``SimulatedBus.stats.requests``: what reached the drives). The poll plan's
  count is computed, not estimated from a second run without clients (whose
  poll rate need not be the same as under load): the gateway
  process registers an ``on_sample`` callback and, at the end of a poll
  cycle (the last drive's sample: its reads are answered, the next cycle has
  not started), takes a *mark*: the simulator's request count, the polls so
  far and the Modbus requests served so far. Between two marks the plan made
  exactly ``2 x polls`` requests (status and monitor per poll; a failed
  poll, and the probes and resyncs after it, would break that, so a window
  with a failed poll fails the benchmark). The window spans every read of
  the gateway's side, warm-up included, and its Modbus request count must
  equal what this process sent.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import json
import sys
import textwrap
import time
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from importlib.metadata import version
from typing import TYPE_CHECKING, Any, Literal, Protocol, cast

from pymodbus.client import AsyncModbusTcpClient

from ._harness import Config, Result, Section, new_runner
from ._servers import ServerProcess

if TYPE_CHECKING:
    from sj300_async.gateway import Gateway
    from sj300_async.gateway.modbus import ClientCounters

__all__ = [
    "CONCURRENT_CLIENTS",
    "DRIVES",
    "READS",
    "TITLE",
    "USES_EVENT_LOOP",
    "GatewayRun",
    "Mark",
    "Rate",
    "main",
    "measure",
    "report",
    "run",
]

TITLE = "gateway"
USES_EVENT_LOOP = True
#: Sequential reads per timed run, full and ``--quick``.
READS = 2_000
QUICK_READS = 48
#: Drives on the line, Modbus units 1..DRIVES.
DRIVES = 8
#: The read: the monitor block, output frequency to power-on time.
ADDRESS = 100
COUNT = 14
#: Clients reading at once in the second row, each sequential.
CONCURRENT_CLIENTS = 4
#: The poll plan's interval, full and ``--quick`` (shorter: the marks wait for a cycle's end).
INTERVAL_S = 0.5
QUICK_INTERVAL_S = 0.1
#: The project's aims: reads/s as a multiple of pymodbus's server (at least as fast: the
#: gateway's own Modbus server replaced pymodbus's, issue 26); extra line requests.
TARGET_RATIO = 1.0
#: Requests each poll makes (status and monitor), with no parameters in the plan.
REQUESTS_PER_POLL = 2

ServerKind = Literal["gateway", "pymodbus"]
# The folder that holds the benchmarks package, as this process found it.


# -- the servers' side (their processes) ------------------------------------------------


class _ModbusServing(Protocol):
    """What this benchmark reads of the running Modbus northbound (``gateway.northbounds``).

    Its class is not part of the gateway's public face; these two attributes are.
    """

    @property
    def port(self) -> int: ...

    @property
    def clients(self) -> ClientCounters: ...


def _modbus(gateway: Gateway) -> _ModbusServing:
    return cast(_ModbusServing, gateway.northbounds["modbus"])


def _gateway_toml(drives: int, interval_s: float) -> str:
    return textwrap.dedent(
        f"""
        [modbus]
        listen = "127.0.0.1:0"
        [[lines]]
        name = "bench"
        url = "sim://?nodes=1-{drives}&baudrate=19200"
        nodes = "1-{drives}"
        interval_s = {interval_s!r}
        trips_interval_s = 0
        setpoint_interval_s = 0
        """
    )


class _CycleMarks:
    """Marks taken in the gateway's process at the end of a poll cycle (module docstring)."""

    def __init__(self, gateway: Gateway) -> None:
        line = gateway.lines[0]
        self._modbus = _modbus(gateway)
        self._simulator = line.bus.simulator
        self._last_node: int = line.config.nodes[-1]
        self._waiting: list[asyncio.Future[str]] = []
        self.polls = 0
        self.failed = 0
        line.poller.on_sample(self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        self.polls += 1
        if sample.error is not None:
            self.failed += 1
        if sample.node != self._last_node:
            return
        # The cycle's last poll is answered and the next has not started: the
        # line is quiet, and every request so far belongs to a counted poll.
        served = sum(self._modbus.clients.requests.values())
        mark = f"mark {self._simulator.stats.requests} {self.polls} {self.failed} {served}"
        waiting, self._waiting = self._waiting, []
        for future in waiting:
            if not future.done():
                future.set_result(mark)

    async def next(self) -> str:
        """The mark at the end of the next poll cycle."""
        future: asyncio.Future[str] = asyncio.get_running_loop().create_future()
        self._waiting.append(future)
        return await future


def _answer_parent(loop: asyncio.AbstractEventLoop, marks: _CycleMarks | None) -> None:
    """Answer ``cpu`` (and ``mark`` on the gateway) on standard input until it closes."""
    for line in sys.stdin:
        command = line.strip()
        if command == "cpu":
            print(f"cpu {time.process_time()!r}", flush=True)
        elif command == "mark" and marks is not None:
            print(asyncio.run_coroutine_threadsafe(marks.next(), loop).result(), flush=True)
        else:
            print(f"unknown {command}", flush=True)


async def _serve_gateway(drives: int, interval_s: float) -> None:
    from sj300_async.gateway import Gateway, parse_config

    config = parse_config(_gateway_toml(drives, interval_s), "bench_gateway.toml")
    async with Gateway(config, tune_collector=True) as gateway:
        marks = _CycleMarks(gateway)
        await marks.next()  # ready: every drive polled once
        print(f"port {_modbus(gateway).port}", flush=True)
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, _answer_parent, loop, marks)


async def _serve_pymodbus(registers: dict[int, list[int]]) -> None:
    from pymodbus.server import ModbusTcpServer
    from pymodbus.simulator import DataType, SimData, SimDevice

    devices = [
        SimDevice(unit, [SimData(ADDRESS, values=values, datatype=DataType.REGISTERS)])
        for unit, values in sorted(registers.items())
    ]
    server = ModbusTcpServer(devices, address=("127.0.0.1", 0))
    await server.serve_forever(background=True)
    listener: Any = server.transport  # asyncio.Server, or uvloop's own Server
    print(f"port {listener.sockets[0].getsockname()[1]}", flush=True)
    try:
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, _answer_parent, loop, None)
    finally:
        await server.shutdown()  # type: ignore[no-untyped-call]


def main(argv: Sequence[str] | None = None) -> int:
    """A server process's entry point: serve until standard input closes."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_gateway")
    parser.add_argument("kind", choices=("gateway", "pymodbus"))
    parser.add_argument("--uvloop", action="store_true", help="serve on uvloop")
    parser.add_argument("--drives", type=int, default=DRIVES, help="gateway: drives 1..N")
    parser.add_argument("--interval", type=float, default=INTERVAL_S, help="gateway: poll cycle")
    parser.add_argument("--registers", default="{}", help="pymodbus: JSON {unit: [values]}")
    args = parser.parse_args(argv)
    serve: Coroutine[Any, Any, None]
    if args.kind == "gateway":
        serve = _serve_gateway(args.drives, args.interval)
    else:
        registers = {int(unit): values for unit, values in json.loads(args.registers).items()}
        serve = _serve_pymodbus(registers)
    if args.uvloop:
        import uvloop

        uvloop.run(serve)
    else:
        asyncio.run(serve)
    return 0


# -- the parent's side ---------------------------------------------------------------------


def _server(kind: ServerKind, args: Sequence[str], *, uvloop: bool) -> ServerProcess:
    """A server of this module in a child process (``_servers.ServerProcess`` runs it)."""
    return ServerProcess(kind, uvloop=uvloop, module="benchmarks.bench_gateway", args=args)


@dataclass(frozen=True, slots=True)
class Mark:
    """Counters the gateway process took at the end of a poll cycle."""

    #: Requests that reached the simulated line (the simulator's count).
    line_requests: int
    #: Polls made (samples published) and, of them, failed ones.
    polls: int
    failed_polls: int
    #: Modbus requests the gateway served.
    modbus_requests: int

    @classmethod
    def take(cls, gateway: ServerProcess) -> Mark:
        line_requests, polls, failed, served = (int(word) for word in gateway.ask("mark"))
        return cls(line_requests, polls, failed, served)


@dataclass(frozen=True, slots=True)
class Rate:
    """One client set-up: reads/s of each server, and each server's CPU per read."""

    label: str
    clients: int
    gateway_rps: float
    peer_rps: float
    #: Mean server CPU seconds per read over every run, warm-up included: (gateway, pymodbus).
    server_cpu_s: tuple[float, float]


@dataclass(frozen=True, slots=True)
class GatewayRun:
    """What :func:`measure` found: the rates, and the line's requests during the reads."""

    rates: tuple[Rate, ...]
    #: Marks at the start and the end of the window that holds every gateway read.
    start: Mark
    end: Mark
    #: Reads this process sent to the gateway in the window.
    reads: int

    @property
    def line_requests(self) -> int:
        return self.end.line_requests - self.start.line_requests

    @property
    def plan_requests(self) -> int:
        """What the poll plan made in the window: two requests per poll."""
        return REQUESTS_PER_POLL * (self.end.polls - self.start.polls)

    @property
    def extra_per_1000_reads(self) -> float:
        return (self.line_requests - self.plan_requests) * 1000 / self.reads


#: A timed run: reads of each client, concurrently; returns the reads made.
_Batch = Callable[[], Coroutine[Any, Any, int]]


def _reads(
    clients: Sequence[AsyncModbusTcpClient], n: int, expected: dict[int, list[int]]
) -> _Batch:
    units = sorted(expected)

    async def one(client: AsyncModbusTcpClient, reads: int, first: int) -> None:
        for i in range(first, first + reads):
            unit = units[i % len(units)]
            response = await client.read_holding_registers(ADDRESS, count=COUNT, device_id=unit)
            if response.isError() or response.registers != expected[unit]:
                raise RuntimeError(f"unit {unit}: unexpected response {response}")

    async def reads() -> int:
        each = n // len(clients)
        await asyncio.gather(*(one(c, each, k) for k, c in enumerate(clients)))
        return each * len(clients)

    return reads


def _alternate(
    runner: asyncio.Runner, ours: _Batch, peer: _Batch, repeats: int
) -> tuple[float, float, int]:
    """Best wall time of each side, their order alternating per repeat; and reads per run.

    One untimed run of each first; then repeat i runs the gateway first when
    i is even, pymodbus first when it is odd.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    reads = runner.run(ours())
    runner.run(peer())
    best = [float("inf"), float("inf")]
    sides = ((0, ours), (1, peer))
    for i in range(repeats):
        for side, batch in sides if i % 2 == 0 else sides[::-1]:
            gc.collect()  # neither side pays for the other's garbage
            start = time.perf_counter()
            runner.run(batch())
            best[side] = min(best[side], time.perf_counter() - start)
    return best[0], best[1], reads


async def _connect(
    stack: contextlib.AsyncExitStack, port: int, clients: int
) -> list[AsyncModbusTcpClient]:
    """*clients* connected clients, each closed by *stack*."""
    out = []
    for _ in range(clients):
        client = AsyncModbusTcpClient("127.0.0.1", port=port)  # needs the running loop
        stack.callback(client.close)
        if not await client.connect():
            raise RuntimeError(f"pymodbus could not connect to port {port}")
        out.append(client)
    return out


async def _gateway_registers(client: AsyncModbusTcpClient) -> dict[int, list[int]]:
    registers = {}
    for unit in range(1, DRIVES + 1):
        response = await client.read_holding_registers(ADDRESS, count=COUNT, device_id=unit)
        if response.isError():
            raise RuntimeError(f"gateway unit {unit}: {response}")
        registers[unit] = list(response.registers)
    return registers


def measure(config: Config) -> GatewayRun:
    """Time both servers with one client, then with several; count the line's requests.

    Raises:
        RuntimeError: a server did not start, a read failed or read something
            else, a poll failed, or the gateway served another number of reads
            than were sent.
    """
    n = QUICK_READS if config.quick else READS
    interval = QUICK_INTERVAL_S if config.quick else INTERVAL_S
    uvloop = config.loop == "uvloop"
    gateway_args = ["--drives", str(DRIVES), "--interval", repr(interval)]
    rates: list[Rate] = []
    processes = contextlib.ExitStack()
    clients = contextlib.AsyncExitStack()
    # Closed in this order: the clients (on the loop), the loop, the server processes.
    with processes, new_runner(config.loop) as runner:
        try:
            gateway = processes.enter_context(_server("gateway", gateway_args, uvloop=uvloop))
            ours = runner.run(_connect(clients, gateway.port, CONCURRENT_CLIENTS))
            expected = runner.run(_gateway_registers(ours[0]))
            peer_args = ["--registers", json.dumps(expected)]
            peer_server = processes.enter_context(_server("pymodbus", peer_args, uvloop=uvloop))
            peers = runner.run(_connect(clients, peer_server.port, CONCURRENT_CLIENTS))
            start = Mark.take(gateway)
            sent = 0
            for k in (1, CONCURRENT_CLIENTS):
                cpu_before = gateway.cpu_seconds(), peer_server.cpu_seconds()
                t_ours, t_peer, reads = _alternate(
                    runner,
                    _reads(ours[:k], n, expected),
                    _reads(peers[:k], n, expected),
                    config.repeats,
                )
                done = reads * (config.repeats + 1)
                sent += done
                cpu = (
                    (gateway.cpu_seconds() - cpu_before[0]) / done,
                    (peer_server.cpu_seconds() - cpu_before[1]) / done,
                )
                label = "1 client" if k == 1 else f"{k} clients at once"
                rates.append(Rate(label, k, reads / t_ours, reads / t_peer, cpu))
            end = Mark.take(gateway)
        finally:
            runner.run(clients.aclose())
    if end.failed_polls != start.failed_polls:
        raise RuntimeError(f"{end.failed_polls - start.failed_polls} polls failed: no plan count")
    if end.modbus_requests - start.modbus_requests != sent:
        raise RuntimeError(
            f"the gateway served {end.modbus_requests - start.modbus_requests} of {sent} reads"
        )
    return GatewayRun(tuple(rates), start, end, sent)


def run(config: Config) -> Section:
    """Measure the gateway's Modbus reads against pymodbus's server, and its line traffic."""
    return report(measure(config), config)


def report(result: GatewayRun, config: Config) -> Section:
    """The notes and rows of a measurement made with *config*."""
    n = QUICK_READS if config.quick else READS
    interval = QUICK_INTERVAL_S if config.quick else INTERVAL_S
    us = 1e6
    notes: tuple[str, ...] = (
        f"{n:,} `read_holding_registers({ADDRESS}, count={COUNT}, device_id=u)` per timed run, "
        f"u cycling over 1..{DRIVES}, by one client, then by {CONCURRENT_CLIENTS} clients at "
        f"once ({n // CONCURRENT_CLIENTS:,} each); each client sequential, in this process; "
        "each server in a process of its own, on 127.0.0.1; the two sides' order alternates "
        "from one repeat to the next.",
        f"Gateway: `sim://?nodes=1-{DRIVES}&baudrate=19200` in its process (replies no sooner "
        "than a 19200-baud line allows, drives' default 1 ms processing), polling status and "
        f"monitor of {DRIVES} drives every {interval:g} s, no trip-history reads; reads served "
        f"from its poll cache. pymodbus {version('pymodbus')}: `ModbusTcpServer` with a "
        f"`SimDevice` per unit 1..{DRIVES}, each one `SimData` block of the same {COUNT} "
        f"registers at {ADDRESS} (the values read from the gateway).",
        "",
        "| clients | wall µs/read gateway | pymodbus | server CPU µs/read gateway | pymodbus |",
        "|---|---:|---:|---:|---:|",
        *(
            f"| {r.label} | {us / r.gateway_rps:.0f} | {us / r.peer_rps:.0f} "
            f"| {r.server_cpu_s[0] * us:.0f} | {r.server_cpu_s[1] * us:.0f} |"
            for r in result.rates
        ),
        "",
        "Server CPU per read is the mean over every run, warm-up included; the gateway's "
        "includes its polling in the meantime.",
        "",
        f"Line traffic: {result.reads:,} Modbus reads served by the gateway between two "
        f"marks taken at the end of a poll cycle; the simulated line got "
        f"{result.line_requests:,} requests, the poll plan made {result.plan_requests:,} "
        f"({result.end.polls - result.start.polls:,} polls x {REQUESTS_PER_POLL}): "
        f"{result.line_requests - result.plan_requests:+,} beyond the plan.",
    )
    results: list[Result] = [
        Result(
            f"gateway: Modbus reads from the cache, {r.label} (vs pymodbus's server)",
            r.gateway_rps,
            r.peer_rps,
            "reads/s",
            TARGET_RATIO if r.clients == 1 else None,
        )
        for r in result.rates
    ]
    results.append(
        Result(
            "gateway: line requests beyond the poll plan, per 1,000 Modbus reads",
            result.extra_per_1000_reads,
            0.0,
            "requests",
            1.0,
            higher_is_better=False,
            against="limit",
        )
    )
    return Section(TITLE, notes, tuple(results))


if __name__ == "__main__":
    sys.exit(main())
