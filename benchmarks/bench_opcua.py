"""OPC UA: a sample's delay to a subscribed client, the northbound's CPU, its start-up, many items.

Every figure against a reference measured in the same run:

1. **Gateway CPU per drive sample, OPC UA against the MQTT bridge.**
   Three gateway processes run side by side over the same windows, each
   polling the same :data:`DRIVES` running drives on ``sim://`` every
   :data:`CPU_INTERVAL_S`: one with no northbound (the bare poll), one with
   ``[mqtt]`` (a real mosquitto on loopback), one with ``[opcua]`` and an
   asyncua client in this process subscribed to every data variable of its
   drives and lines (publishing interval :data:`PUBLISHING_MS`). Each
   process reports its CPU time (``time.process_time()``) and its polls at
   the start and the end of each window; a side's CPU per sample is its
   best window's. The row: OPC UA's extra CPU per sample over the bare poll
   against the MQTT bridge's extra CPU per sample; each against the bare
   poll in the rows below it.
2. **Delay from a drive sample to an OPC UA client's notification**, p50
   and p99. A gateway process polls :data:`BIG_DRIVES` running drives (two
   lines) every :data:`CPU_INTERVAL_S`; a client in this process subscribes
   to each drive's ``ConverterOutputFrequency`` (publishing interval
   :data:`PUBLISHING_MS`; the ramp changes the frequency at every poll).
   The gateway process records every sample it publishes (its drive and
   its ``time``: Unix time of the poll's end); each notification's
   SourceTimestamp (the read time) is matched to one of them, and the delay
   is this process's ``time.time()`` when asyncua hands the notification to
   the subscription's handler minus the sample's ``time``: both are the
   machine's one realtime clock. Against the poll interval (rows) and the
   publishing interval (notes), which bounds the delay: the server sends
   what changed once per publishing interval, so a notification waits up to
   one interval; the notes give the delay beyond it.
3. **Start-up of the address space** with :data:`BIG_DRIVES` drives: the
   same process starts the gateway without ``[opcua]`` (``__aenter__``'s
   wall time), then asyncua's ``Server()`` and ``Server.init()`` alone (the
   standard address space, namespace 0), then the gateway with ``[opcua]``
   (``OpcuaServer.startup_s`` and ``node_count``), :data:`STARTUP_REPEATS`
   times after one untimed round; best of each. Rows: start-up against the
   gateway's start without OPC UA, and ``Server.init()`` against the
   start-up (its share). The child also times ``Server.init()`` and the
   address space's one ``add_nodes`` call inside each start-up (wrappers
   around both: timing only), for the notes.
4. **Many monitored items** (asyncua issue #1516: lag from about 6,000).
   On the last start-up's gateway (figure 2's), after figure 2's window,
   the client creates monitored items on every variable in the gateway's
   namespace (data variables and properties: about 5,800 with 64 drives),
   :data:`ITEMS_PER_SUBSCRIPTION` per subscription, and figure 2's window
   is measured again with them all active. Rows: the time to create them,
   per item, against the 64 items' subscription per item; the p99 with
   them all against the p99 without. The notes say whether every sample
   still reached the client, and the gateway's CPU per sample both ways.
   Only what the drives change makes notifications (about two values per
   sample): some 1,000 a second, not the 6,000 a second of the issue,
   whose every tag changed every second.

Decisions:

- **This module is also the gateway children's script**
  (``python -m benchmarks.bench_opcua gateway ...``): a child runs
  :class:`~sj300_async.gateway.Gateway` from a TOML configuration as
  ``sj300 gateway`` does, starts its drives (forward towards
  :data:`RUN_HZ` on a :data:`RAMP_S` ramp, so the output frequency changes
  at every poll), prints ``port N`` (its OPC UA port, 0 without) once every
  drive was polled (and with MQTT published) once, and answers ``sample``,
  ``variables``, ``record``, ``times``, ``startup`` and ``stop`` on its
  standard input. No trip-history or set-frequency reads beside the poll
  (``trips_interval_s = 0``, ``setpoint_interval_s = 0``): every published
  snapshot is a poll's sample, and the samples are the polls.
- **OPC UA without security** (``security = ["None"]``, anonymous), as the
  MQTT bridge is measured without TLS: the figures are the northbounds'
  own work, not the ciphers'. The certificate is generated at the CPU
  figure's OPC UA child's start; the big child uses the same directory, so
  its start-up rounds load it.
- **CPU: three processes at once**, as ``bench_mqtt`` and
  ``bench_workbench`` run two: drift of the machine hits every side alike.
  The MQTT gateway publishes to a mosquitto with no subscriber (the bridge's
  work is the same; the broker's is not the gateway's). The OPC UA client
  lives in this process; the notes check it got a notification for every
  value the server pushed in the windows (asyncua queues one value per
  item: a value replaced within a publishing interval would be lost, which
  at a 0.2 s poll does not happen). Extra CPU per sample is a difference of
  two noisy figures, so the notes give the ratio per window too.
- **Publishing interval 50 ms** for every subscription: the short end of
  what a SCADA asks, the costly side for the server (a publish cycle per
  interval), and a short bound on the delay.
- **64 drives** are two ``sim://`` lines of 32 (an SJ300 line's nodes are
  1-32; the second URL spells ``pace=0``, the default, to be a line of its
  own, with ``unit_offset = 32``).
- **Figures 2 to 4 share one gateway process** (the big child), started
  once the CPU figure's children have stopped: its start-up rounds run
  alone on the machine, and the last round's gateway is the one served.
- **--quick** measures nothing: every gateway has :data:`QUICK_DRIVES`
  drives, one OPC UA child (with one start-up round and no untimed one)
  serves every figure, and the windows are short.
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import contextlib
import faulthandler
import gc
import json
import logging
import math
import os
import signal
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Coroutine, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from ._harness import Config, Result, Section, new_runner
from ._servers import ServerProcess
from .bench_mqtt import _ask, _mosquitto, _print_tasks

if TYPE_CHECKING:
    from asyncua import Client

    from sj300_async.gateway import Gateway

__all__ = [
    "BIG_DRIVES",
    "DRIVES",
    "TITLE",
    "USES_EVENT_LOOP",
    "BigRun",
    "CpuRun",
    "Delays",
    "OpcuaRun",
    "Startup",
    "Window",
    "main",
    "measure",
    "opcua_section",
    "report",
    "run",
]

TITLE = "opcua"
USES_EVENT_LOOP = True
#: Drives of each CPU figure's gateway (one line), of the big gateway, and of every
#: gateway with --quick.
DRIVES: Final = 32
BIG_DRIVES: Final = 64
QUICK_DRIVES: Final = 8
#: Every gateway's poll interval; the CPU figure's timed windows (full and --quick).
CPU_INTERVAL_S: Final = 0.2
WINDOW_S: Final = 2.5
QUICK_WINDOW_S: Final = 0.3
#: Every subscription's publishing interval (ms).
PUBLISHING_MS: Final = 50.0
#: Each delay window (full and --quick), and the quiet time before it.
DELAY_WINDOW_S: Final = 3.0
QUICK_DELAY_WINDOW_S: Final = 0.3
SETTLE_S: Final = 0.5
QUICK_SETTLE_S: Final = 0.1
#: After a window: the last samples' notifications on their way (several publishing intervals).
DRAIN_S: Final = 0.3
#: Timed start-up rounds (full, --quick); the full run adds one untimed round first.
STARTUP_REPEATS: Final = 2
QUICK_STARTUP_REPEATS: Final = 1
#: Monitored items per subscription when monitoring every variable.
ITEMS_PER_SUBSCRIPTION: Final = 2000
LINE: Final = "bench"
#: The running drives' setpoint and ramp (F002, in 0.01 s): the output changes every poll.
RUN_HZ: Final = 50.0
RAMP_S: Final = 300.0
#: The project's aim (docs/BENCHMARKS.md, "opcua"): OPC UA's extra CPU per sample at most
#: 1.5x the MQTT bridge's (a cost's ratio reads reference / ours).
TARGET_CPU_RATIO: Final = 1 / 1.5
#: How long a child may take to poll (and publish) every drive once after its start.
READY_TIMEOUT_S: Final = 60.0
#: Two SourceTimestamps within this are the same sample (µs datetimes, 100 ns ticks).
MATCH_S: Final = 2e-6


# -- the children (their processes) -------------------------------------------------------


def _lines_toml(drives: int, interval_s: float) -> str:
    """``[[lines]]`` of *drives* simulated drives, 32 per line (an SJ300 line's nodes)."""
    text = ""
    for index in range(math.ceil(drives / 32)):
        count = min(32, drives - 32 * index)
        # Each sim:// URL is a line of its own; pace=0 is the default (unpaced).
        url = f"sim://?nodes=1-{count}" + ("&pace=0" * index)
        text += textwrap.dedent(
            f"""
            [[lines]]
            name = "{LINE}{index}"
            url = "{url}"
            nodes = "1-{count}"
            unit_offset = {32 * index}
            interval_s = {interval_s!r}
            trips_interval_s = 0
            setpoint_interval_s = 0
            """
        )
    return text


def _gateway_toml(
    gateway_id: str, drives: int, interval_s: float, *, broker: int, opcua: Path | None
) -> str:
    text = f'[gateway]\nid = "{gateway_id}"\n'
    if broker:
        text += f'[mqtt]\nurl = "mqtt://127.0.0.1:{broker}"\n'
    if opcua is not None:
        text += opcua_section(opcua)
    return text + _lines_toml(drives, interval_s)


#: The monitored items one client of these benchmarks holds, at most: this benchmark's
#: session watches every variable and then 5,800 more items, the plant's client one item
#: a drive (2,048). ``[opcua]``'s defaults (1,000 a session, 2,000 an address) are for
#: an unknown client; a SCADA watching more raises them, as these do (docs/OPCUA.md).
ITEMS_PER_CLIENT: Final = 10_000


def opcua_section(directory: Path) -> str:
    """``[opcua]`` on a free loopback port, no security, its certificate in *directory*,
    room for :data:`ITEMS_PER_CLIENT` monitored items."""
    return textwrap.dedent(
        f"""
        [opcua]
        endpoint = "opc.tcp://127.0.0.1:0"
        security = ["None"]
        certificate = "{directory / "cert.der"}"
        private_key = "{directory / "key.pem"}"
        max_monitored_items_per_session = {ITEMS_PER_CLIENT}
        max_monitored_items_per_address = {ITEMS_PER_CLIENT}
        """
    )


#: Wall time of the last ``Server.init()`` and ``SpaceBuilder.commit()`` (a child's side).
_PHASES: dict[str, float] = {}


def _instrument() -> None:
    """Time asyncua's ``Server.init`` and the address space's one ``add_nodes`` (timing only)."""
    from asyncua import Server
    from asyncua.server.internal_session import InternalSession

    def timed(name: str, method: Callable[..., Coroutine[Any, Any, Any]]) -> Callable[..., Any]:
        async def wrapper(*args: Any, **kwargs: Any) -> Any:
            began = time.perf_counter()
            try:
                return await method(*args, **kwargs)
            finally:
                _PHASES[name] = time.perf_counter() - began

        return wrapper

    setattr(Server, "init", timed("init", Server.init))  # noqa: B010 - a class attribute
    # The address space is added in one add_nodes call (gateway/opcua/_space.py); namespace
    # 0's nodes come from init's own code, so the last call timed is the gateway's.
    setattr(InternalSession, "add_nodes", timed("commit", InternalSession.add_nodes))  # noqa: B010


_PER_CALL: Final = 11714  # Server_ServerCapabilities_OperationLimits_MaxMonitoredItemsPerCall


async def _start_drives(gateway: Gateway) -> None:
    """Run every drive forward towards :data:`RUN_HZ` on a long ramp, through its line's bus:
    the lines side by side, as an operator's script would (one after the other, 2,048
    drives took 11 s, and a child's warm-up measured that rather than the gateway)."""
    from sj300_async.sj300 import Drive

    async def start(line: Any) -> None:
        simulator = line.bus.simulator
        assert simulator is not None
        for node in line.drives:
            simulator.drives[node].set_parameter("F002", round(RAMP_S * 100))
            drive = line.bus.drive(node)
            assert isinstance(drive, Drive)
            await drive.set_frequency(RUN_HZ)
            await drive.run_forward()

    await asyncio.gather(*(start(line) for line in gateway.lines))


class _Counts:
    """What a gateway child counts: polls, and (while recording) each published sample."""

    def __init__(self, gateway: Gateway) -> None:
        self.gateway = gateway
        # The northbounds as the gateway holds them (their classes are the packages' own).
        self.opcua: Any = gateway.northbounds.get("opcua")
        self.mqtt: Any = gateway.northbounds.get("mqtt")
        self.drives = sum(len(line.drives) for line in gateway.lines)
        self.polls = 0
        self.failed = 0
        self.seen: set[tuple[str, int]] = set()
        #: While recording: every published sample's (line, node, time).
        self.recording: list[tuple[str, int, float]] | None = None
        for line in gateway.lines:
            line.poller.on_sample(self._on_sample_of(line))

    def _on_sample_of(self, line: Any) -> Callable[[Any], None]:
        name = line.config.name

        def on_sample(sample: Any) -> None:
            # The gateway's own callback came first (registered at its start): the drive's
            # snapshot is this sample's.
            self.polls += 1
            self.seen.add((name, sample.node))
            if sample.error is not None:
                self.failed += 1
            if self.recording is not None:
                snapshot = line.drives[sample.node].snapshot
                if snapshot.taken_at == sample.timestamp:
                    self.recording.append((name, sample.node, snapshot.time))

        return on_sample

    def ready(self) -> bool:
        if len(self.seen) < self.drives:
            return False
        return self.mqtt is None or len(self.mqtt.stats.states) == self.drives

    def sample(self) -> str:
        """``sample CPU polls failed pushed states``."""
        pushed = 0 if self.opcua is None else self.opcua.pushed
        states = 0 if self.mqtt is None else sum(self.mqtt.stats.states.values())
        return f"sample {time.process_time()!r} {self.polls} {self.failed} {pushed} {states}"

    def variables(self) -> str:
        """Every variable of the OPC UA namespace, by kind, as one JSON word."""
        from asyncua import ua

        opcua = self.opcua
        if opcua is None:
            return "variables {}"
        drives = [str(b.node.Identifier) for n in opcua._drives.values() for b in n.bindings]
        lines = [str(node.Identifier) for n in opcua._lines for node in n.counters.values()]
        known = set(drives) | set(lines)
        aspace = opcua._server.iserver.aspace
        other = sorted(
            str(node.Identifier)
            for node in aspace.keys()  # noqa: SIM118 - it has no __iter__
            if node.NamespaceIndex == opcua.namespace
            and isinstance(node.Identifier, str)  # not the trip event type's properties
            and str(node.Identifier) not in known
            and aspace[node].attributes[ua.AttributeIds.NodeClass].value.Value.Value
            == ua.NodeClass.Variable
        )
        table = {"namespace": opcua.namespace, "drives": drives, "lines": lines, "other": other}
        return "variables " + json.dumps(table, separators=(",", ":"))


def _answer_parent(loop: asyncio.AbstractEventLoop, counts: _Counts, startup: str) -> None:
    """Answer the parent on standard input; return at ``stop`` or when it closes."""

    async def on_loop(make: Callable[[], str]) -> str:
        return make()

    def ask(make: Callable[[], str]) -> str:
        return asyncio.run_coroutine_threadsafe(on_loop(make), loop).result()

    def record() -> str:
        counts.recording = []
        return "record"

    def times() -> str:
        recorded, counts.recording = counts.recording or [], None
        return "times " + json.dumps(recorded, separators=(",", ":"))

    for line in sys.stdin:
        command = line.strip()
        if command == "sample":
            print(ask(counts.sample), flush=True)
        elif command == "variables":
            print(ask(counts.variables), flush=True)
        elif command == "record":
            print(ask(record), flush=True)
        elif command == "times":
            print(ask(times), flush=True)
        elif command == "startup":
            print(f"startup {startup}", flush=True)
        elif command == "stop":
            return
        else:
            print(f"unknown {command}", flush=True)


async def _time_startups(
    on: str, off: str, rounds: int, warm_up: bool
) -> tuple[list[dict[str, float]], Gateway]:
    """Figure 3's rounds (module docstring); the last OPC UA gateway is left running."""
    from asyncua import Server

    from sj300_async.gateway import Gateway, parse_config

    timed: list[dict[str, float]] = []
    for index in range(rounds + int(warm_up)):
        gc.collect()
        gateway = Gateway(parse_config(off, "bench_opcua_off.toml"), tune_collector=True)
        began = time.perf_counter()
        await gateway.__aenter__()
        gateway_s = time.perf_counter() - began
        await gateway.__aexit__(None, None, None)
        gc.collect()
        server = Server()
        began = time.perf_counter()
        await server.init()
        init_alone_s = time.perf_counter() - began
        del server
        gc.collect()
        gateway = Gateway(parse_config(on, "bench_opcua_on.toml"), tune_collector=True)
        began = time.perf_counter()
        await gateway.__aenter__()
        with_opcua_s = time.perf_counter() - began
        opcua: Any = gateway.northbounds["opcua"]
        result = {
            "gateway_s": gateway_s,
            "init_alone_s": init_alone_s,
            "with_opcua_s": with_opcua_s,
            "startup_s": opcua.startup_s,
            "init_s": _PHASES.get("init", math.nan),
            "commit_s": _PHASES.get("commit", math.nan),
            "nodes": opcua.node_count,
        }
        if index >= int(warm_up):
            timed.append(result)
        if index == rounds + int(warm_up) - 1:
            return timed, gateway  # the last one serves the figures that follow
        await gateway.__aexit__(None, None, None)
    raise ValueError(f"no start-up round: {rounds}")


async def _serve_gateway(args: argparse.Namespace) -> None:
    from sj300_async.gateway import Gateway, parse_config

    # asyncua's warnings (revised subscription values...) to nobody: the parent reads
    # stderr only when a child fails, and a full pipe would block the child.
    logging.getLogger("asyncua").setLevel(logging.ERROR)
    opcua = Path(args.directory) if args.opcua else None
    text = _gateway_toml(args.id, args.drives, args.interval, broker=args.broker, opcua=opcua)
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGUSR1, _print_tasks)  # the parent's hang diagnosis
    startup: list[dict[str, float]] = []
    async with contextlib.AsyncExitStack() as stack:
        if args.startup:
            _instrument()
            off = _gateway_toml(args.id, args.drives, args.interval, broker=0, opcua=None)
            startup, gateway = await _time_startups(text, off, args.startup, args.warm_up)
            stack.push_async_exit(gateway)
        else:
            config = parse_config(text, f"bench_opcua_{args.id}.toml")
            gateway = await stack.enter_async_context(Gateway(config, tune_collector=True))
        counts = _Counts(gateway)
        await _start_drives(gateway)
        deadline = loop.time() + READY_TIMEOUT_S
        while not counts.ready():  # a child's start-up: polling its own counters is fine
            if loop.time() > deadline:
                raise RuntimeError(f"{args.id}: not every drive polled and published")
            await asyncio.sleep(0.01)
        port = 0 if counts.opcua is None else int(counts.opcua.url.rsplit(":", 1)[1])
        print(f"port {port}", flush=True)
        answer = json.dumps(startup, separators=(",", ":"))
        await loop.run_in_executor(None, _answer_parent, loop, counts, answer)
    print(f"stop {counts.polls} {counts.failed}", flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """A gateway child's entry point: serve until ``stop`` or until its stdin closes."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_opcua")
    parser.add_argument("kind", choices=("gateway",))
    parser.add_argument("--uvloop", action="store_true", help="run on uvloop")
    parser.add_argument("--id", default="opcua", help="the gateway's id")
    parser.add_argument("--drives", type=int, default=DRIVES, help="simulated drives")
    parser.add_argument("--interval", type=float, default=CPU_INTERVAL_S, help="poll interval")
    parser.add_argument("--broker", type=int, default=0, help="MQTT broker's port (0: no MQTT)")
    parser.add_argument("--opcua", action="store_true", help="serve OPC UA")
    parser.add_argument("--directory", default=".", help="the OPC UA certificate's directory")
    parser.add_argument("--startup", type=int, default=0, help="timed start-up rounds first")
    parser.add_argument("--warm-up", action="store_true", help="one untimed start-up round")
    args = parser.parse_args(argv)
    faulthandler.enable()  # SIGABRT from the parent (a hang) dumps every thread's stack
    serve = _serve_gateway(args)
    if args.uvloop:
        import uvloop

        uvloop.run(serve)
    else:
        asyncio.run(serve)
    return 0


# -- the parent's side: results ---------------------------------------------------------------


def _count(n: int, noun: str) -> str:
    return f"{n:,} {noun}" + ("" if n == 1 else "s")


def percentile(values: Sequence[float], p: float) -> float:
    """The *p*-th percentile (0..100), nearest rank, of sorted *values*."""
    rank = min(len(values), max(1, math.ceil(p / 100 * len(values))))
    return values[rank - 1]


@dataclass(frozen=True, slots=True)
class Sample:
    """A child's ``sample`` answer."""

    cpu_s: float
    polls: int
    failed: int
    pushed: int
    states: int

    @classmethod
    def parse(cls, words: Sequence[str]) -> Sample:
        return cls(float(words[0]), *(int(w) for w in words[1:5]))


@dataclass(frozen=True, slots=True)
class Window:
    """One timed window of the CPU figure: each side's CPU and polls, what OPC UA delivered."""

    seconds: float
    bare_cpu_s: float
    bare_polls: int
    mqtt_cpu_s: float
    mqtt_polls: int
    opcua_cpu_s: float
    opcua_polls: int
    #: MQTT states the broker acknowledged; OPC UA values pushed, notifications received.
    states: int
    pushed: int
    notifications: int

    @property
    def bare_s(self) -> float:
        return self.bare_cpu_s / self.bare_polls

    @property
    def mqtt_s(self) -> float:
        return self.mqtt_cpu_s / self.mqtt_polls

    @property
    def opcua_s(self) -> float:
        return self.opcua_cpu_s / self.opcua_polls


@dataclass(frozen=True, slots=True)
class CpuRun:
    windows: tuple[Window, ...]
    #: Drives of each gateway.
    drives: int
    #: Monitored items of the client (every data variable of the drives and the line).
    items: int
    #: Polls that failed, all three gateways (none on an idle machine).
    failed: int

    @property
    def bare_s(self) -> float:
        """CPU per sample of the bare poll: the best window."""
        return min(w.bare_s for w in self.windows)

    @property
    def mqtt_s(self) -> float:
        return min(w.mqtt_s for w in self.windows)

    @property
    def opcua_s(self) -> float:
        return min(w.opcua_s for w in self.windows)

    @property
    def mqtt_extra_s(self) -> float:
        return self.mqtt_s - self.bare_s

    @property
    def opcua_extra_s(self) -> float:
        return self.opcua_s - self.bare_s


@dataclass(frozen=True, slots=True)
class Startup:
    """One timed start-up round (module docstring, figure 3), seconds."""

    gateway_s: float
    init_alone_s: float
    with_opcua_s: float
    startup_s: float
    init_s: float
    commit_s: float
    nodes: int


@dataclass(frozen=True, slots=True)
class Delays:
    """One delay window: each matched notification's delay, what was published and delivered."""

    #: Sample to notification, sorted (seconds); and the same from the SourceTimestamp.
    delays_s: tuple[float, ...]
    #: Samples published in the window, and those a notification was matched to.
    published: int
    matched: int
    #: Notifications of the window no published sample matched (initial values, none else).
    unmatched: int
    #: The gateway's CPU per sample over the window, and this process's CPU over it.
    gateway_cpu_per_sample_s: float
    client_cpu_s: float
    #: Notifications every subscription of the client received in the window.
    notifications: int
    seconds: float

    def p(self, q: float) -> float:
        return percentile(self.delays_s, q)


@dataclass(frozen=True, slots=True)
class BigRun:
    drives: int
    startups: tuple[Startup, ...]
    #: Frequency items (one per drive), and every variable's items (data + other).
    small_items: int
    small_create_s: float
    alone: Delays
    big_items: int
    big_data_items: int
    subscriptions: int
    big_create_s: float
    #: From the first create request to every big item's first value at the client.
    big_initial_s: float
    with_all: Delays

    def best(self, name: str) -> float:
        value: float = min(getattr(s, name) for s in self.startups)
        return value

    @property
    def nodes(self) -> int:
        return self.startups[-1].nodes


@dataclass(frozen=True, slots=True)
class OpcuaRun:
    cpu: CpuRun
    big: BigRun
    #: The machine's 1-minute load average before and after (a shared machine's noise).
    load: tuple[float, float]


# -- the parent's side: the client ----------------------------------------------------------


@dataclass(eq=False)
class _Handler:
    """A subscription's handler: counts notifications, and records the frequency ones."""

    counted: int = 0
    #: The nodes whose first value came (a node is in one of a handler's subscriptions;
    #: client handles are counted per subscription).
    first: set[str] = field(default_factory=set)
    recording: list[tuple[str, float, float]] | None = None

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        now = time.time()
        self.counted += 1
        identifier = str(node.nodeid.Identifier)
        self.first.add(identifier)
        if self.recording is not None:
            source = data.monitored_item.Value.SourceTimestamp
            if source is not None:
                self.recording.append((identifier, source.timestamp(), now))


async def _subscribe(
    client: Client, handler: _Handler, namespace: int, identifiers: Sequence[str]
) -> Any:
    from asyncua import ua

    subscription = await client.create_subscription(PUBLISHING_MS, handler)
    nodes = [client.get_node(ua.NodeId(i, namespace)) for i in identifiers]
    # As a well-behaved client: no more items a request than the server advertises.
    limit = await client.get_node(ua.NodeId(_PER_CALL)).read_value() or len(nodes)
    results: list[Any] = []
    for start in range(0, len(nodes), limit):
        results += await subscription.subscribe_data_change(
            nodes[start : start + limit], sampling_interval=0.0
        )
    bad = [r for r in results if isinstance(r, ua.StatusCode)]
    if bad:
        raise RuntimeError(f"{len(bad)} of {len(nodes)} monitored items refused: {bad[0]}")
    return subscription


async def _until(condition: Callable[[], bool], what: str, timeout: float) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not condition():
        if loop.time() > deadline:
            raise RuntimeError(f"timed out after {timeout:g} s waiting for {what}")
        await asyncio.sleep(0.005)


def _drive_key(identifier: str) -> str:
    """``bench0/Drive3/Monitoring/ConverterOutputFrequency`` -> ``bench0/3``."""
    line, drive = identifier.split("/")[:2]
    return f"{line}/{drive.removeprefix('Drive')}"


async def _delays(
    gateway: ServerProcess, handler: _Handler, others: Sequence[_Handler], seconds: float
) -> Delays:
    """Record a window of *seconds*: match every frequency notification to its sample."""
    handler.recording = []
    counted = handler.counted + sum(h.counted for h in others)
    before = Sample.parse(await _ask(gateway, "sample"))
    await _ask(gateway, "record")
    began, cpu = time.time(), time.process_time()
    start = time.perf_counter()
    await asyncio.sleep(seconds)
    ended, client_cpu = time.time(), time.process_time() - cpu
    spent = time.perf_counter() - start
    notifications = handler.counted + sum(h.counted for h in others) - counted
    await asyncio.sleep(DRAIN_S)  # the window's last samples' notifications
    words = await _ask(gateway, "times")
    after = Sample.parse(await _ask(gateway, "sample"))
    recorded, handler.recording = handler.recording, None
    published: dict[str, list[float]] = {}
    for line, node, at in json.loads(words[0]):
        published.setdefault(f"{line}/{node}", []).append(at)
    for times in published.values():
        times.sort()
    expected = sum(1 for ts in published.values() for t in ts if began <= t <= ended)
    delays: list[float] = []
    matched = unmatched = 0
    for identifier, source, received in recorded:
        times = published.get(_drive_key(identifier), [])
        index = bisect.bisect_left(times, source - MATCH_S)
        if index < len(times) and abs(times[index] - source) <= MATCH_S:
            if began <= times[index] <= ended:
                matched += 1
                delays.append(received - times[index])
        else:
            unmatched += 1
    if not delays:
        raise RuntimeError(
            f"no notification of {len(recorded)} matched one of the {expected} samples published"
        )
    polls = after.polls - before.polls
    return Delays(
        tuple(sorted(delays)),
        expected,
        matched,
        unmatched,
        (after.cpu_s - before.cpu_s) / polls,
        client_cpu,
        notifications,
        spent,
    )


# -- the CPU figure ---------------------------------------------------------------------------


def _gateway(
    stack: contextlib.ExitStack,
    gateway_id: str,
    drives: int,
    *,
    broker: int = 0,
    directory: Path | None = None,
    startup: int = 0,
    warm_up: bool = False,
    uvloop: bool,
) -> ServerProcess:
    """Start a gateway child (blocking until it is ready); *stack* ends it."""
    args = ["--id", gateway_id, "--drives", str(drives), "--interval", repr(CPU_INTERVAL_S)]
    args += ["--broker", str(broker)]
    if directory is not None:
        directory.mkdir(parents=True, exist_ok=True)
        args += ["--opcua", "--directory", str(directory)]
    if startup:
        args += ["--startup", str(startup)]
    if warm_up:
        args.append("--warm-up")
    process = ServerProcess("gateway", uvloop=uvloop, module="benchmarks.bench_opcua", args=args)
    return stack.enter_context(process)


async def _connect(port: int) -> Client:
    from asyncua import Client

    client = Client(f"opc.tcp://127.0.0.1:{port}", timeout=30)
    await client.connect()
    return client


async def _measure_cpu(
    config: Config, bare: ServerProcess, mqtt: ServerProcess, opcua: ServerProcess, drives: int
) -> CpuRun:
    """Figure 1's windows over three running gateway children (module docstring)."""
    window_s = QUICK_WINDOW_S if config.quick else WINDOW_S
    windows: list[Window] = []
    sides = (bare, mqtt, opcua)
    table = json.loads((await _ask(opcua, "variables"))[0])
    identifiers = table["drives"] + table["lines"]
    client = await _connect(opcua.port)
    try:
        handler = _Handler()
        await _subscribe(client, handler, table["namespace"], identifiers)
        await _until(lambda: len(handler.first) == len(identifiers), "every first value", 30)
        for index in range(config.repeats + 1):  # the first window untimed
            first = await asyncio.gather(*(_ask(side, "sample") for side in sides))
            counted = handler.counted
            start = time.perf_counter()
            await asyncio.sleep(window_s)  # the window: the gateways poll and serve
            last = await asyncio.gather(*(_ask(side, "sample") for side in sides))
            seconds = time.perf_counter() - start
            b0, m0, o0 = (Sample.parse(words) for words in first)
            b1, m1, o1 = (Sample.parse(words) for words in last)
            if index == 0:
                continue
            windows.append(
                Window(
                    seconds,
                    b1.cpu_s - b0.cpu_s,
                    b1.polls - b0.polls,
                    m1.cpu_s - m0.cpu_s,
                    m1.polls - m0.polls,
                    o1.cpu_s - o0.cpu_s,
                    o1.polls - o0.polls,
                    m1.states - m0.states,
                    o1.pushed - o0.pushed,
                    handler.counted - counted,
                )
            )
    finally:
        await client.disconnect()
    return CpuRun(tuple(windows), drives, len(identifiers), b1.failed + m1.failed + o1.failed)


# -- the start-up, delay and many-items figures -----------------------------------------------


async def _measure_big(config: Config, gateway: ServerProcess, drives: int) -> BigRun:
    """Figures 2 to 4 on a child that timed its start-ups (module docstring)."""
    window_s = QUICK_DELAY_WINDOW_S if config.quick else DELAY_WINDOW_S
    settle_s = QUICK_SETTLE_S if config.quick else SETTLE_S
    startups = tuple(Startup(**r) for r in json.loads((await _ask(gateway, "startup"))[0]))
    table = json.loads((await _ask(gateway, "variables"))[0])
    namespace = table["namespace"]
    frequency = [i for i in table["drives"] if i.endswith("/ConverterOutputFrequency")]
    every = table["drives"] + table["lines"] + table["other"]
    client = await _connect(gateway.port)
    try:
        small = _Handler()
        start = time.perf_counter()
        await _subscribe(client, small, namespace, frequency)
        small_create_s = time.perf_counter() - start
        await _until(lambda: len(small.first) == len(frequency), "every first frequency", 30)
        await asyncio.sleep(settle_s)
        alone = await _delays(gateway, small, (), window_s)

        big = _Handler()
        chunks = math.ceil(len(every) / ITEMS_PER_SUBSCRIPTION)
        size = math.ceil(len(every) / chunks)
        start = time.perf_counter()
        for first in range(0, len(every), size):
            await _subscribe(client, big, namespace, every[first : first + size])
        big_create_s = time.perf_counter() - start
        await _until(lambda: len(big.first) == len(every), "every item's first value", 60)
        big_initial_s = time.perf_counter() - start
        await asyncio.sleep(settle_s)
        with_all = await _delays(gateway, small, (big,), window_s)
    finally:
        await client.disconnect()
    return BigRun(
        drives,
        startups,
        len(frequency),
        small_create_s,
        alone,
        len(every),
        len(table["drives"]) + len(table["lines"]),
        chunks,
        big_create_s,
        big_initial_s,
        with_all,
    )


# -- the whole ---------------------------------------------------------------------------------


async def _measure(config: Config, broker: int, directory: Path) -> tuple[CpuRun, BigRun]:
    """The CPU figure's three children, then the big one; --quick: one OPC UA child for all."""
    uvloop = config.loop == "uvloop"

    def start(stack: contextlib.ExitStack, name: str, drives: int, **kwargs: Any) -> Any:
        return asyncio.to_thread(_gateway, stack, name, drives, uvloop=uvloop, **kwargs)

    if config.quick:  # measures nothing: 8 drives, and the OPC UA child serves every figure
        drives = QUICK_DRIVES
        with contextlib.ExitStack() as stack:
            bare, mqtt, opcua = await asyncio.gather(
                start(stack, "bare", drives),
                start(stack, "mqtt", drives, broker=broker),
                start(stack, "big", drives, directory=directory, startup=QUICK_STARTUP_REPEATS),
            )
            cpu = await _measure_cpu(config, bare, mqtt, opcua, drives)
            await asyncio.gather(*(_ask(side, "stop") for side in (bare, mqtt)))
            big = await _measure_big(config, opcua, drives)
            await _ask(opcua, "stop")
        return cpu, big
    with contextlib.ExitStack() as stack:
        bare, mqtt, opcua = await asyncio.gather(
            start(stack, "bare", DRIVES),
            start(stack, "mqtt", DRIVES, broker=broker),
            start(stack, "opcua", DRIVES, directory=directory),
        )
        cpu = await _measure_cpu(config, bare, mqtt, opcua, DRIVES)
        await asyncio.gather(*(_ask(side, "stop") for side in (bare, mqtt, opcua)))
    with contextlib.ExitStack() as stack:
        # The same certificate directory: the untimed round loads what the first child made.
        gateway = await start(
            stack, "big", BIG_DRIVES, directory=directory, startup=STARTUP_REPEATS, warm_up=True
        )
        big = await _measure_big(config, gateway, BIG_DRIVES)
        await _ask(gateway, "stop")
    return cpu, big


@contextlib.contextmanager
def _quiet_asyncua() -> Iterator[None]:
    """asyncua's client warnings (revised subscription values, session time-out) unshown."""
    logger = logging.getLogger("asyncua")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def measure(config: Config) -> OpcuaRun:
    """Every figure (module docstring).

    Raises:
        RuntimeError: asyncua, aiomqtt or mosquitto missing, a child did not start, a
            subscription was refused, or no notification matched a published sample.
    """
    try:
        import aiomqtt  # noqa: F401  (the gateway extra)
        import asyncua  # noqa: F401  (the opcua extra)
    except ImportError as exc:
        raise RuntimeError(
            f"the opcua benchmark needs {exc.name}: pip install 'sj300-async[gateway,opcua]'"
        ) from None
    load = os.getloadavg()[0]

    with (
        _quiet_asyncua(),
        _mosquitto() as broker,
        tempfile.TemporaryDirectory(prefix="bench_opcua_") as directory,
        new_runner(config.loop) as runner,
    ):
        cpu, big = runner.run(_measure(config, broker, Path(directory)))
    return OpcuaRun(cpu, big, (load, os.getloadavg()[0]))


def run(config: Config) -> Section:
    """Measure OPC UA's delay, CPU per sample, start-up and many items."""
    return report(measure(config), config)


def report(result: OpcuaRun, config: Config) -> Section:
    """The notes and rows of a measurement made with *config*."""
    cpu, big = result.cpu, result.big
    us, ms = 1e6, 1e3
    window_s = QUICK_WINDOW_S if config.quick else WINDOW_S
    polls = [sum(getattr(w, f"{side}_polls") for w in cpu.windows) for side in ("bare", "mqtt")]
    polls.append(sum(w.opcua_polls for w in cpu.windows))
    pushed = sum(w.pushed for w in cpu.windows)
    notified = sum(w.notifications for w in cpu.windows)
    states = sum(w.states for w in cpu.windows)
    per_window = sorted(
        (w.opcua_s - w.bare_s) / (w.mqtt_s - w.bare_s) for w in cpu.windows if w.mqtt_s != w.bare_s
    )
    alone, every = big.alone, big.with_all
    interval_ms, publishing = CPU_INTERVAL_S * ms, PUBLISHING_MS
    startup, gateway_s = big.best("startup_s"), big.best("gateway_s")
    init_alone = big.best("init_alone_s")
    best = min(big.startups, key=lambda s: s.startup_s)
    small_per_item = big.small_create_s / big.small_items
    big_per_item = big.big_create_s / big.big_items

    def delay_row(label: str, d: Delays) -> str:
        return (
            f"| {label} | {d.p(50) * ms:.1f} | {d.p(90) * ms:.1f} | {d.p(99) * ms:.1f} "
            f"| {d.delays_s[-1] * ms:.1f} | {(d.p(99) * ms - publishing):+.1f} "
            f"| {d.matched:,} of {d.published:,} |"
        )

    notes: tuple[str, ...] = (
        f"CPU: three gateway processes at once, each polling {cpu.drives} running drives on "
        f"`sim://?nodes=1-{cpu.drives}` (status and monitor) every {CPU_INTERVAL_S:g} s: no "
        f"northbound, MQTT (mosquitto, QoS 1, retained), OPC UA (security None) with an asyncua "
        f"client in this process subscribed to all {cpu.items:,} data variables of its drives "
        f"and line (publishing interval {publishing:g} ms); {len(cpu.windows)} timed windows of "
        f"{window_s:g} s after an untimed one. Samples in the windows: {polls[0]:,} bare, "
        f"{polls[1]:,} MQTT, {polls[2]:,} OPC UA; {states:,} MQTT states acknowledged "
        f"({states / polls[1]:.2f} per sample); {pushed:,} OPC UA values pushed "
        f"({pushed / polls[2]:.2f} per sample), {notified:,} notifications received"
        + (f"; {cpu.failed} polls failed" if cpu.failed else "")
        + ".",
        f"Gateway CPU per drive sample, best window: {cpu.bare_s * us:.1f} µs bare, "
        f"{cpu.mqtt_s * us:.1f} µs with MQTT ({cpu.mqtt_extra_s * us:+.1f}), "
        f"{cpu.opcua_s * us:.1f} µs with OPC UA ({cpu.opcua_extra_s * us:+.1f}). OPC UA extra / "
        f"MQTT extra: {cpu.opcua_extra_s / cpu.mqtt_extra_s:.2f}x; per window: "
        + ", ".join(f"{r:.2f}" for r in per_window)
        + ".",
        "",
        f"Start-up, {big.drives} drives ({_count(math.ceil(big.drives / 32), 'line')}), "
        f"{_count(len(big.startups), 'timed round')}"
        + ("" if config.quick else " after an untimed one")
        + " in one process: the gateway without OPC UA "
        + ", ".join(f"{s.gateway_s * ms:.1f}" for s in big.startups)
        + " ms; asyncua's `Server()` + `init()` alone "
        + ", ".join(f"{s.init_alone_s * ms:.0f}" for s in big.startups)
        + " ms; OPC UA's `startup_s` "
        + ", ".join(f"{s.startup_s * ms:.0f}" for s in big.startups)
        + f" ms ({big.nodes:,} nodes in its namespace). Within the best start-up "
        f"({best.startup_s * ms:.0f} ms): `Server.init()` {best.init_s * ms:.0f} ms "
        f"({best.init_s / best.startup_s:.0%}), the one `add_nodes` "
        f"{best.commit_s * ms:.0f} ms ({best.commit_s / best.startup_s:.0%}), the rest "
        f"(certificate, configuration, gathering the nodes, binding, listening) "
        f"{(best.startup_s - best.init_s - best.commit_s) * ms:.0f} ms. The whole gateway "
        f"with OPC UA: {best.with_opcua_s * ms:.0f} ms.",
        "",
        f"Delay: a client in this process subscribed to the {big.small_items} drives' "
        f"ConverterOutputFrequency (publishing interval {publishing:g} ms; drives ramping, "
        f"the value changes at every poll of {interval_ms:g} ms); windows of "
        f"{alone.seconds:.1f} s; every notification matched to its sample by its "
        f"SourceTimestamp; delay = this process's time.time() at the handler - the sample's "
        f"`time` (the gateway process's time.time() at the poll's end: one clock).",
        "",
        "| sample to notification | p50 ms | p90 ms | p99 ms | max ms "
        "| p99 - publishing interval, ms | samples delivered |",
        "|---|---:|---:|---:|---:|---:|---:|",
        delay_row(f"{big.small_items} items", alone),
        delay_row(f"with {big.big_items:,} more", every),
        "",
        f"p50 / poll interval {alone.p(50) * ms / interval_ms:.3f}, p99 / poll interval "
        f"{alone.p(99) * ms / interval_ms:.3f}; p50 / publishing interval "
        f"{alone.p(50) * ms / publishing:.2f}, p99 / publishing interval "
        f"{alone.p(99) * ms / publishing:.2f}.",
        f"Many items: {big.big_items:,} more monitored items (every variable of the namespace: "
        f"{big.big_data_items:,} data variables, {big.big_items - big.big_data_items:,} "
        f"properties) in {_count(big.subscriptions, 'subscription')}: created in "
        f"{big.big_create_s * ms:.0f} ms ({big_per_item * us:.0f} µs per item; the "
        f"{big.small_items} items' subscription {small_per_item * us:.0f} µs per item), every "
        f"first value at the client {big.big_initial_s * ms:.0f} ms after the first request. "
        f"With them all: p99 {every.p(99) * ms:.1f} ms against {alone.p(99) * ms:.1f} ms; "
        f"{every.notifications / every.seconds:,.0f} notifications/s to the client (against "
        f"{alone.notifications / alone.seconds:,.0f}); the gateway's CPU per sample "
        f"{every.gateway_cpu_per_sample_s * us:.0f} µs against "
        f"{alone.gateway_cpu_per_sample_s * us:.0f} µs; this process (the client) "
        f"{every.client_cpu_s / every.seconds:.0%} of a CPU against "
        f"{alone.client_cpu_s / alone.seconds:.0%}.",
        "",
        f"The machine's 1-minute load average: {result.load[0]:.2f} before, "
        f"{result.load[1]:.2f} after (2 CPUs here: above 2, others wait for a CPU).",
    )
    results = (
        Result(
            f"opcua: drive sample to client notification, p50 ({publishing:g} ms publishing; "
            "vs poll interval)",
            alone.p(50) * ms,
            interval_ms,
            "ms",
            None,
            higher_is_better=False,
            against="poll interval",
            as_multiple=True,
        ),
        Result(
            f"opcua: drive sample to client notification, p99 ({publishing:g} ms publishing; "
            "vs poll interval)",
            alone.p(99) * ms,
            interval_ms,
            "ms",
            None,
            higher_is_better=False,
            against="poll interval",
            as_multiple=True,
        ),
        Result(
            f"opcua: gateway CPU per drive sample beyond the bare poll, OPC UA (client on every "
            f"variable) vs MQTT bridge ({cpu.drives} drives)",
            cpu.opcua_extra_s * us,
            cpu.mqtt_extra_s * us,
            "µs",
            TARGET_CPU_RATIO,
            higher_is_better=False,
            against="MQTT bridge",
            as_multiple=True,
        ),
        Result(
            "opcua: gateway CPU per drive sample with OPC UA (vs the bare poll)",
            cpu.opcua_s * us,
            cpu.bare_s * us,
            "µs",
            None,
            higher_is_better=False,
            against="bare poll",
            as_multiple=True,
        ),
        Result(
            "opcua: gateway CPU per drive sample with MQTT (vs the bare poll)",
            cpu.mqtt_s * us,
            cpu.bare_s * us,
            "µs",
            None,
            higher_is_better=False,
            against="bare poll",
            as_multiple=True,
        ),
        Result(
            f"opcua: address space start-up, {big.drives} drives (vs the gateway's start "
            "without OPC UA)",
            startup * ms,
            gateway_s * ms,
            "ms",
            None,
            higher_is_better=False,
            against="gateway start",
            as_multiple=True,
        ),
        Result(
            "opcua: asyncua Server.init() alone (vs the OPC UA start-up)",
            init_alone * ms,
            startup * ms,
            "ms",
            None,
            higher_is_better=False,
            against="OPC UA start-up",
            as_multiple=True,
        ),
        Result(
            f"opcua: creating {big.big_items:,} monitored items, per item (vs a "
            f"{big.small_items}-item subscription's)",
            big_per_item * us,
            small_per_item * us,
            "µs",
            None,
            higher_is_better=False,
            against=f"{big.small_items} items",
            as_multiple=True,
        ),
        Result(
            f"opcua: sample to notification p99 with {big.big_items + big.small_items:,} "
            f"monitored items (vs {big.small_items})",
            every.p(99) * ms,
            alone.p(99) * ms,
            "ms",
            None,
            higher_is_better=False,
            against=f"{big.small_items} items",
            as_multiple=True,
        ),
    )
    return Section(TITLE, notes, results)


if __name__ == "__main__":
    sys.exit(main())
