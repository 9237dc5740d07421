"""MQTT: what the gateway's bridge costs per published drive state, and how soon a change shows.

Two figures, each against something measured in the same run:

1. **Gateway CPU per published drive state**, against aiomqtt publishing
   the same payloads in a tight loop. Two gateway processes run side by
   side over the same windows, each polling 32 drives on ``sim://`` every
   :data:`CPU_INTERVAL_S`: one with ``[mqtt]`` (it publishes a retained
   state per drive per poll), one without. Each process reports its own
   CPU time (``time.process_time()``) and its polls at the start and the
   end of each window; the bridge's extra CPU per message is

       (CPU per poll with MQTT - CPU per poll without) x polls / messages

   where the messages are counted by a subscriber in this process (and
   checked against the gateway's own count). The floor: a process of its
   own connects to the same broker with aiomqtt and publishes the payloads
   this process received from the gateway (same topics' shape, QoS,
   retain) in a tight loop, each publish awaited before the next; its CPU
   per message is the reference. Row: bridge / floor.
2. **Delay from a drive's change to the fleet view**, p50 and p99. This
   process serves 32 simulated drives over TCP
   (:func:`sj300_async.simulator.serve_tcp`); a gateway process polls them
   (``tcp://127.0.0.1:PORT``) every :data:`LATENCY_INTERVAL_S` and
   publishes; this process follows the broker as ``sj300 monitor --url
   mqtt://...`` does (:func:`sj300_async.gateway.mqtt.follow`: aiomqtt,
   ``StateMessage.from_json``, the fleet view's checks). It trips a drive
   (``SimulatedDrive.trip``), timestamps that, and timestamps the first
   state of that drive the fleet view gets with ``tripped`` true; then
   resets it. :data:`CHANGES` such changes over randomly chosen drives.

Decisions:

- **This module is also the children's script**
  (``python -m benchmarks.bench_mqtt gateway|floor``); a gateway child
  prints ``port 0`` once every drive is polled (and, with MQTT, published)
  once, the ready line :class:`~benchmarks._servers.ServerProcess` waits
  for (it serves no port here), and answers ``cpu``, ``stats`` and
  ``stop`` on its standard input. The gateway runs in process as
  ``sj300 gateway`` runs it (:class:`~sj300_async.gateway.Gateway`
  from a TOML configuration), with its defaults: QoS 1, Home Assistant
  discovery on (published at connect, before any window), keepalive 30 s.
- **CPU: both gateways at once, not one after the other.** The MQTT-on
  and MQTT-off gateways run over the very same windows, so drift of the
  machine hits both alike. 32 drives on ``sim://?nodes=1-32`` (the
  in-memory simulator in the gateway's process, drives' default 1 ms of
  processing, unpaced: a cycle of 32 drives takes about 0.1 s, so a
  :data:`CPU_INTERVAL_S` poll keeps both gateways at the interval's pace,
  i.e. the same polls); no trip-history reads. CPU per poll is the best
  (lowest) window of each side, after one untimed window: the estimate
  least disturbed by the rest of the machine; dividing by polls rather
  than subtracting raw CPU keeps the figure right should one side poll
  less. The subscriber is the fleet view's own loop: it gets every
  message (the broker is told to queue without limit), and its count is
  checked against the gateway's count of acknowledged states once the
  gateway stopped (its "offline" arrived: everything before it did): equal,
  or more by at most the batch in flight at the stop, which the bridge
  counts neither published nor lost (docs/BENCHMARKS.md, "mqtt").
- **The floor** publishes the payloads the gateway published, re-encoded
  from what the fleet view parsed (``StateMessage.to_json``, the bridge's
  own encoding: the same bytes) but naming a gateway id of its own, as long
  as the bridge's (a fleet view refuses a state whose payload names another
  gateway than its topic), with the bridge's QoS (1) and retain flag. Each
  publish is awaited before the next (a tight loop: "publish, PUBACK,
  publish"), since the bridge too publishes each sample as it comes (they
  come one at a time, a few milliseconds apart). The same process also
  times batches of 32 publishes awaited together (the bridge's most in
  flight), in the notes: the cheapest aiomqtt gets. Best of the floor
  runs, one after each window.
- **Latency: the line.** The simulator over TCP answers no sooner than a
  19200-baud line could carry a short exchange (``serve_tcp``'s default),
  about 11 ms per transaction, so a cycle of 32 drives (status and
  monitor) takes about 0.7 s: longer than the gateway's default interval
  (0.5 s, used here), as on a real line (2.4 s at 19200 baud). The poll
  period is then the cycle, and the delay is what a user of such a line
  sees.
- **Latency: the change** is a trip, because the status is what every poll
  reads first and what an operator wants to see first. Before each change
  this process waits a random time in [0, poll period) (seeded, ``--seed``),
  so the change lands at a random phase of the cycle, as a real fault
  does; a drive is chosen only once the fleet view has seen it not
  tripped, so the first tripped state after the change can only come from
  a poll after it. ``trips_interval_s = 0``: no trip-history read adds to
  the line after a trip. ``setpoint_interval_s = 0``: the set-frequency
  reads beside the poll (issue 27, every 2 s per drive by default) lengthen
  the cycles they fall in, which the reference (the mean cycle) does not
  model; with them the p99 was the longest cycle's (1,052 ms against a
  mean of 798), whatever the bridge did.
- **Latency: the reference** is what a poll-based system cannot beat: up to
  one poll period (the interval, or the mean cycle when it is longer)
  until the drive's next status read, plus that drive's poll (the mean
  cycle / 32), both from the poller's own statistics in the same run. The
  row reads it as an efficiency (reference / p99; with 50 changes the p99
  is their largest); the notes add p99 / interval and the part of the
  delay after the poll (from the state's ``time``, the poll's end, to its
  arrival here: bridge, broker and fleet view, both ends on this machine's
  clock).
- One mosquitto (found on PATH or in /usr/sbin) on a free loopback port,
  without persistence, started and stopped by this module; every child is
  reaped (closing its standard input ends it; killed after 5 s).
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import contextlib
import dataclasses
import faulthandler
import gc
import json
import math
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Coroutine, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, cast

from ._harness import Config, Result, Section, new_runner
from ._servers import ServerProcess

if TYPE_CHECKING:
    from sj300_async.gateway import Gateway
    from sj300_async.gateway.mqtt import BridgeStats

__all__ = [
    "CHANGES",
    "DRIVES",
    "TITLE",
    "USES_EVENT_LOOP",
    "CpuRun",
    "LatencyRun",
    "MqttRun",
    "Window",
    "main",
    "measure",
    "report",
    "run",
]

TITLE = "mqtt"
USES_EVENT_LOOP = True
#: Drives on each gateway's line.
DRIVES = 32
LINE = "bench"
#: The CPU figure's poll interval, its timed windows (full and ``--quick``) and messages
#: per floor run.
CPU_INTERVAL_S = 0.2
WINDOW_S = 3.0
QUICK_WINDOW_S = 0.5
FLOOR_MESSAGES = 2_000
QUICK_FLOOR_MESSAGES = 200
#: Untimed publishes before the floor's timed ones.
FLOOR_WARM_UP = 100
#: The latency figure's poll interval (the gateway's default) and number of changes (full
#: and ``--quick``).
LATENCY_INTERVAL_S = 0.5
CHANGES = 50
QUICK_CHANGES = 4
#: Gateway ids on the broker. The floor's payloads name the floor's own: a fleet view
#: refuses a state whose topic and payload disagree; an id as long as the bridge's keeps
#: the payloads byte for byte as long.
ON_ID, OFF_ID, FLOOR_ID, LATENCY_ID = "mqtt-on", "mqtt-off", "aiomqtt", "latency"
#: Publishes the bridge has in flight at most (its MAX_IN_FLIGHT), and the floor's second
#: mode awaits together.
MAX_IN_FLIGHT = BATCH = 256
#: The trip code of the latency figure's changes (E07, over-voltage).
TRIP_CODE = 7
#: The project's aims (docs/BENCHMARKS.md, "mqtt"): the bridge's CPU per message at most
#: 3x the floor's (the ratio reads floor / bridge); p99 within 90 % of what polling cannot
#: beat (the ratio reads polling's floor / p99, as an efficiency).
TARGET_CPU_RATIO = 1 / 3
TARGET_LATENCY_RATIO = 0.9
#: How long a child may take to poll and publish every drive once (a cold start).
READY_TIMEOUT_S = 30.0


# -- the children (their processes) -------------------------------------------------------


def _gateway_toml(gateway_id: str, url: str, interval_s: float, broker_port: int) -> str:
    mqtt = f'[mqtt]\nurl = "mqtt://127.0.0.1:{broker_port}"\n' if broker_port else ""
    return f'[gateway]\nid = "{gateway_id}"\n{mqtt}' + textwrap.dedent(
        f"""
        [[lines]]
        name = "{LINE}"
        url = "{url}"
        nodes = "1-{DRIVES}"
        interval_s = {interval_s!r}
        trips_interval_s = 0
        setpoint_interval_s = 0
        """
    )


class _Bridge(Protocol):
    """What this benchmark reads of the running MQTT northbound (``gateway.northbounds``).

    Its class is not part of the gateway's public face; its counters are.
    """

    @property
    def stats(self) -> BridgeStats: ...


class _Counts:
    """Polls of the gateway's line, counted from its poller (a child's side)."""

    def __init__(self, gateway: Gateway) -> None:
        line = gateway.lines[0]
        self.gateway = gateway
        # Kept: the gateway forgets its northbounds when it stops.
        self.bridge = cast("_Bridge | None", gateway.northbounds.get("mqtt"))
        self.poller, self.bus = line.poller, line.bus
        self.polls = 0
        self.failed = 0
        self.polled: set[int] = set()
        line.poller.on_sample(self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        self.polls += 1
        self.polled.add(sample.node)
        if sample.error is not None:
            self.failed += 1

    def states(self) -> int:
        return 0 if self.bridge is None else sum(self.bridge.stats.states.values())

    def ready(self) -> bool:
        """Every drive polled, and (with MQTT) its state acknowledged by the broker."""
        if len(self.polled) < DRIVES:
            return False
        return self.bridge is None or len(self.bridge.stats.states) == DRIVES

    def line(self, word: str) -> str:
        """``WORD polls failed states replaced lost cycles mean_cycle_s max_cycle_s``."""
        stats = self.poller.bus_stats(self.bus)
        bridge = self.bridge
        replaced = 0 if bridge is None else sum(bridge.stats.replaced.values())
        lost = 0 if bridge is None else bridge.stats.lost
        mean = stats.mean_cycle_s or 0.0
        return (
            f"{word} {self.polls} {self.failed} {self.states()} {replaced} {lost} "
            f"{stats.cycles} {mean!r} {stats.max_cycle_s!r}"
        )


def _answer_parent(loop: asyncio.AbstractEventLoop, counts: _Counts) -> None:
    """Answer ``cpu`` and ``stats`` on standard input; return at ``stop`` or when it closes."""

    async def stats() -> str:
        return counts.line("stats")

    for line in sys.stdin:
        command = line.strip()
        if command == "cpu":
            print(f"cpu {time.process_time()!r}", flush=True)
        elif command == "stats":
            print(asyncio.run_coroutine_threadsafe(stats(), loop).result(), flush=True)
        elif command == "stop":
            return
        else:
            print(f"unknown {command}", flush=True)


def _print_tasks() -> None:
    """Every asyncio task's stack on stderr: what a hung child's loop is waiting for."""
    for task in asyncio.all_tasks():
        print(f"-- {task!r}", file=sys.stderr)
        task.print_stack(file=sys.stderr)
    sys.stderr.flush()


async def _serve_gateway(gateway_id: str, url: str, interval_s: float, broker_port: int) -> None:
    from sj300_async.gateway import Gateway, parse_config

    text = _gateway_toml(gateway_id, url, interval_s, broker_port)
    config = parse_config(text, f"bench_mqtt_{gateway_id}.toml")
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGUSR1, _print_tasks)  # the parent's hang diagnosis
    async with Gateway(config, tune_collector=True) as gateway:
        counts = _Counts(gateway)
        deadline = loop.time() + READY_TIMEOUT_S
        while not counts.ready():  # a child's start-up: polling its own counters is fine
            if loop.time() > deadline:
                raise RuntimeError(f"{gateway_id}: not every drive polled and published")
            await asyncio.sleep(0.01)
        print("port 0", flush=True)  # ready (ServerProcess's ready line; no port served)
        await loop.run_in_executor(None, _answer_parent, loop, counts)
    # Stopped: every state it published is acknowledged (or counted lost).
    print(counts.line("stop"), flush=True)


async def _publish_floor(broker_port: int, payloads: Path, count: int) -> None:
    import aiomqtt

    items = [(topic, text.encode()) for topic, text in json.loads(payloads.read_text())]
    client = aiomqtt.Client(
        "127.0.0.1", broker_port, identifier=f"bench-{FLOOR_ID}", clean_session=True, keepalive=30
    )
    # As the bridge: no warning (a log record each) for the batches in flight.
    client.pending_calls_threshold = 2 * BATCH
    async with client:
        for i in range(FLOOR_WARM_UP):  # untimed
            await client.publish(*items[i % len(items)], qos=1, retain=True)
        gc.collect()
        start = time.process_time()
        for i in range(count):
            topic, payload = items[i % len(items)]
            await client.publish(topic, payload, qos=1, retain=True)
        sequential = time.process_time() - start
        gc.collect()
        start = time.process_time()
        for first in range(0, count, BATCH):
            await asyncio.gather(
                *(
                    client.publish(*items[i % len(items)], qos=1, retain=True)
                    for i in range(first, min(first + BATCH, count))
                )
            )
        batched = time.process_time() - start
    sent = FLOOR_WARM_UP + 2 * count
    print(json.dumps({"sequential_s": sequential, "batched_s": batched, "sent": sent}))


def main(argv: Sequence[str] | None = None) -> int:
    """A child's entry point: a gateway (until ``stop`` or its stdin closes), or the floor."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_mqtt")
    parser.add_argument("kind", choices=("gateway", "floor"))
    parser.add_argument("--uvloop", action="store_true", help="run on uvloop")
    parser.add_argument("--broker", type=int, default=0, help="the broker's port (0: no MQTT)")
    parser.add_argument("--id", default=ON_ID, help="gateway: its id")
    parser.add_argument("--url", default=f"sim://?nodes=1-{DRIVES}", help="gateway: its line")
    parser.add_argument("--interval", type=float, default=CPU_INTERVAL_S, help="gateway: poll")
    parser.add_argument("--payloads", type=Path, help="floor: JSON [[topic, payload], ...]")
    parser.add_argument("--count", type=int, default=FLOOR_MESSAGES, help="floor: messages")
    args = parser.parse_args(argv)
    faulthandler.enable()  # SIGABRT from the parent (a hang) dumps every thread's stack
    serve: Coroutine[Any, Any, None]
    if args.kind == "gateway":
        serve = _serve_gateway(args.id, args.url, args.interval, args.broker)
    else:
        serve = _publish_floor(args.broker, args.payloads, args.count)
    if args.uvloop:
        import uvloop

        uvloop.run(serve)
    else:
        asyncio.run(serve)
    return 0


# -- the broker ------------------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


@contextlib.contextmanager
def _mosquitto() -> Iterator[int]:
    """A mosquitto on a free loopback port (yielded), stopped and reaped on the way out.

    Raises:
        RuntimeError: mosquitto is not installed, or did not start.
    """
    path = shutil.which("mosquitto", path=f"{os.environ.get('PATH', '')}:/usr/sbin:/usr/local/sbin")
    if path is None:
        raise RuntimeError("mosquitto is not installed (Debian: apt-get install mosquitto)")
    with tempfile.TemporaryDirectory(prefix="bench_mqtt_") as directory:
        log = Path(directory) / "mosquitto.log"
        for _ in range(5):  # another process may take the free port first
            port = _free_port()
            conf = Path(directory) / "mosquitto.conf"
            # No queue limit: a subscriber that falls behind loses nothing (exact counts).
            conf.write_text(
                f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
                "max_queued_messages 0\n",
                encoding="utf-8",
            )
            with log.open("wb") as out:
                proc = subprocess.Popen(
                    [path, "-c", str(conf)],
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                )
            try:
                if _accepting(port, proc):
                    yield port
                    return
            finally:
                if proc.poll() is None:
                    proc.terminate()
                    try:
                        proc.wait(5)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                proc.wait()
        raise RuntimeError(f"mosquitto did not start: {log.read_text(errors='replace')}")


def _accepting(port: int, proc: subprocess.Popen[bytes], timeout: float = 5.0) -> bool:
    """True once *port* accepts a connection; False if the broker exited (port taken)."""
    deadline = time.monotonic() + timeout
    while proc.poll() is None:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return True
        except OSError:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
    return False


# -- the parent's side -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Stats:
    """A gateway child's counters (its ``stats`` / ``stop`` answer)."""

    polls: int
    failed: int
    #: State messages the broker acknowledged.
    states: int
    replaced: int
    lost: int
    cycles: int
    mean_cycle_s: float
    max_cycle_s: float

    @classmethod
    def parse(cls, words: Sequence[str]) -> Stats:
        polls, failed, states, replaced, lost, cycles = (int(w) for w in words[:6])
        return cls(polls, failed, states, replaced, lost, cycles, float(words[6]), float(words[7]))


@dataclass(frozen=True, slots=True)
class Window:
    """One timed window of the CPU figure: each gateway's CPU and polls, the messages seen."""

    seconds: float
    on_cpu_s: float
    on_polls: int
    off_cpu_s: float
    off_polls: int
    #: State messages of the MQTT gateway: counted here, and by the gateway.
    messages: int
    gateway_states: int

    @property
    def on_per_poll_s(self) -> float:
        return self.on_cpu_s / self.on_polls

    @property
    def off_per_poll_s(self) -> float:
        return self.off_cpu_s / self.off_polls


@dataclass(frozen=True, slots=True)
class CpuRun:
    """The CPU figure: the timed windows, the floor runs, the final counts."""

    windows: tuple[Window, ...]
    #: Each floor run: (sequential CPU s, batched CPU s), per :attr:`floor_messages` each.
    floors: tuple[tuple[float, float], ...]
    floor_messages: int
    #: Floor messages the fleet view received, and the floor processes sent.
    floor_received: int
    floor_sent: int
    #: The MQTT gateway's final counts, and the states the fleet view received from it.
    final: Stats
    received: int

    @property
    def messages_per_poll(self) -> float:
        return sum(w.messages for w in self.windows) / sum(w.on_polls for w in self.windows)

    @property
    def bridge_s(self) -> float:
        """Extra gateway CPU per published state: best window of each side (module docstring)."""
        on = min(w.on_per_poll_s for w in self.windows)
        off = min(w.off_per_poll_s for w in self.windows)
        return (on - off) / self.messages_per_poll

    @property
    def floor_s(self) -> float:
        """aiomqtt's CPU per message, each publish awaited: the best floor run."""
        return min(sequential for sequential, _ in self.floors) / self.floor_messages

    @property
    def floor_batched_s(self) -> float:
        return min(batched for _, batched in self.floors) / self.floor_messages


@dataclass(frozen=True, slots=True)
class LatencyRun:
    """The latency figure: each change's delay, and the poll plan it ran under."""

    interval_s: float
    #: Change to the fleet view, sorted (seconds).
    delays_s: tuple[float, ...]
    #: The poll's end (the state's ``time``) to the fleet view, per change, sorted.
    after_poll_s: tuple[float, ...]
    stats: Stats

    def percentile(self, p: float, values: Sequence[float] | None = None) -> float:
        """The *p*-th percentile (0..100), nearest rank, of the delays (or *values*)."""
        values = self.delays_s if values is None else values
        rank = min(len(values), max(1, math.ceil(p / 100 * len(values))))
        return values[rank - 1]

    @property
    def period_s(self) -> float:
        """The poll period: the interval, or the mean cycle when it is longer."""
        return max(self.interval_s, self.stats.mean_cycle_s)

    @property
    def drive_poll_s(self) -> float:
        """One drive's poll: the mean cycle's share of each drive."""
        return self.stats.mean_cycle_s / DRIVES

    @property
    def bound_s(self) -> float:
        """What polling cannot beat: a period until the next status read, then the poll."""
        return self.period_s + self.drive_poll_s


@dataclass(frozen=True, slots=True)
class MqttRun:
    cpu: CpuRun
    latency: LatencyRun


class _View:
    """The fleet view this process runs (``follow``), and what the benchmark reads of it."""

    def __init__(self, port: int) -> None:
        from sj300_async.gateway.mqtt import Fleet, parse_fleet_url

        self.fleet = Fleet(parse_fleet_url(f"mqtt://127.0.0.1:{port}"))
        self.counts: collections.Counter[str] = collections.Counter()
        #: The latest states of the MQTT gateway of the CPU figure (the floor's payloads).
        self.payloads: collections.deque[Any] = collections.deque(maxlen=4 * FLOOR_MESSAGES)
        self.on_latency: Callable[[Any, float], None] | None = None
        self.subscribed = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    def _on_state(self, message: Any) -> bool:
        now = asyncio.get_running_loop().time()
        self.counts[message.gateway] += 1
        if message.gateway == ON_ID:
            self.payloads.append(message)
        elif message.gateway == LATENCY_ID and self.on_latency is not None:
            self.on_latency(message, now)
        return True

    def _on_link(self, problem: str | None) -> None:
        if problem is None:
            self.subscribed.set()
        else:
            raise RuntimeError(f"the fleet view lost the broker: {problem}")

    async def __aenter__(self) -> _View:
        from sj300_async.gateway.mqtt import follow

        self._task = asyncio.create_task(follow(self.fleet, self._on_state, on_link=self._on_link))
        waiting = asyncio.create_task(self.subscribed.wait())
        await asyncio.wait({self._task, waiting}, return_when=asyncio.FIRST_COMPLETED)
        waiting.cancel()
        if self._task.done():
            self._task.result()  # its error
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    def check(self) -> None:
        """Raise the fleet view's error, if it ended."""
        if self._task is not None and self._task.done():
            self._task.result()
            raise RuntimeError("the fleet view ended")

    async def until(self, condition: Callable[[], bool], what: str, timeout: float) -> None:
        """Return once *condition* holds (checked every 10 ms)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while not condition():
            self.check()
            if loop.time() > deadline:
                raise RuntimeError(f"timed out after {timeout:g} s waiting for {what}")
            await asyncio.sleep(0.01)


def _gateway(
    stack: contextlib.ExitStack,
    gateway_id: str,
    url: str,
    interval_s: float,
    broker_port: int,
    *,
    uvloop: bool,
) -> ServerProcess:
    """Start a gateway child (blocking until it is ready); *stack* ends it."""
    args = ["--id", gateway_id, "--url", url, "--interval", repr(interval_s)]
    args += ["--broker", str(broker_port)]
    process = ServerProcess("gateway", uvloop=uvloop, module="benchmarks.bench_mqtt", args=args)
    return stack.enter_context(process)


#: The longest a gateway child may take to answer a command (a stop flushes and disconnects).
ASK_TIMEOUT_S = 60.0


async def _ask(gateway: ServerProcess, command: str) -> list[str]:
    """*command*'s answer; a child that does not answer in time dumps its threads and fails.

    A full clean-clone `make test` once saw a child not answer (not reproduced
    since): this turns such a hang into an error that shows where it was.
    """
    try:
        return await asyncio.wait_for(asyncio.to_thread(gateway.ask, command), ASK_TIMEOUT_S)
    except TimeoutError:
        dump = gateway.dump_and_kill()
        raise RuntimeError(
            f"{gateway.kind} child did not answer {command!r} in {ASK_TIMEOUT_S:g} s:\n{dump}"
        ) from None


async def _sample(gateway: ServerProcess) -> tuple[float, Stats]:
    cpu = float((await _ask(gateway, "cpu"))[0])
    return cpu, Stats.parse(await _ask(gateway, "stats"))


async def _stop(gateway: ServerProcess) -> Stats:
    """Stop the gateway (cleanly: it flushes and says offline); its final counts."""
    return Stats.parse(await _ask(gateway, "stop"))


def _floor_run(port: int, payloads: Path, count: int, *, uvloop: bool) -> dict[str, Any]:
    args = [sys.executable, "-m", "benchmarks.bench_mqtt", "floor", "--broker", str(port)]
    args += ["--payloads", str(payloads), "--count", str(count)]
    if uvloop:
        args.append("--uvloop")
    root = Path(__file__).parent.parent
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(root), env.get("PYTHONPATH", "")) if p)
    done = subprocess.run(args, cwd=root, env=env, capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        raise RuntimeError(f"the floor failed: {done.stderr.strip()}")
    result: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
    return result


async def _measure_cpu(view: _View, port: int, config: Config, directory: Path) -> CpuRun:
    from sj300_async.gateway.mqtt import Topics

    window_s = QUICK_WINDOW_S if config.quick else WINDOW_S
    count = QUICK_FLOOR_MESSAGES if config.quick else FLOOR_MESSAGES
    uvloop = config.loop == "uvloop"
    url = f"sim://?nodes=1-{DRIVES}"
    windows: list[Window] = []
    floors: list[tuple[float, float]] = []
    floor_sent = 0
    payloads = directory / "payloads.json"
    with contextlib.ExitStack() as stack:
        on, off = await asyncio.gather(
            asyncio.to_thread(_gateway, stack, ON_ID, url, CPU_INTERVAL_S, port, uvloop=uvloop),
            asyncio.to_thread(_gateway, stack, OFF_ID, url, CPU_INTERVAL_S, 0, uvloop=uvloop),
        )
        for i in range(config.repeats + 1):  # the first window untimed
            (on_cpu, on_stats), (off_cpu, off_stats) = await asyncio.gather(
                _sample(on), _sample(off)
            )
            seen = view.counts[ON_ID]
            start = time.perf_counter()
            await asyncio.sleep(window_s)  # the window: the gateways poll and publish
            (on_cpu2, on_stats2), (off_cpu2, off_stats2) = await asyncio.gather(
                _sample(on), _sample(off)
            )
            window = Window(
                time.perf_counter() - start,
                on_cpu2 - on_cpu,
                on_stats2.polls - on_stats.polls,
                off_cpu2 - off_cpu,
                off_stats2.polls - off_stats.polls,
                view.counts[ON_ID] - seen,
                on_stats2.states - on_stats.states,
            )
            if on_stats2.failed or off_stats2.failed:
                raise RuntimeError("a poll failed on sim://")
            if i == 0:
                # The floor's payloads: what the gateway published, as the fleet view read it.
                items = [
                    [
                        Topics(FLOOR_ID).state(m.line, m.node),
                        dataclasses.replace(m, gateway=FLOOR_ID).to_json().decode(),
                    ]
                    for m in view.payloads
                ]
                payloads.write_text(json.dumps(items), encoding="utf-8")
                continue
            windows.append(window)
            floor = await asyncio.to_thread(_floor_run, port, payloads, count, uvloop=uvloop)
            floors.append((floor["sequential_s"], floor["batched_s"]))
            floor_sent += floor["sent"]
        final = await _stop(on)
        await _stop(off)
    # Stopped: its "offline" came after everything it published (one publisher's messages
    # arrive in order), and the floor's processes awaited each publish.
    await view.until(
        lambda: view.fleet.gateways.get(ON_ID) is False and view.counts[FLOOR_ID] >= floor_sent,
        "the gateway's offline and every floor message at the fleet view",
        timeout=10,
    )
    # A clean stop cancels the bridge's batch in flight: the gateway counts those
    # messages lost (none is confirmed), though some may reach the broker. So the view
    # may get up to that many more than were published, and nothing else is lost.
    uncounted = view.counts[ON_ID] - final.states
    if not 0 <= uncounted <= final.lost <= MAX_IN_FLIGHT:
        raise RuntimeError(
            f"the fleet view got {view.counts[ON_ID]} states, the gateway published "
            f"{final.states} ({final.lost} lost)"
        )
    if view.counts[FLOOR_ID] != floor_sent:
        raise RuntimeError(f"the fleet view got {view.counts[FLOOR_ID]} of {floor_sent}")
    return CpuRun(
        tuple(windows),
        tuple(floors),
        count,
        view.counts[FLOOR_ID],
        floor_sent,
        final,
        view.counts[ON_ID],
    )


async def _measure_latency(view: _View, port: int, config: Config) -> LatencyRun:
    from sj300_async.simulator import serve_tcp
    from sj300_async.simulator.sj300 import SimulatedBus

    interval = LATENCY_INTERVAL_S
    changes = QUICK_CHANGES if config.quick else CHANGES
    loop = asyncio.get_running_loop()
    rng = random.Random(config.seed)
    sim = SimulatedBus(range(1, DRIVES + 1))
    tripped: dict[int, bool | None] = {}
    waiting: dict[int, asyncio.Future[tuple[float, float]]] = {}

    def on_state(message: Any, now: float) -> None:
        tripped[message.node] = message.tripped
        future = waiting.get(message.node)
        if message.tripped and future is not None and not future.done():
            future.set_result((now, time.time() - message.time))

    view.on_latency = on_state
    delays: list[float] = []
    after_poll: list[float] = []
    async with await serve_tcp(sim) as server:
        with contextlib.ExitStack() as stack:
            gateway = await asyncio.to_thread(
                _gateway,
                stack,
                LATENCY_ID,
                f"tcp://127.0.0.1:{server.port}",
                interval,
                port,
                uvloop=config.loop == "uvloop",
            )
            nodes = list(sim.drives)
            await view.until(
                lambda: all(tripped.get(n) is False for n in nodes), "every drive seen", 10
            )
            # A poll period: the interval, or the cycle when it is longer.
            period = max(interval, Stats.parse(await _ask(gateway, "stats")).mean_cycle_s)
            previous = 0
            for _ in range(changes):
                node = rng.choice([n for n in nodes if tripped.get(n) is False and n != previous])
                await asyncio.sleep(rng.uniform(0, period))  # a random phase of the poll
                future: asyncio.Future[tuple[float, float]] = loop.create_future()
                waiting[node] = future
                changed = loop.time()
                if not sim.drives[node].trip(TRIP_CODE, now=changed):
                    raise RuntimeError(f"drive {node} was tripped already")
                seen, after = await asyncio.wait_for(future, 10 * interval + 5)
                del waiting[node]
                delays.append(seen - changed)
                after_poll.append(after)
                sim.drives[node].reset(loop.time())
                previous = node
            stats = await _stop(gateway)
    view.on_latency = None
    if stats.failed:
        raise RuntimeError(f"{stats.failed} polls failed on the simulated line")
    return LatencyRun(interval, tuple(sorted(delays)), tuple(sorted(after_poll)), stats)


async def _measure(config: Config, port: int, directory: Path) -> MqttRun:
    async with _View(port) as view:
        cpu = await _measure_cpu(view, port, config, directory)
        latency = await _measure_latency(view, port, config)
        view.check()
    return MqttRun(cpu, latency)


def measure(config: Config) -> MqttRun:
    """Both figures, on one broker.

    Raises:
        RuntimeError: mosquitto or aiomqtt missing, a child did not start, a poll failed,
            or a published state did not reach the fleet view.
    """
    try:
        import aiomqtt  # noqa: F401  (the gateway extra)
    except ImportError:
        raise RuntimeError(
            "the mqtt benchmark needs aiomqtt: pip install 'sj300-async[gateway]'"
        ) from None
    with (
        _mosquitto() as port,
        tempfile.TemporaryDirectory(prefix="bench_mqtt_") as directory,
        new_runner(config.loop) as runner,
    ):
        return runner.run(_measure(config, port, Path(directory)))


def run(config: Config) -> Section:
    """Measure the bridge's CPU per published state, and a change's delay to the fleet view."""
    return report(measure(config), config)


def report(result: MqttRun, config: Config) -> Section:
    """The notes and rows of a measurement made with *config*."""
    cpu, lat = result.cpu, result.latency
    us, ms = 1e6, 1e3
    window_s = QUICK_WINDOW_S if config.quick else WINDOW_S
    best_on = min(w.on_per_poll_s for w in cpu.windows)
    best_off = min(w.off_per_poll_s for w in cpu.windows)
    messages = sum(w.messages for w in cpu.windows)
    states = sum(w.gateway_states for w in cpu.windows)
    polls = sum(w.on_polls for w in cpu.windows), sum(w.off_polls for w in cpu.windows)
    p50, p99 = lat.percentile(50), lat.percentile(99)
    after = lat.after_poll_s
    notes: tuple[str, ...] = (
        f"CPU: two gateway processes at once, each polling {DRIVES} drives on "
        f"`sim://?nodes=1-{DRIVES}` (status and monitor) every {CPU_INTERVAL_S:g} s, one with "
        f"MQTT (QoS 1, retained state per drive per poll), one without; {len(cpu.windows)} "
        f"timed windows of {window_s:g} s after an untimed one. Polls in the windows: "
        f"{polls[0]:,} with MQTT, {polls[1]:,} without; state messages: {messages:,} received "
        f"by the fleet view ({states:,} by the gateway's count); {cpu.messages_per_poll:.3f} "
        "per poll.",
        f"Gateway CPU per poll, best window: {best_on * us:.1f} µs with MQTT, "
        f"{best_off * us:.1f} µs without: {cpu.bridge_s * us:.1f} µs per published state. "
        f"The floor: aiomqtt publishing the same payloads (QoS 1, retained) in a process of "
        f"its own, each awaited: {cpu.floor_s * us:.1f} µs per message; "
        f"{BATCH} awaited together: {cpu.floor_batched_s * us:.1f} µs (best of "
        f"{len(cpu.floors)} runs of {cpu.floor_messages:,}). Bridge / floor: "
        f"{cpu.bridge_s / cpu.floor_s:.2f}x (batched floor: "
        f"{cpu.bridge_s / cpu.floor_batched_s:.2f}x).",
        f"Counts: the MQTT gateway published {cpu.final.states:,} states in all by its own "
        f"count ({cpu.final.replaced} replaced before sending, {cpu.final.lost} lost), the "
        f"fleet view received {cpu.received:,} ({cpu.received - cpu.final.states} more: in "
        "flight when the gateway stopped, which the bridge does not count); the floor sent "
        f"{cpu.floor_sent:,}, the fleet view received {cpu.floor_received:,}.",
        "",
        f"Latency: {len(lat.delays_s)} trips of a random drive of {DRIVES} (this process's "
        f"simulator over TCP), each at a random phase; the gateway polls every "
        f"{lat.interval_s:g} s; its cycle took {lat.stats.mean_cycle_s * ms:.0f} ms on average "
        f"({lat.stats.max_cycle_s * ms:.0f} ms at most, {lat.stats.cycles} cycles).",
        "",
        "| change to fleet view | p50 | p90 | p99 | max |",
        "|---|---:|---:|---:|---:|",
        f"| whole delay, ms | {p50 * ms:.0f} | {lat.percentile(90) * ms:.0f} | {p99 * ms:.0f} "
        f"| {lat.delays_s[-1] * ms:.0f} |",
        f"| after the poll (bridge, broker, fleet view), ms | "
        f"{lat.percentile(50, after) * ms:.1f} | {lat.percentile(90, after) * ms:.1f} "
        f"| {lat.percentile(99, after) * ms:.1f} | {after[-1] * ms:.1f} |",
        "",
        f"p99 / poll interval: {p99 / lat.interval_s:.2f}; p50 / interval: "
        f"{p50 / lat.interval_s:.2f}. What polling cannot beat: a poll period "
        f"({lat.period_s * ms:.0f} ms: the interval, or the mean cycle when longer) plus one "
        f"drive's poll ({lat.drive_poll_s * ms:.1f} ms) = {lat.bound_s * ms:.0f} ms; p99 / that: "
        f"{p99 / lat.bound_s:.2f}. (With {len(lat.delays_s)} changes, p99 is the "
        f"{min(len(lat.delays_s), math.ceil(0.99 * len(lat.delays_s)))}th of them, sorted.)",
    )
    results = (
        Result(
            "mqtt: gateway CPU per published drive state (vs aiomqtt publishing the same)",
            cpu.bridge_s * us,
            cpu.floor_s * us,
            "µs",
            TARGET_CPU_RATIO,
            higher_is_better=False,
            against="aiomqtt loop",
        ),
        Result("mqtt: drive change to fleet view, p50", p50 * ms, None, "ms"),
        Result(
            "mqtt: drive change to fleet view, p99 (vs poll period + one drive's poll)",
            p99 * ms,
            lat.bound_s * ms,
            "ms",
            TARGET_LATENCY_RATIO,
            higher_is_better=False,
            against="polling's floor",
            percent=True,
        ),
    )
    return Section(TITLE, notes, results)


if __name__ == "__main__":
    sys.exit(main())
