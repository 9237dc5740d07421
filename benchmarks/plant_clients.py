"""The clients of bench_plant's ``all`` gateway: one process beside it, reading every northbound.

bench_plant's gateway child starts this process once its servers listen
(``python -m benchmarks.plant_clients ...``, the arguments made by
:func:`arguments`) and stops it after its measured windows. It is a process
of its own so that what the clients cost is not counted in the gateway's
``process_time``; one event loop runs every client, and nothing is logged
per message.

The conversation on its standard streams:

- it prints ``ready SECONDS`` once every client is connected and
  subscribed (or has failed: its failure is in the results);
- ``start`` on its standard input opens the window: from then on every
  message's delay is recorded;
- ``stop`` (or the end of its input) closes it: the clients are closed and
  one JSON line of results is printed (:func:`results`), then it exits.

The clients, each optional (a client whose option is absent is not run):

- **MQTT JSON** (``--mqtt``): subscribed to every drive's state topic of
  the gateway (QoS 0); the delay is the time the message is handled minus
  the state's ``time``. The retained states the broker hands over on
  subscribing are not samples just sent, and are skipped.
- **Sparkplug** (``--sparkplug``, on the same broker): subscribed to the
  group's DDATA and DBIRTH topics, every edge node; each payload decoded
  with :func:`~sj300_async.gateway.sparkplug.decode_payload`, the delay
  measured from its timestamp (the sample's, in milliseconds). The devices
  born while it listens are counted.
- **OPC UA** (``--opcua``): one subscription (publishing interval
  :data:`PUBLISHING_MS`) with a data-change item on each drive's
  ``Monitoring/ConverterOutputFrequency`` (which the ramp changes at every
  poll); the delay is measured from the value's SourceTimestamp.
- **The workbench** (``--http``): :data:`EVENT_STREAMS` event streams on
  ``/api/v1/events``, which carry every drive's updates; the delay is
  measured from the drive's ``time``.
- **Modbus** (``--modbus``, one per listener): a pymodbus master per
  listener reads each of its units' monitor (100..113) and status
  (200..204) blocks once a second, the listeners' sweeps spread over the
  second; with ``--summary``, it reads its units' records in the
  listener's summary (unit 255) instead, 120 registers a read (15 drives).
  Modbus carries no time of the sample but register 1, the
  sample's age in whole seconds: too coarse for a delay within one poll
  interval, so the figures are reads per second, errors, and the sweeps
  that overran their second.

Every delay is this process's ``time.time()`` when the message is handled
minus the sample's time as the northbound carries it: one realtime clock,
the machine's. It includes this process's own lag (its event loop behind
the messages): the loop's lag over the window is in the results too.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import json
import logging
import os
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from sj300_async.gateway.modbus import SUMMARY_RECORD, SUMMARY_UNIT

from .bench_opcua import percentile

__all__ = [
    "EVENT_STREAMS",
    "MODBUS_BLOCKS",
    "PUBLISHING_MS",
    "Tally",
    "Window",
    "arguments",
    "main",
    "parse_ranges",
    "ranges",
    "results",
]

#: The OPC UA subscription's publishing interval: a tenth of the poll interval, so that it
#: adds at most 0.1 s to a delay without waking the server's publishing twenty times a second.
PUBLISHING_MS: Final = 100.0
#: Event streams open on the workbench (a tab holds one: two tabs).
EVENT_STREAMS: Final = 2
#: What a Modbus master reads of each unit every second: (address, count).
MODBUS_BLOCKS: Final = ((100, 14), (200, 5))
#: Registers a read of the summary asks for: 15 whole records (function 3 reads 125 at
#: most), so that each drive's record comes from one answer.
MAX_READ: Final = 15 * SUMMARY_RECORD
#: A Modbus master's sweep of its units, once a second.
SWEEP_S: Final = 1.0
#: How long the clients may take to subscribe (OPC UA's items on a busy server).
READY_TIMEOUT_S: Final = 90.0
#: How long the clients get to close once their figures are out.
CLOSE_TIMEOUT_S: Final = 5.0
#: How often the event loop's lag is sampled.
LAG_TICK_S: Final = 0.05
#: The MQTT topics' prefix (the gateway's default) and Sparkplug's namespace.
PREFIX: Final = "sj300"
SPARKPLUG: Final = "spBv1.0"


# -- what is counted ---------------------------------------------------------------------------


@dataclass(slots=True)
class Window:
    """Whether delays are recorded now (between ``start`` and ``stop``), and for how long."""

    open: bool = False
    began: float = 0.0
    seconds: float = 0.0
    cpu_s: float = 0.0

    def start(self) -> None:
        self.open, self.began, self.cpu_s = True, time.perf_counter(), time.process_time()

    def stop(self) -> None:
        if self.open:
            self.open = False
            self.seconds = time.perf_counter() - self.began
            self.cpu_s = time.process_time() - self.cpu_s


@dataclass(slots=True)
class Tally:
    """One client's counts: every message, and each one's delay while the window is open."""

    window: Window
    #: Messages handled since the client subscribed.
    received: int = 0
    #: Messages that could not be read (no time, not the format), and refused items.
    errors: int = 0
    #: Every drive heard from (a key per drive, whatever the client names it by).
    drives: set[object] = field(default_factory=set)
    #: Seconds from each sample to its message, in the window.
    delays: list[float] = field(default_factory=list)
    failure: str | None = None

    def record(self, drive: object, sampled: float) -> None:
        """A message of *drive*'s sample taken at Unix time *sampled*."""
        self.received += 1
        self.drives.add(drive)
        if self.window.open:
            self.delays.append(time.time() - sampled)

    def figures(self) -> dict[str, Any]:
        delays = sorted(self.delays)
        ms = 1e3

        def at(p: float) -> float | None:
            return percentile(delays, p) * ms if delays else None

        return {
            "messages": len(delays),
            "received": self.received,
            "drives": len(self.drives),
            "errors": self.errors,
            "p50_ms": at(50),
            "p99_ms": at(99),
            "max_ms": at(100),
            "failure": self.failure,
        }


@dataclass(slots=True)
class ModbusTally:
    """The Modbus masters' counts, in the window (their reads carry no sample time)."""

    window: Window
    #: Masters (one per listener).
    masters: int = 0
    #: They read the summary (unit 255), not each unit.
    summary: bool = False
    #: Reads due per sweep, every master's.
    due: int = 0
    reads: int = 0
    #: Exception replies by code, and requests that got no reply (``"transport"``).
    errors: dict[str, int] = field(default_factory=dict)
    #: Sweeps that took longer than their second, and each sweep's time (s).
    late: int = 0
    sweeps: list[float] = field(default_factory=list)
    failure: str | None = None

    def error(self, kind: str) -> None:
        if self.window.open:
            self.errors[kind] = self.errors.get(kind, 0) + 1

    def figures(self) -> dict[str, Any]:
        seconds = self.window.seconds
        sweeps = sorted(self.sweeps)
        return {
            "masters": self.masters,
            "summary": self.summary,
            "due_per_s": self.due / SWEEP_S,
            "reads": self.reads,
            "reads_per_s": self.reads / seconds if seconds else None,
            "errors": self.errors,
            "late_sweeps": self.late,
            "sweep_p99_ms": percentile(sweeps, 99) * 1e3 if sweeps else None,
            "failure": self.failure,
        }


_PER_CALL: Final = 11714  # Server_ServerCapabilities_OperationLimits_MaxMonitoredItemsPerCall


async def _guarded(
    tally: Tally | ModbusTally, client: Awaitable[None], ready: asyncio.Event
) -> None:
    """Run *client* (which sets *ready* once subscribed) until cancelled; a failure is kept
    in its tally, not raised.

    A client that fails counts as ready, so that the others are measured and
    the failure is reported rather than waited for.
    """
    try:
        await client
    except asyncio.CancelledError:
        raise
    except Exception as exc:
        while isinstance(exc, ExceptionGroup):  # a task group's: the first is the cause
            exc = exc.exceptions[0]
        tally.failure = f"{type(exc).__name__}: {exc}"
    finally:
        ready.set()


# -- the clients -------------------------------------------------------------------------------


def _mqtt_client(port: int, name: str) -> Any:
    from sj300_async.gateway.mqttlink.client import Client

    # Read only, one reader each: the broker's queue limit is off (bench_mqtt._mosquitto).
    return Client("127.0.0.1", port, identifier=f"plant-clients-{os.getpid()}-{name}")


async def mqtt_states(port: int, gateway: str, tally: Tally, ready: asyncio.Event) -> None:
    """Every drive's JSON state of *gateway*: the delay from its ``time``."""
    async with _mqtt_client(port, "json") as client:
        await client.subscribe(f"{PREFIX}/{gateway}/+/+/state", qos=0)
        ready.set()
        async for message in client.messages:
            if message.retain:  # the broker's stored state, handed over on subscribing
                continue
            try:
                sampled = json.loads(message.payload)["time"]
                tally.record(message.topic, float(sampled))
            except (ValueError, KeyError, TypeError):
                tally.errors += 1


async def sparkplug(
    port: int, group: str, tally: Tally, births: set[str], ready: asyncio.Event
) -> None:
    """The group's DDATA and DBIRTH messages, every edge node's: the delay from the payload's
    timestamp; *births* gets each device born (``node/device``)."""
    from sj300_async.gateway.sparkplug import MalformedPayload, decode_payload

    filters = [(f"{SPARKPLUG}/{group}/{kind}/+/+", 0) for kind in ("DDATA", "DBIRTH")]
    async with _mqtt_client(port, "spb") as client:
        await client.subscribe(filters)
        ready.set()
        async for message in client.messages:
            parts = message.topic.split("/")
            device = f"{parts[3]}/{parts[4]}"
            if parts[2] == "DBIRTH":
                births.add(device)
            try:
                stamp = decode_payload(message.payload).timestamp_ms
            except MalformedPayload:
                stamp = None
            if stamp is None:
                tally.errors += 1
            else:
                tally.record(device, stamp / 1e3)


class _DataChange:
    """The OPC UA subscription's handler: one delay per notification."""

    def __init__(self, tally: Tally) -> None:
        self.tally = tally

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        source = data.monitored_item.Value.SourceTimestamp
        if source is None:
            self.tally.errors += 1
        else:  # asyncua's datetimes are UTC-aware: timestamp() is Unix time
            self.tally.record(node.nodeid.Identifier, source.timestamp())


async def opcua(
    url: str,
    namespace: str,
    drives: Sequence[tuple[str, int]],
    tally: Tally,
    ready: asyncio.Event,
) -> None:
    """One subscription, an item on each drive's output frequency: the delay from its
    SourceTimestamp."""
    from asyncua import Client, ua

    client = Client(url, timeout=30)
    async with client:
        index = await client.get_namespace_index(namespace)
        subscription = await client.create_subscription(PUBLISHING_MS, _DataChange(tally))
        nodes = [
            client.get_node(
                ua.NodeId(f"{line}/Drive{node}/Monitoring/ConverterOutputFrequency", index)
            )
            for line, node in drives
        ]
        # As a well-behaved client: no more items a request than the server advertises.
        limit = await client.get_node(ua.NodeId(_PER_CALL)).read_value() or len(nodes)
        created: list[Any] = []
        for start in range(0, len(nodes), limit):
            created += await subscription.subscribe_data_change(
                nodes[start : start + limit], sampling_interval=0.0
            )
        refused = [item for item in created if isinstance(item, ua.StatusCode)]
        if refused:  # the run would load OPC UA less than it says: it fails (in the notes)
            tally.errors += len(refused)
            raise RuntimeError(f"{len(refused)} of {len(nodes)} monitored items refused: "
                               f"{refused[0]}")  # fmt: skip
        ready.set()
        await asyncio.Event().wait()  # until cancelled: the handler does the work


async def event_streams(port: int, streams: int, tally: Tally, ready: asyncio.Event) -> None:
    """*streams* event streams on the workbench: the delay from each drive event's ``time``."""
    import aiohttp

    # No time-out on reading: a stream is one response that never ends.
    timeout = aiohttp.ClientTimeout(total=None, sock_read=None)
    async with aiohttp.ClientSession(timeout=timeout) as session, asyncio.TaskGroup() as group:
        opened = [asyncio.Event() for _ in range(streams)]
        for event in opened:
            group.create_task(_event_stream(session, port, tally, event))
        for event in opened:  # a stream that fails first cancels this wait (the group's rule)
            await event.wait()
        ready.set()


async def _event_stream(session: Any, port: int, tally: Tally, opened: asyncio.Event) -> None:
    async with session.get(f"http://127.0.0.1:{port}/api/v1/events") as response:
        response.raise_for_status()
        opened.set()
        rest = b""
        # Whole chunks, split into events here: one call per chunk, not per line.
        async for chunk in response.content.iter_any():
            *frames, rest = (rest + chunk).split(b"\n\n")
            for frame in frames:
                _drive_event(frame, tally)
    raise RuntimeError("the event stream ended")


def _drive_event(frame: bytes, tally: Tally) -> None:
    if not frame.startswith(b"event: drive\n"):
        return  # the gateway's and the lines' events, the retry line, keep-alive comments
    try:
        body = json.loads(frame.partition(b"\ndata: ")[2])
        sampled = body["time"]
        if sampled is not None:  # a drive never sampled yet: no delay to measure
            tally.record((body["line"], body["node"]), float(sampled))
    except (ValueError, KeyError, TypeError):
        tally.errors += 1


def summary_reads(units: Sequence[int]) -> list[tuple[int, int]]:
    """The reads of the summary (unit 255) that cover *units*' records: (address, count),
    at most :data:`MAX_READ` registers each."""
    first, end = SUMMARY_RECORD * min(units), SUMMARY_RECORD * (max(units) + 1)
    return [(a, min(MAX_READ, end - a)) for a in range(first, end, MAX_READ)]


async def modbus_master(
    port: int,
    units: Sequence[int],
    start_s: float,
    summary: bool,
    tally: ModbusTally,
    ready: asyncio.Event,
) -> None:
    """Read every unit's :data:`MODBUS_BLOCKS` each second, or with *summary* the records of
    every unit in the listener's summary; the first sweep at *start_s* (loop time)."""
    from pymodbus.client import AsyncModbusTcpClient

    client = AsyncModbusTcpClient("127.0.0.1", port=port)
    try:
        if not await client.connect():
            raise RuntimeError(f"no Modbus connection to port {port}")
        ready.set()
        loop = asyncio.get_running_loop()
        reads = summary_reads(units)
        due = start_s
        while True:
            await asyncio.sleep(max(0.0, due - loop.time()))
            began = loop.time()
            if summary:
                await _sweep_summary(client, reads, tally)
            else:
                await _sweep(client, units, tally)
            if tally.window.open:
                tally.sweeps.append(loop.time() - began)
            due += SWEEP_S
            if loop.time() > due:  # overran its second: the next starts now, not in a burst
                tally.late += tally.window.open
                due = loop.time()
    finally:
        client.close()


async def _sweep(client: Any, units: Sequence[int], tally: ModbusTally) -> None:
    for unit in units:
        for address, count in MODBUS_BLOCKS:
            await _read(client, unit, address, count, tally)


async def _sweep_summary(client: Any, reads: Sequence[tuple[int, int]], tally: ModbusTally) -> None:
    for address, count in reads:
        await _read(client, SUMMARY_UNIT, address, count, tally)


async def _read(client: Any, unit: int, address: int, count: int, tally: ModbusTally) -> None:
    from pymodbus.exceptions import ModbusException

    try:
        response = await client.read_holding_registers(address, count=count, device_id=unit)
    except ModbusException:
        tally.error("transport")
        return
    if response.isError():
        tally.error(f"0x{response.exception_code:02X}")
    elif tally.window.open:
        tally.reads += 1


async def _loop_lag(window: Window, lags: list[float]) -> None:
    """How late this process's event loop wakes a timer, in the window."""
    loop = asyncio.get_running_loop()
    while True:
        began = loop.time()
        await asyncio.sleep(LAG_TICK_S)
        if window.open:
            lags.append(loop.time() - began - LAG_TICK_S)


# -- the command line --------------------------------------------------------------------------


def ranges(numbers: Sequence[int]) -> str:
    """``1-4,33-36`` for 1, 2, 3, 4, 33, 34, 35, 36 (sorted or not)."""
    out: list[str] = []
    ordered = sorted(numbers)
    i = 0
    while i < len(ordered):
        j = i
        while j + 1 < len(ordered) and ordered[j + 1] == ordered[j] + 1:
            j += 1
        out.append(str(ordered[i]) if i == j else f"{ordered[i]}-{ordered[j]}")
        i = j + 1
    return ",".join(out)


def parse_ranges(text: str) -> list[int]:
    """The numbers of :func:`ranges`'s text."""
    out: list[int] = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        out += range(int(first), int(last or first) + 1)
    return out


def arguments(
    *,
    gateway: str,
    drives: Sequence[tuple[str, int]],
    broker: int | None = None,
    group: str | None = None,
    opcua: tuple[str, str] | None = None,
    http: int | None = None,
    modbus: Sequence[tuple[int, Sequence[int]]] = (),
    summary: bool = False,
) -> list[str]:
    """This module's command line (after ``python -m benchmarks.plant_clients``).

    *drives* are (line, node); *broker* the MQTT broker's port (JSON states);
    *group* the Sparkplug group on it; *opcua* (endpoint URL, namespace URI);
    *http* the workbench's port; *modbus* each listener's (port, unit ids), read through
    the summary (unit 255) with *summary*, else unit by unit.
    """
    lines: dict[str, list[int]] = {}
    for line, node in drives:
        lines.setdefault(line, []).append(node)
    out = ["--gateway", gateway]
    for line, nodes in lines.items():
        out += ["--line", f"{line}={ranges(nodes)}"]
    if broker is not None:
        out += ["--mqtt", str(broker)]
        if group is not None:
            out += ["--sparkplug", group]
    if opcua is not None:
        out += ["--opcua", opcua[0], "--namespace", opcua[1]]
    if http is not None:
        out += ["--http", str(http)]
    for port, units in modbus:
        out += ["--modbus", f"{port}={ranges(units)}"]
    if modbus and summary:
        out.append("--summary")
    return out


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.plant_clients")
    parser.add_argument("--gateway", required=True, help="the gateway's id")
    parser.add_argument("--line", action="append", default=[], help="NAME=NODES (1-32,40)")
    parser.add_argument("--mqtt", type=int, help="the broker's port: every JSON state")
    parser.add_argument("--sparkplug", metavar="GROUP", help="the Sparkplug group (on --mqtt)")
    parser.add_argument("--opcua", metavar="URL", help="the OPC UA endpoint")
    parser.add_argument("--namespace", help="the OPC UA namespace URI of the drives")
    parser.add_argument("--http", type=int, help="the workbench's port: event streams")
    parser.add_argument("--streams", type=int, default=EVENT_STREAMS)
    parser.add_argument("--modbus", action="append", default=[], help="PORT=UNITS, a listener")
    parser.add_argument(
        "--summary", action="store_true", help="the masters read the summary (unit 255)"
    )
    return parser


@dataclass(slots=True)
class _Run:
    """The clients of one run: what they count, and the tasks that run them."""

    window: Window = field(default_factory=Window)
    tallies: dict[str, Tally] = field(default_factory=dict)
    modbus: ModbusTally | None = None
    births: set[str] = field(default_factory=set)
    lags: list[float] = field(default_factory=list)
    #: One per client (each Modbus master's own): set once it is subscribed, or failed.
    readies: list[tuple[Tally | ModbusTally, asyncio.Event]] = field(default_factory=list)
    tasks: list[asyncio.Task[None]] = field(default_factory=list)
    ready_s: float = 0.0

    def start(
        self, tally: Tally | ModbusTally, client: Callable[[asyncio.Event], Awaitable[None]]
    ) -> None:
        ready = asyncio.Event()
        self.readies.append((tally, ready))
        self.tasks.append(asyncio.create_task(_guarded(tally, client(ready), ready)))

    def tally(self, name: str) -> Tally:
        self.tallies[name] = Tally(self.window)
        return self.tallies[name]


def _start_clients(args: argparse.Namespace, run: _Run) -> None:
    """A task per client the arguments name."""
    drives = [
        (name, node)
        for name, _, nodes in (text.partition("=") for text in args.line)
        for node in parse_ranges(nodes)
    ]
    if args.mqtt is not None:
        states = run.tally("mqtt")
        run.start(states, functools.partial(mqtt_states, args.mqtt, args.gateway, states))
        if args.sparkplug is not None:
            spb = run.tally("sparkplug")
            run.start(spb, functools.partial(sparkplug, args.mqtt, args.sparkplug, spb, run.births))
    if args.opcua is not None:
        ua_tally = run.tally("opcua")
        run.start(ua_tally, functools.partial(opcua, args.opcua, args.namespace, drives, ua_tally))
    if args.http is not None:
        http = run.tally("http")
        run.start(http, functools.partial(event_streams, args.http, args.streams, http))
    if args.modbus:
        masters = run.modbus = ModbusTally(run.window)
        first = asyncio.get_running_loop().time() + SWEEP_S / 2
        listeners = [text.partition("=") for text in args.modbus]
        masters.masters = len(listeners)
        masters.summary = args.summary
        for i, (port, _, text) in enumerate(listeners):
            # The listeners' sweeps spread over the second, as independent masters' would be.
            start_s = first + i * SWEEP_S / len(listeners)
            units = parse_ranges(text)
            masters.due += (
                len(summary_reads(units)) if args.summary else len(units) * len(MODBUS_BLOCKS)
            )
            master = functools.partial(modbus_master, int(port), units, start_s, args.summary)
            run.start(masters, functools.partial(master, masters))


async def _commands() -> asyncio.StreamReader:
    """This process's standard input, read on the loop."""
    reader = asyncio.StreamReader()
    loop = asyncio.get_running_loop()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    return reader


async def _subscribed(readies: Sequence[tuple[Tally | ModbusTally, asyncio.Event]]) -> None:
    """Wait until every client is subscribed, at most :data:`READY_TIMEOUT_S`: one that is
    not by then is a failure in the results, and the others are measured all the same."""
    waits = [asyncio.create_task(ready.wait()) for _, ready in readies]
    if waits:
        await asyncio.wait(waits, timeout=READY_TIMEOUT_S)
    for (tally, ready), wait in zip(readies, waits, strict=True):
        wait.cancel()
        if not ready.is_set() and tally.failure is None:
            tally.failure = f"not subscribed within {READY_TIMEOUT_S:g} s"


async def _serve(args: argparse.Namespace) -> None:
    run = _Run()
    began = time.perf_counter()
    run.tasks.append(asyncio.create_task(_loop_lag(run.window, run.lags)))
    try:
        _start_clients(args, run)
        await _subscribed(run.readies)
        run.ready_s = time.perf_counter() - began
        print(f"ready {run.ready_s:.3f}", flush=True)
        commands = await _commands()
        while (line := await commands.readline()) and line.strip() != b"stop":
            if line.strip() == b"start":
                run.window.start()
        run.window.stop()
        # The figures are final once the window closes: out before the clients close,
        # whose goodbyes (an OPC UA session's close, on a gateway still busy with the
        # others) may take long, once for ever (a full run's child waited 120 s).
        print(json.dumps(results(run), allow_nan=False), flush=True)
    finally:
        for task in run.tasks:
            task.cancel()
        await asyncio.wait(run.tasks, timeout=CLOSE_TIMEOUT_S)


def results(run: _Run) -> dict[str, Any]:
    """The JSON line: each client's figures, the window, this process's CPU and loop lag."""
    lags = sorted(run.lags)
    out: dict[str, Any] = {
        "ready_s": run.ready_s,
        "window_s": run.window.seconds,
        "cpu_s": run.window.cpu_s,
        "loop_lag_p99_ms": percentile(lags, 99) * 1e3 if lags else None,
        "loop_lag_max_ms": lags[-1] * 1e3 if lags else None,
        "clients": {name: tally.figures() for name, tally in run.tallies.items()},
    }
    if "sparkplug" in run.tallies:
        out["clients"]["sparkplug"]["births"] = len(run.births)
    if run.modbus is not None:
        out["clients"]["modbus"] = run.modbus.figures()
    return out


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m benchmarks.plant_clients ...`` (module docstring)."""
    args = _parser().parse_args(argv)
    # The client libraries' warnings (revised subscription values, a reconnect) to nobody:
    # failures are counted in the results, and nothing may log per message.
    for name in ("asyncua", "pymodbus"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    asyncio.run(_serve(args))


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        main()
