"""The whole gateway at plant scale: 64 lines of 32 drives at 1 Hz, each northbound's cost.

Issue 30's measurement: what each northbound adds to the gateway's CPU
per drive sample, against the bare poll's own CPU per sample in the same
run, whether every drive state reaches the broker (none replaced unsent),
the memory per drive, the time from start to every drive visible on MQTT
(each drive's first state; every Sparkplug birth), the delay from a
sample to each northbound's client with every northbound serving clients,
and two gateways feeding one broker.

Each configuration runs in a process of its own (``python -m
benchmarks.bench_plant gateway --with ...``), one after the other, so that
each has the machine's two cores to itself and its RSS is its own:

- ``bare``: the lines alone, no northbound;
- ``mqtt``: ``[mqtt]`` with the JSON topics and Home Assistant discovery
  (QoS 1, the default), on a mosquitto of its own on loopback;
- ``sparkplug``: ``[sparkplug]`` alone (issue 42: before, ``[mqtt]
  sparkplug = true`` with ``state_topics = false``);
- ``mqtt+sparkplug``: both, each reading the drive as served (the state
  message was built once for both before issue 42);
- ``opcua``: ``[opcua]`` without security, no client;
- ``http``: ``[http]`` (the workbench, /metrics), no client;
- ``modbus``: ten ``[[modbus.listeners]]``, nine of seven lines and one of
  the last line, no client;
- ``all``: every one of them at once, with a client on each (below);
- ``all-per-unit``: the same, its Modbus masters reading each unit's
  blocks instead of the listeners' summaries (below).

Every line is ``sim://?nodes=1-32`` (the same URL: 64 simulators of their
own), polled every second (status and monitor), no trip-history or
set-frequency reads beside the poll, so a sample is a poll. Every drive
runs forward on a long ramp, so its output changes at every poll: the
worst case for publishing by exception. A child lets the gateway run
:data:`WARM_UP_S` seconds (the births, the discovery configs, OPC UA's
start-up), then measures :data:`WINDOWS` windows of :data:`WINDOW_S`
seconds: its CPU (``time.process_time()``, the simulators' included, alike
on every side) per sample polled; the best window counts. ``bare`` and
``all`` run a second time after the others (:data:`REPEATED`): the best
window of their two children counts.

**The clients of** ``all``: once its servers listen, its child starts
:mod:`benchmarks.plant_clients`, a process of its own (its CPU is not in the
child's ``process_time``; the notes give it): a subscriber to every drive's
JSON state, a Sparkplug host on the group's DDATA and DBIRTH topics, an OPC
UA subscription with an item on each drive's output frequency, event
streams on the workbench, and a Modbus master per listener reading every
drive's values once a second: through the listener's summary (unit 255,
15 drives a read: 138 reads a second for 2,048 drives), the way the
gateway offers a SCADA of a plant this size its overview (docs/GATEWAY.md,
"The summary: unit 255"); ``all-per-unit``'s read each unit's monitor and
status blocks (4,096 reads a second, two per drive), which the goal's row
does not count but a row of its own shows. The child waits until they
have subscribed, and :data:`CLIENTS_SETTLE_S` more (the first values they
are handed are each drive's state as of subscribing, not samples just
taken), then records their delays over its windows: the client's
``time.time()`` on handling a message minus the sample's time as the
message carries it (the JSON state's ``time``, the Sparkplug payload's
timestamp, the OPC UA SourceTimestamp, the workbench event's ``time``).
Modbus carries no sample time finer than a whole second (register 1), so
its masters report reads per second and errors instead of a delay.

**Two gateways** (:func:`measure_two_gateways`, after the configurations,
on a mosquitto of their own): two ``mqtt+sparkplug`` children of 32 lines
each (``l0``..``l31`` as :data:`PAIR`'s first gateway, ``l32``..``l63`` as
its second), one Sparkplug group, started together once a fleet view
(:func:`~sj300_async.gateway.mqtt.follow`, as ``sj300 monitor --url
mqtt://...`` follows the broker) and a Sparkplug host subscribed to the
group's DBIRTHs are on the broker. Their warm-up is
:data:`PAIR_WARM_UP_S`: the time both views have to see every drive.

Rows: ``all`` against ``bare`` (the issue's goal: at most twice),
``all-per-unit`` against ``bare`` (information), each
northbound alone against ``bare`` (information), the JSON topics' and
Sparkplug's share of samples neither replaced unsent nor lost (goal:
every one; the states confirmed in a window are shown too, but up to a
chunk of 256 is in flight at each of its edges), RSS per drive and the
traced heap per drive (below) of ``all`` against ``bare``, the p99
delay from a sample to each timed client of ``all`` against the poll
interval (goal: under it, or the client falls behind), and the drives the
two gateways' fleet view and Sparkplug host saw against every drive
(goal: all). The notes give the time to every drive visible, each
client's figures, and the time until the two views saw every drive.

**Memory** (issue 44, :mod:`benchmarks._memory`): the notes' table gives
each configuration's RSS per drive against ``bare``'s, and the traced heap
per drive by package of children of their own (``python -m
benchmarks.bench_plant heap --with ...``, after the timed ones, at 256
drives: ``tracemalloc`` slows everything), each against ``bare``'s.

``--quick`` measures nothing: two lines of four drives, one short window,
only ``bare`` and ``all`` (with its clients), then two gateways of one
line each, then the heap of ``bare`` and ``mqtt`` on one line of four.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Final

from ._harness import Config, Result, Section
from ._memory import Heap, heap_child, measure_heap, memory_notes, memory_rows
from .bench_mqtt import _mosquitto
from .bench_opcua import _start_drives, opcua_section
from .plant_clients import (
    CLOSE_TIMEOUT_S,
    EVENT_STREAMS,
    PUBLISHING_MS,
    READY_TIMEOUT_S,
    arguments,
)

__all__ = [
    "CONFIGURATIONS",
    "TITLE",
    "USES_EVENT_LOOP",
    "Child",
    "main",
    "measure",
    "measure_heap",
    "report",
    "run",
]

TITLE = "plant"
USES_EVENT_LOOP = True
#: Each configuration's northbounds, in the order they run.
CONFIGURATIONS: Final = (
    *("bare", "mqtt", "sparkplug", "mqtt+sparkplug", "opcua", "http", "modbus", "all"),
    "all-per-unit",
    "all-without-recorder",
)
#: The configurations of one northbound or two, reported against the bare poll.
ALONE: Final = ("mqtt", "sparkplug", "mqtt+sparkplug", "opcua", "http", "modbus")
#: The configurations with every northbound and its clients: the masters read the
#: listeners' summaries (``all``, the goal's) or each unit (``all-per-unit``).
WITH_CLIENTS: Final = ("all", "all-per-unit", "all-without-recorder")
#: The gateway's id (the JSON topics' level, the Sparkplug edge node) and Sparkplug group.
GATEWAY_ID: Final = "plant"
GROUP: Final = "plant"
#: The northbounds of ``all``, and the trip recorder (on by default: issue 45); every
#: other configuration runs with ``[recorder] enabled = false`` (the bare poll is the poll).
EVERY: Final = frozenset({"mqtt", "sparkplug", "opcua", "http", "modbus", "recorder"})
LINES: Final = 64
DRIVES_PER_LINE: Final = 32
QUICK_LINES: Final = 2
QUICK_DRIVES_PER_LINE: Final = 4
INTERVAL_S: Final = 1.0
WARM_UP_S: Final = 12.0
WINDOW_S: Final = 5.0
WINDOWS: Final = 3
QUICK_WARM_UP_S: Final = 2.0
QUICK_WINDOW_S: Final = 1.0
#: Lines per Modbus listener (unit ids 1..224 within each).
LINES_PER_LISTENER: Final = 7
#: The clients of ``all`` whose delay is a row (the key in their figures), in order.
DELAYED: Final = (
    ("mqtt", "MQTT JSON"),
    ("sparkplug", "Sparkplug"),
    ("opcua", "OPC UA"),
    ("http", "the workbench"),
)
#: The goal's two configurations, run a second time after the others (full runs): the
#: machine is shared, and a host slowed for one child of the two moved the goal's ratio by
#: 0.3x either way (a bare poll of 204 us an hour after one of 146). The best window of
#: each, over both of its children, counts.
REPEATED: Final = ("bare", "all")
#: The goal: every northbound together at most 1.5x the poll's CPU per sample (issue 44;
#: issue 30's was 2x).
TARGET_ALL: Final = 1 / 1.5
#: The repository: the children's working directory (``python -m benchmarks...``).
ROOT: Final = Path(__file__).resolve().parent.parent
#: How long a child may take, over its windows and warm-up.
CHILD_TIMEOUT_S: Final = 300.0
#: How long ``all``'s clients may take to say they are ready (they give up on a client
#: after plant_clients.READY_TIMEOUT_S and report it), or to answer.
CLIENTS_TIMEOUT_S: Final = READY_TIMEOUT_S + 30.0
#: How long the clients process takes to close after its figures, at most.
CLIENTS_CLOSE_S: Final = CLOSE_TIMEOUT_S
#: From the clients' subscriptions to the windows (full, --quick): the first values they
#: are handed (each drive's state as of subscribing, the event streams' "everything") pass.
CLIENTS_SETTLE_S: Final = 3.0
QUICK_CLIENTS_SETTLE_S: Final = 0.5


def _toml(
    which: str,
    lines: int,
    per_line: int,
    broker: int,
    directory: Path,
    gateway_id: str = GATEWAY_ID,
    first_line: int = 0,
    interval_s: float = INTERVAL_S,
    trend_s: float | None = None,
) -> str:
    """The configuration of *which*: lines ``l<first_line>`` on, *lines* of them, polled
    every *interval_s*; the workbench's trends *trend_s* long (None: its default)."""
    parts = EVERY if which in WITH_CLIENTS else set(which.split("+")) - {"bare"}
    if which == "all-without-recorder":
        parts = EVERY - {"recorder"}
    text = f'[gateway]\nid = "{gateway_id}"\n'
    if "recorder" not in parts:
        text += "[recorder]\nenabled = false\n"
    if "mqtt" in parts:
        text += f'[mqtt]\nurl = "mqtt://127.0.0.1:{broker}"\n'
    if "sparkplug" in parts:
        text += f'[sparkplug]\nurl = "mqtt://127.0.0.1:{broker}"\ngroup_id = "{GROUP}"\n'
    indices = range(first_line, first_line + lines)
    if "modbus" in parts:
        text += "[modbus]\n"
        for first in range(first_line, first_line + lines, LINES_PER_LISTENER):
            names = ", ".join(
                f'"l{i}"' for i in range(first, min(indices.stop, first + LINES_PER_LISTENER))
            )
            text += f'[[modbus.listeners]]\nlisten = "127.0.0.1:0"\nlines = [{names}]\n'
    if "opcua" in parts:
        text += opcua_section(directory)
    if "http" in parts:
        text += '[http]\nlisten = "127.0.0.1:0"\n'
        text += "" if trend_s is None else f"trend_s = {trend_s!r}\n"
    for index in indices:
        text += textwrap.dedent(
            f"""
            [[lines]]
            name = "l{index}"
            url = "sim://?nodes=1-{per_line}"
            nodes = "1-{per_line}"
            unit_offset = {((index - first_line) % LINES_PER_LISTENER) * DRIVES_PER_LINE}
            interval_s = {interval_s!r}
            trips_interval_s = 0
            setpoint_interval_s = 0
            """
        )
    return text


# -- the child ------------------------------------------------------------------------------


class SampleCount:
    """Every drive sample *gateway*'s lines take, counted (what CPU is divided by)."""

    def __init__(self, gateway: Any) -> None:
        self.samples = 0
        for line in gateway.lines:
            line.poller.on_sample(self._one)

    def _one(self, sample: object) -> None:
        self.samples += 1


async def _child(args: argparse.Namespace) -> dict[str, Any]:
    from sj300_async.gateway import Gateway, parse_config

    directory = Path(args.directory)
    text = _toml(
        args.which, args.lines, args.per_line, args.broker, directory, args.id, args.first_line
    )
    loop = asyncio.get_running_loop()
    began = loop.time()
    async with Gateway(parse_config(text, "bench_plant.toml"), tune_collector=True) as gateway:
        started_s = loop.time() - began
        counted = SampleCount(gateway)
        drives = len(gateway.drives)
        bridge: Any = gateway.northbounds.get("mqtt")
        edge: Any = gateway.northbounds.get("sparkplug")
        visible: dict[str, float] = {}

        async def watch() -> None:
            """When every drive was first seen in each northbound, from the start: beside
            the drives' start and the clients', which are the harness's, not the gateway's."""
            expected = (bridge is not None) + (edge is not None)
            while len(visible) < expected:
                now = loop.time() - began
                if bridge is not None and len(bridge.stats.states) == drives:
                    visible.setdefault("mqtt", now)
                if edge is not None and edge.stats.published["DBIRTH"] >= drives:
                    visible.setdefault("sparkplug", now)
                await asyncio.sleep(0.05)

        watcher = asyncio.create_task(watch())
        clients = None
        try:
            await _start_drives(gateway)  # the OPC UA benchmark's ramp: 50 Hz over 300 s
            # Started now that every server listens; read beside the warm-up.
            if args.which in WITH_CLIENTS:
                summary = args.which != "all-per-unit"
                clients = await _Clients.start(gateway, args.broker, summary=summary)
            await asyncio.sleep(args.warm_up)
            watcher.cancel()  # what was not visible by now is not (the report says so)
            if clients is not None:
                await clients.ready(args.settle)
                clients.command("start")
            before = _delivery(bridge, edge)
            windows = []
            for _ in range(args.windows):
                cpu, count, wall = time.process_time(), counted.samples, loop.time()
                await asyncio.sleep(args.window)
                cpu, count = time.process_time() - cpu, counted.samples - count
                windows.append({"cpu_s": cpu, "samples": count, "wall_s": loop.time() - wall})
            after = _delivery(bridge, edge)
            figures = None if clients is None else await clients.results()
        finally:
            watcher.cancel()
            if clients is not None:
                await clients.close()
        statm = Path("/proc/self/statm").read_text(encoding="ascii").split()
        opcua: Any = gateway.northbounds.get("opcua")
        return {
            "which": args.which,
            "drives": drives,
            "started_s": started_s,
            "opcua_startup_s": None if opcua is None else opcua.startup_s,
            "visible_s": visible,
            "windows": windows,
            "rss_bytes": int(statm[1]) * os.sysconf("SC_PAGE_SIZE"),
            "delivery": {k: after[k] - before[k] for k in after},
            "clients": figures,
        }


class _Clients:
    """A child's clients process (:mod:`benchmarks.plant_clients`), on the child's loop."""

    def __init__(self, process: asyncio.subprocess.Process) -> None:
        self.process = process
        self.ready_at: float | None = None

    @classmethod
    async def start(cls, gateway: Any, broker: int, *, summary: bool) -> _Clients:
        """Start the clients of every northbound of *gateway* (servers listening); the Modbus
        masters read the summary (unit 255) with *summary*, else each unit."""
        modbus = gateway.northbounds["modbus"]
        opcua = gateway.northbounds["opcua"]
        command = arguments(
            gateway=gateway.config.gateway_id,
            drives=[drive.key for drive in gateway.drives],
            broker=broker,
            group=GROUP,
            opcua=(opcua.url, opcua.config.namespace),
            http=gateway.northbounds["http"].port,
            modbus=[(server.port, sorted(server.units)) for _, server in modbus.servers],
            summary=summary,
        )
        process = await asyncio.create_subprocess_exec(
            *(sys.executable, "-m", "benchmarks.plant_clients", *command),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )  # its stderr is the child's: a traceback reaches the parent's error message
        return cls(process)

    async def _line(self) -> str:
        assert self.process.stdout is not None
        async with asyncio.timeout(CLIENTS_TIMEOUT_S):
            line = await self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"the clients exited ({await self.process.wait()})")
        return line.decode()

    async def ready(self, settle_s: float) -> None:
        """Once every client is subscribed, and *settle_s* after: their first values (each
        drive's state as of subscribing) are not samples just taken."""
        loop = asyncio.get_running_loop()
        if self.ready_at is None:
            word = await self._line()
            if not word.startswith("ready"):
                raise RuntimeError(f"the clients said {word!r}, not ready")
            self.ready_at = loop.time()
        await asyncio.sleep(max(0.0, self.ready_at + settle_s - loop.time()))

    def command(self, word: str) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(f"{word}\n".encode())

    async def results(self) -> dict[str, Any]:
        """Stop the clients; their figures (:func:`benchmarks.plant_clients.results`)."""
        self.command("stop")
        body: dict[str, Any] = json.loads(await self._line())
        try:  # its figures are out: a close that hangs (an OPC UA session's) is cut short
            async with asyncio.timeout(2 * CLIENTS_CLOSE_S):
                await self.process.wait()
        except TimeoutError:
            self.process.kill()
            await self.process.wait()
        return body

    async def close(self) -> None:
        """End the process if it still runs (a failed child), and reap it."""
        if self.process.returncode is None:
            self.process.kill()
        await self.process.wait()


def _delivery(bridge: Any, edge: Any) -> dict[str, int]:
    """What the MQTT clients did with the samples so far (counters)."""
    out = {"mqtt_samples": 0, "mqtt_states": 0, "mqtt_replaced": 0, "mqtt_lost": 0}
    out |= {"spb_samples": 0, "spb_replaced": 0}
    if bridge is not None:
        stats = bridge.stats
        out["mqtt_samples"] = sum(stats.samples.values())
        out["mqtt_states"] = sum(stats.states.values())
        out["mqtt_replaced"] = sum(stats.replaced.values())
        out["mqtt_lost"] = stats.lost
    if edge is not None:
        out["spb_samples"] = edge.stats.samples
        out["spb_replaced"] = edge.stats.replaced
    return out


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m benchmarks.bench_plant gateway|heap|soak ...``: one configuration's child,
    timed (gateway) or its heap traced (heap, :func:`benchmarks._memory.heap_child`), or a
    long run of ``all`` sampling its memory and descriptors (soak, :mod:`benchmarks._soak`)."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["soak"]:
        from ._soak import main as soak

        soak(argv[1:])
        return
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_plant")
    parser.add_argument("role", choices=["gateway", "heap"])
    parser.add_argument("--with", dest="which", choices=CONFIGURATIONS, required=True)
    parser.add_argument("--lines", type=int, default=LINES)
    parser.add_argument("--per-line", type=int, default=DRIVES_PER_LINE)
    parser.add_argument("--broker", type=int, default=0)
    parser.add_argument("--id", default=GATEWAY_ID, help="the gateway's id")
    parser.add_argument("--first-line", type=int, default=0, help="the first line's index")
    parser.add_argument("--directory", required=True)
    parser.add_argument("--warm-up", type=float, default=WARM_UP_S)
    parser.add_argument("--window", type=float, default=WINDOW_S)
    parser.add_argument("--windows", type=int, default=WINDOWS)
    parser.add_argument("--settle", type=float, default=CLIENTS_SETTLE_S)
    args = parser.parse_args(argv)
    if args.role == "gateway":
        print(json.dumps(asyncio.run(_child(args))), flush=True)
        return
    text = _toml(args.which, args.lines, args.per_line, args.broker, Path(args.directory))

    async def clients(gateway: Any) -> _Clients:  # all's, as the timed child starts them
        return await _Clients.start(gateway, args.broker, summary=args.which != "all-per-unit")

    start = clients if args.which in WITH_CLIENTS else None
    body = asyncio.run(heap_child(args.which, text, args.warm_up, start, args.settle))
    print(json.dumps(body), flush=True)


# -- the parent -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Child:
    """One configuration's figures."""

    which: str
    drives: int
    #: CPU per sample of each window (s).
    cpu_per_sample_s: tuple[float, ...]
    samples_per_s: tuple[float, ...]
    rss_bytes: int
    started_s: float
    opcua_startup_s: float | None
    visible_s: dict[str, float]
    delivery: dict[str, int]
    #: ``all``'s clients' figures (:func:`benchmarks.plant_clients.results`), else None.
    clients: dict[str, Any] | None = None

    @property
    def best_cpu_s(self) -> float:
        return min(self.cpu_per_sample_s)

    def merged(self, again: Child) -> Child:
        """This child's figures with *again*'s windows (a second child of the same
        configuration) after its own; the rest is this one's."""
        return replace(
            self,
            cpu_per_sample_s=self.cpu_per_sample_s + again.cpu_per_sample_s,
            samples_per_s=self.samples_per_s + again.samples_per_s,
        )

    @classmethod
    def from_json(cls, body: dict[str, Any]) -> Child:
        windows = body["windows"]
        return cls(
            which=body["which"],
            drives=body["drives"],
            cpu_per_sample_s=tuple(w["cpu_s"] / max(1, w["samples"]) for w in windows),
            samples_per_s=tuple(w["samples"] / w["wall_s"] for w in windows),
            rss_bytes=body["rss_bytes"],
            started_s=body["started_s"],
            opcua_startup_s=body["opcua_startup_s"],
            visible_s=body["visible_s"],
            delivery=body["delivery"],
            clients=body.get("clients"),
        )


def _command(
    which: str,
    config: Config,
    broker: int,
    directory: Path,
    *,
    gateway_id: str = GATEWAY_ID,
    first_line: int = 0,
    lines: int | None = None,
    warm_up: float | None = None,
) -> list[str]:
    """A child's command line: *which* configuration, the run's sizes unless given."""
    quick = config.quick
    return [
        sys.executable, "-m", "benchmarks.bench_plant", "gateway", "--with", which,
        "--broker", str(broker), "--directory", str(directory),
        "--id", gateway_id, "--first-line", str(first_line),
        "--lines", str(lines or (QUICK_LINES if quick else LINES)),
        "--per-line", str(QUICK_DRIVES_PER_LINE if quick else DRIVES_PER_LINE),
        "--warm-up", str(warm_up or (QUICK_WARM_UP_S if quick else WARM_UP_S)),
        "--window", str(QUICK_WINDOW_S if quick else WINDOW_S),
        "--windows", str(1 if quick else WINDOWS),
        "--settle", str(QUICK_CLIENTS_SETTLE_S if quick else CLIENTS_SETTLE_S),
    ]  # fmt: skip


def _child_of(name: str, returncode: int, stdout: str, stderr: str) -> Child:
    if returncode != 0:
        raise RuntimeError(f"the {name} child failed ({returncode}): {stderr[-2000:]}")
    return Child.from_json(json.loads(stdout.strip().splitlines()[-1]))


def _run_child(which: str, config: Config, broker: int, directory: Path) -> Child:
    done = subprocess.run(
        _command(which, config, broker, directory),
        capture_output=True,
        text=True,
        timeout=CHILD_TIMEOUT_S,
        cwd=ROOT,
        check=False,
    )
    return _child_of(which, done.returncode, done.stdout, done.stderr)


@contextmanager
def _broker() -> Any:
    with _mosquitto() as port:
        yield port


def measure(config: Config) -> dict[str, Child]:
    """Every configuration's child, one after the other; then (full runs) the goal's two
    again, each one's windows merged with its first child's (:data:`REPEATED`)."""
    out: dict[str, Child] = {}
    with _broker() as port, tempfile.TemporaryDirectory(prefix="bench_plant_") as directory:
        for which in ("bare", "all") if config.quick else CONFIGURATIONS:
            out[which] = _run_child(which, config, port, Path(directory))
        if not config.quick:
            for which in REPEATED:
                out[which] = out[which].merged(_run_child(which, config, port, Path(directory)))
    return out


# -- two gateways on one broker ------------------------------------------------------------

#: The two gateways' ids: each serves half the lines, both on one broker, in one group.
PAIR: Final = ("plant-a", "plant-b")
#: Their children's warm-up: the time the fleet view and the host have to see every drive.
PAIR_WARM_UP_S: Final = 20.0


@dataclass(frozen=True)
class TwoGateways:
    """What a fleet view and a Sparkplug host saw of two gateways on one broker."""

    #: Every drive of both gateways.
    drives: int
    #: The drives whose JSON state the fleet view got, and the devices born (DBIRTH).
    fleet_drives: int
    born: int
    #: From the children's start to every drive in the fleet view, and to every DBIRTH
    #: (None: not all of them by the end).
    fleet_s: float | None
    born_s: float | None
    #: Each gateway's own figures, in :data:`PAIR`'s order.
    children: tuple[Child, ...]


class _Watch:
    """A fleet view (``sj300 monitor --url mqtt://...``'s) and a Sparkplug host on a broker."""

    def __init__(self, broker: int, drives: int) -> None:
        self.broker = broker
        self.drives = drives
        self.seen: set[tuple[str, str, int]] = set()
        self.born: set[str] = set()
        #: Seconds from :attr:`began` to every drive seen, by which view.
        self.times: dict[str, float] = {}
        self.began = 0.0

    def _all(self, view: str, found: set[Any]) -> None:
        if len(found) >= self.drives:
            self.times.setdefault(view, asyncio.get_running_loop().time() - self.began)

    async def fleet(self, connected: asyncio.Event) -> None:
        from sj300_async.gateway.mqtt import Fleet, StateMessage, follow, parse_fleet_url

        def on_state(state: StateMessage) -> bool:
            if state.gateway in PAIR:
                self.seen.add((state.gateway, state.line, state.node))
                self._all("fleet", self.seen)
            return True

        def on_link(problem: str | None) -> None:
            if problem is None:
                connected.set()

        fleet = Fleet(parse_fleet_url(f"mqtt://127.0.0.1:{self.broker}"))
        await follow(fleet, on_state, on_link=on_link)

    async def host(self, connected: asyncio.Event) -> None:
        from sj300_async.gateway.mqttlink.client import Client
        from sj300_async.gateway.sparkplug import decode_payload

        async with Client("127.0.0.1", self.broker, identifier="bench-plant-host") as client:
            await client.subscribe(f"spBv1.0/{GROUP}/DBIRTH/+/+", qos=0)
            connected.set()
            async for message in client.messages:
                node, device = message.topic.split("/")[3:5]
                if node in PAIR:
                    decode_payload(message.payload)  # a birth it cannot read is no birth
                    self.born.add(f"{node}/{device}")
                    self._all("sparkplug", self.born)


async def _pair_child(command: list[str], name: str) -> Child:
    process = await asyncio.create_subprocess_exec(
        *command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT
    )
    try:
        async with asyncio.timeout(CHILD_TIMEOUT_S):
            out, err = await process.communicate()
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    assert process.returncode is not None
    return _child_of(name, process.returncode, out.decode(), err.decode())


async def _two_gateways(config: Config, broker: int, directory: Path) -> TwoGateways:
    quick = config.quick
    lines = (QUICK_LINES if quick else LINES) // len(PAIR)
    drives = lines * len(PAIR) * (QUICK_DRIVES_PER_LINE if quick else DRIVES_PER_LINE)
    watch = _Watch(broker, drives)
    views = [watch.fleet, watch.host]
    connected = [asyncio.Event() for _ in views]
    tasks = [asyncio.create_task(view(event)) for view, event in zip(views, connected, strict=True)]
    try:
        async with asyncio.timeout(CLIENTS_TIMEOUT_S):  # subscribed before any gateway starts
            await asyncio.gather(*(event.wait() for event in connected))
        watch.began = asyncio.get_running_loop().time()
        commands = [
            _command(
                "mqtt+sparkplug", config, broker, directory, gateway_id=name,
                first_line=index * lines, lines=lines,
                warm_up=None if quick else PAIR_WARM_UP_S,
            )
            for index, name in enumerate(PAIR)
        ]  # fmt: skip
        children = await asyncio.gather(*map(_pair_child, commands, PAIR))
    finally:
        for task in tasks:
            task.cancel()
        failures = await asyncio.gather(*tasks, return_exceptions=True)
    for failure in failures:
        if not isinstance(failure, asyncio.CancelledError):
            raise RuntimeError(f"a view of the two gateways failed: {failure!r}")
    return TwoGateways(
        drives,
        len(watch.seen),
        len(watch.born),
        watch.times.get("fleet"),
        watch.times.get("sparkplug"),
        tuple(children),
    )


def measure_two_gateways(config: Config) -> TwoGateways:
    """Two gateways of half the lines each on a broker of their own, watched (module
    docstring)."""
    with _broker() as port, tempfile.TemporaryDirectory(prefix="bench_plant_") as directory:
        return asyncio.run(_two_gateways(config, port, Path(directory)))


def _share(delivered: int, samples: int) -> float:
    return delivered / samples if samples else math.nan


def run(config: Config) -> Section:
    """Measure each configuration, then two gateways; rows against the bare poll of the
    same run."""
    return report(measure(config), measure_two_gateways(config), measure_heap(config))


def report(
    children: dict[str, Child],
    two: TwoGateways | None = None,
    heap: dict[str, Heap] | None = None,
) -> Section:
    """The rows and notes of *children*'s figures, and of *two* gateways' and the *heap*
    children's when given."""
    bare = children["bare"]
    us = 1e6
    drives = bare.drives
    results = [
        Result(
            f"plant: every northbound, CPU per drive sample ({drives} drives at 1 Hz)",
            children["all"].best_cpu_s * us,
            bare.best_cpu_s * us,
            "µs",
            target=TARGET_ALL,
            higher_is_better=False,
            against="bare poll",
            as_multiple=True,
        )
    ]
    if "all-without-recorder" in children:
        # Issue 45: what the trip recorder adds with every northbound on (their trends and
        # line logs are the ones it reads), same run.
        results.append(
            Result(
                "plant: every northbound, the trip recorder's share of the CPU per drive sample",
                children["all"].best_cpu_s * us,
                children["all-without-recorder"].best_cpu_s * us,
                "µs",
                higher_is_better=False,
                against="without it",
                as_multiple=True,
            )
        )
    if "all-per-unit" in children:
        results.append(
            Result(
                "plant: every northbound, Modbus masters reading each unit, CPU per drive sample",
                children["all-per-unit"].best_cpu_s * us,
                bare.best_cpu_s * us,
                "µs",
                higher_is_better=False,
                against="bare poll",
                as_multiple=True,
            )
        )
    for which in (w for w in ALONE if w in children):
        results.append(
            Result(
                f"plant: {which} alone, CPU per drive sample",
                children[which].best_cpu_s * us,
                bare.best_cpu_s * us,
                "µs",
                higher_is_better=False,
                against="bare poll",
                as_multiple=True,
            )
        )
    whole = children["all"].delivery
    results += [
        Result(
            # Not the states confirmed in the window: up to a chunk of 256 is in flight
            # at each edge of it. A state is failed only by being replaced or lost.
            "plant: JSON states neither replaced nor lost, every northbound on",
            _share(
                whole["mqtt_samples"] - whole["mqtt_replaced"] - whole["mqtt_lost"],
                whole["mqtt_samples"],
            ),
            1.0,
            "share",
            target=1.0,
            against="every sample",
            percent=True,
        ),
        Result(
            "plant: Sparkplug samples not replaced, every northbound on",
            _share(whole["spb_samples"] - whole["spb_replaced"], whole["spb_samples"]),
            1.0,
            "share",
            target=1.0,
            against="every sample",
            percent=True,
        ),
    ]
    results += memory_rows(children, heap)
    results += _delay_rows(children["all"].clients)
    notes = [
        f"{drives} simulated SJ300 drives ({len(children)} children, one after the "
        "other), polled every second, each running on a long ramp; CPU per sample is "
        "`process_time` over samples, the best of each child's windows (simulators included, "
        "alike on every side).",
    ]
    for name, child in children.items():
        windows = ", ".join(f"{c * us:.0f}" for c in child.cpu_per_sample_s)
        rates = ", ".join(f"{r:.0f}" for r in child.samples_per_s)
        visible = ", ".join(f"{k} {v:.1f} s" for k, v in sorted(child.visible_s.items()))
        startup = (
            ""
            if child.opcua_startup_s is None
            else f"; OPC UA start-up {child.opcua_startup_s:.1f} s"
        )
        delivery = child.delivery
        notes.append(
            f"`{name}`: CPU per sample by window {windows} µs; samples/s {rates}; RSS "
            f"{child.rss_bytes / 2**20:.0f} MiB; started in {child.started_s:.1f} s{startup}"
            + (f"; every drive visible: {visible}" if visible else "")
            + (f"; JSON states {delivery['mqtt_states']} of {delivery['mqtt_samples']} samples "
               f"confirmed ({delivery['mqtt_replaced']} replaced, {delivery['mqtt_lost']} lost)"
               if delivery["mqtt_samples"] else "")
            + (f"; Sparkplug {delivery['spb_replaced']} of {delivery['spb_samples']} samples "
               "replaced" if delivery["spb_samples"] else "")
        )  # fmt: skip
    for name in (w for w in WITH_CLIENTS if w in children):
        clients = children[name].clients
        if clients is not None:
            notes.append(f"`{name}`: " + _clients_note(clients))
    notes += memory_notes(children, heap)  # RSS per drive for each, the heap's packages
    if two is not None:
        results += _two_rows(two)
        notes.append(_two_note(two))
    return Section(TITLE, tuple(notes), tuple(results))


def _two_rows(two: TwoGateways) -> list[Result]:
    """Every drive of both gateways in the fleet view and born to the host (the goal: all)."""
    name = f"plant: two gateways on one broker ({two.drives} drives)"
    return [
        Result(
            f"{name}, drives in the fleet view",
            two.fleet_drives,
            two.drives,
            "drives",
            target=1.0,
            against="every drive",
        ),
        Result(
            f"{name}, devices born to a Sparkplug host",
            two.born,
            two.drives,
            "drives",
            target=1.0,
            against="every drive",
        ),
    ]


def _two_note(two: TwoGateways) -> str:
    def seconds(value: float | None) -> str:
        return "never" if value is None else f"{value:.1f} s"

    each = "; ".join(
        f"`{gateway}` {child.drives} drives, CPU per sample "
        + ", ".join(f"{c * 1e6:.0f}" for c in child.cpu_per_sample_s)
        + " µs"
        for gateway, child in zip(PAIR, two.children, strict=True)
    )
    return (
        f"Two gateways (`mqtt+sparkplug`, half the lines each, one mosquitto, Sparkplug group "
        f"`{GROUP}`), watched from before their start by a fleet view (`follow`, as `sj300 "
        f"monitor --url mqtt://...`) and a Sparkplug host subscribed to the group's DBIRTHs: "
        f"every drive in the fleet view after {seconds(two.fleet_s)}, every device born after "
        f"{seconds(two.born_s)} (from the children's start, their imports and start-up "
        f"included); {each}."
    )


def _delay_rows(clients: dict[str, Any] | None) -> list[Result]:
    """A row per timed client of ``all``: its p99 against the poll interval (it keeps up)."""
    figures = {} if clients is None else clients["clients"]
    out = []
    for key, label in DELAYED:
        p99 = figures.get(key, {}).get("p99_ms")
        out.append(
            Result(
                f"plant: p99 delay sample to {label}, every northbound on",
                math.inf if p99 is None else p99,  # nothing received: never
                INTERVAL_S * 1e3,
                "ms",
                target=1.0,
                higher_is_better=False,
                against="poll interval",
                as_multiple=True,
            )
        )
    return out


def _clients_note(body: dict[str, Any]) -> str:
    """What ``all``'s clients received, and what they cost their own process."""
    figures = body["clients"]
    lag = body["loop_lag_p99_ms"]
    parts = []
    for key, label in DELAYED:
        one = figures.get(key)
        if one is None:
            continue
        text = f"{label} {one['messages']:,} messages from {one['drives']:,} drives"
        if one["p50_ms"] is not None:
            text += (
                f", delay p50 {one['p50_ms']:.0f} / p99 {one['p99_ms']:.0f} / max "
                f"{one['max_ms']:.0f} ms"
            )
        text += f", {one['errors']} errors" if one["errors"] else ""
        text += f" (**failed**: {one['failure']})" if one["failure"] else ""
        if key == "sparkplug":
            text += f", {one['births']:,} devices born while it listened"
        parts.append(text)
    modbus = figures.get("modbus")
    if modbus is not None:
        rate = modbus["reads_per_s"] or 0.0
        errors = ", ".join(f"{n} {k}" for k, n in sorted(modbus["errors"].items())) or "none"
        how = "of the summary" if modbus["summary"] else "unit by unit"
        parts.append(
            f"Modbus {modbus['masters']} master{'s' * (modbus['masters'] != 1)} reading {how}, "
            f"{rate:,.0f} reads/s of {modbus['due_per_s']:,.0f} due, errors {errors}, "
            f"{modbus['late_sweeps']} sweeps late"
            + (f" (**failed**: {modbus['failure']})" if modbus["failure"] else "")
        )
    return (
        f"`all`'s clients (benchmarks/plant_clients.py, a process of its own; OPC UA "
        f"publishing every {PUBLISHING_MS:.0f} ms, {EVENT_STREAMS} event streams; ready "
        f"{body['ready_s']:.1f} s after starting; over the {body['window_s']:.1f} s of the "
        f"windows: {body['cpu_s']:.2f} s CPU"
        + ("" if lag is None else f", its loop's lag p99 {lag:.0f} ms")
        + "): "
        + "; ".join(parts)
        + ". Delay: the client's `time.time()` on handling the message minus the sample's "
        "time as the message carries it."
    )


if __name__ == "__main__":
    main()
