"""Scale-out: two ``sj300 gateway`` processes of 32 drives each, one broker, one fleet view.

Method: one mosquitto (:mod:`mqtt_broker`); two simulated lines of 32
SJ300 drives, each served over TCP from this test's process
(:func:`~sj300_async.simulator.serve_tcp`), so the test knows what every
drive really holds; two gateway processes (``python -m sj300_async gateway
--config``, ids ``gw-a`` and ``gw-b``), each owning one line, both
publishing to the broker. Then ``sj300 monitor --url mqtt://... --json
--count 1`` (one cycle: each drive once) as a user runs it (a subprocess on
a pipe) must list each of the 64 drives once, with that drive's own values.
Then ``gw-b`` is killed with SIGKILL (it can say nothing itself), and a
second run of the monitor must show its 32 drives ``offline (stale)`` (its
last will), ``gw-a``'s 32 ``online``.

Decisions:

- **Simulators in the test's process, not ``sim://`` in each gateway.**
  Every drive gets its own set frequency (F001, polled) and one drive per
  line is tripped (E07), so a drive shown with another drive's values, or
  a gateway's drive shown under the other gateway, fails the test; with
  ``sim://`` every drive would look the same.
- **Never a sleep for a state.** A subscriber of this test's own (aiomqtt,
  on ``sj300/#``) keeps the latest state of each drive and each gateway's
  availability; the test waits for conditions on them (``wait_for``) and
  reads the processes' output. The monitor runs only once every drive's
  expected state is retained, so its first cycle is the retained states,
  one per drive (the broker hands them over on subscribing, before anything
  published later); a gateway's next state ends it.
- **Fast**: polls every 0.2 s, MQTT keepalive 1 s (the broker sees a killed
  process's socket close at once anyway; the keepalive bounds a silent
  one). The whole test takes a few seconds.
- The trip's code (``E07``) is waited for: the gateway names it only once
  the trip history was read after the trip was seen.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
import textwrap
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
from cli.clirun import TIMEOUT, Result, cli_env, sj300
from mqtt_broker import Broker, running_broker
from waiting import wait_for

from sj300_async.gateway.mqtt import AVAILABLE, UNAVAILABLE, StateMessage
from sj300_async.simulator import SimulatorServer, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

GATEWAYS = ("gw-a", "gw-b")
NODES = range(1, 33)
LINE = "hall"
TRIPPED = 7
#: How long a gateway process may take to publish every drive (a cold start on 2 busy CPUs).
STARTUP_S = 20.0


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


def set_frequency_hz(gateway: str, node: int) -> float:
    """Each drive's own set frequency: gw-a 10.25..18.00 Hz, gw-b 20.25..28.00 Hz."""
    return (10.0 if gateway == "gw-a" else 20.0) + node * 0.25


@dataclass
class Line:
    """A gateway's line: 32 simulated drives behind TCP."""

    gateway: str
    sim: SimulatedBus
    server: SimulatorServer

    @property
    def url(self) -> str:
        return f"tcp://127.0.0.1:{self.server.port}"


@contextlib.asynccontextmanager
async def simulated_line(gateway: str) -> AsyncIterator[Line]:
    sim = SimulatedBus(NODES)
    loop = asyncio.get_running_loop()
    for node, drive in sim.drives.items():
        drive.set_parameter("F001", round(set_frequency_hz(gateway, node) * 100))
    assert sim.drives[TRIPPED].trip(7, now=loop.time())
    server = await serve_tcp(sim)
    async with server:
        yield Line(gateway, sim, server)


def gateway_toml(line: Line, broker: Broker) -> str:
    return textwrap.dedent(
        f"""
        [gateway]
        id = "{line.gateway}"
        [mqtt]
        url = "{broker.url}"
        keepalive_s = 1
        [[lines]]
        name = "{LINE}"
        url = "{line.url}"
        nodes = "1-32"
        interval_s = 0.2
        parameters = ["F001"]
        """
    )


@contextlib.asynccontextmanager
async def gateway_process(
    line: Line, broker: Broker, directory: Path
) -> AsyncIterator[asyncio.subprocess.Process]:
    """``sj300 gateway --config`` on *line*; running once it printed where it publishes.

    Killed and reaped on the way out if still running (stderr: ``<id>.log``).
    """
    config = directory / f"{line.gateway}.toml"
    config.write_text(gateway_toml(line, broker), encoding="utf-8")
    log = directory / f"{line.gateway}.log"
    with log.open("wb") as err:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "sj300_async", "gateway", "--config", str(config),
            stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE, stderr=err,
            env=cli_env(),
        )  # fmt: skip
    try:
        assert proc.stdout is not None
        first = await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)
        assert first.decode().strip() == f"mqtt to {broker.url} as {line.gateway}", (
            first,
            log.read_text(),
        )
        yield proc
    finally:
        if proc.returncode is None:
            proc.kill()
        await proc.wait()


@dataclass
class Watcher:
    """What this test sees on the broker: each drive's latest state, each gateway's availability."""

    states: dict[tuple[str, int], StateMessage] = field(default_factory=dict)
    availability: dict[str, str] = field(default_factory=dict)

    def receive(self, topic: str, payload: bytes) -> None:
        parts = topic.split("/")
        if len(parts) == 3 and parts[2] == "availability":
            self.availability[parts[1]] = payload.decode()
        elif len(parts) == 5 and parts[4] == "state" and payload:
            message = StateMessage.from_json(payload)
            self.states[message.gateway, message.node] = message

    def as_expected(self, gateway: str) -> bool:
        """Every drive of *gateway* is published with its own values (the trip named)."""
        return all(
            (m := self.states.get((gateway, node))) is not None
            and m.set_frequency_hz == set_frequency_hz(gateway, node)
            and (m.trip == "E07" if node == TRIPPED else m.tripped is False)
            for node in NODES
        )


@contextlib.asynccontextmanager
async def watching(broker: Broker) -> AsyncIterator[Watcher]:
    """A subscriber to ``sj300/#``, subscribed when this enters."""
    watcher = Watcher()
    subscribed = asyncio.Event()

    async def run() -> None:
        async with aiomqtt.Client("127.0.0.1", broker.port) as client:
            await client.subscribe("sj300/#", qos=1)
            subscribed.set()
            async for message in client.messages:
                payload = message.payload if isinstance(message.payload, bytes) else b""
                watcher.receive(message.topic.value, payload)

    task = asyncio.create_task(run())
    try:
        await wait_for(lambda: subscribed.is_set() or task.done(), "the watcher subscribed")
        if task.done():
            task.result()  # its error
        yield watcher
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def assert_plausible(shown: dict[str, Any], gateway: str, node: int) -> None:
    """What the fleet view printed for one drive is that drive's truth."""
    assert (shown["gateway"], shown["line"], shown["node"]) == (gateway, LINE, node)
    assert (shown["protocol"], shown["online"]) == ("sj300", True)
    assert shown["set_frequency_hz"] == set_frequency_hz(gateway, node)
    assert shown["parameters"] == {"F001": set_frequency_hz(gateway, node)}
    # Stopped drives: no output; a tripped one names its trip.
    assert (shown["output_frequency_hz"], shown["output_current_a"]) == (0.0, 0.0)
    assert (shown["running"], shown["direction"]) == (False, "stop")
    if node == TRIPPED:
        assert (shown["tripped"], shown["trip"], shown["status"]["b"]) == (True, "E07", "TRIPPED")
        assert (shown["state"], shown["trip_meaning"]) == ("tripped", "over-voltage")
    else:
        assert (shown["tripped"], shown["trip"], shown["status"]["b"]) == (False, None, "STOPPED")
        assert (shown["state"], shown["trip_meaning"]) == ("stopped", None)
    # Polled a moment ago, on this machine's clock (Unix time, the gateway's poll).
    assert 0 <= time.time() - shown["time"] < 10, shown["time"]
    assert (shown["error"], shown["latency_s"], shown["gateway_online"]) == (None, None, True)


def by_drive(result: Result) -> dict[tuple[str, int], dict[str, Any]]:
    assert result.code == 0, result.err
    lines = result.json_lines()
    drives = {(s["gateway"], s["node"]): s for s in lines}
    assert len(drives) == len(lines) == 64, "a drive missing, or printed twice"
    return drives


async def test_two_gateways_of_32_drives_in_one_fleet_view_and_a_killed_one_goes_stale(
    broker: Broker, tmp_path: Path
) -> None:
    async with (
        simulated_line("gw-a") as line_a,
        simulated_line("gw-b") as line_b,
        watching(broker) as watcher,
        gateway_process(line_a, broker, tmp_path),
        gateway_process(line_b, broker, tmp_path) as gw_b,
    ):
        await wait_for(
            lambda: all(watcher.as_expected(g) for g in GATEWAYS),
            "every drive of both gateways published with its values",
            timeout=STARTUP_S,
            interval=0.02,
        )
        assert watcher.availability == {"gw-a": AVAILABLE, "gw-b": AVAILABLE}

        # The fleet view's first cycle: the 64 retained states, one per drive, each its own.
        result = await sj300("monitor", "--url", broker.url, "--json", "--count", "1")
        drives = by_drive(result)
        assert set(drives) == {(g, n) for g in GATEWAYS for n in NODES}
        for (gateway, node), shown in drives.items():
            assert_plausible(shown, gateway, node)
        assert result.err == ""

        # kill -9: gw-b says nothing; the broker publishes its last will.
        gw_b.send_signal(signal.SIGKILL)
        await gw_b.wait()
        await wait_for(lambda: watcher.availability.get("gw-b") == UNAVAILABLE, "gw-b's last will")
        assert watcher.availability["gw-a"] == AVAILABLE

        # A second run (plain lines on a pipe): gw-b's drives stale, gw-a's online.
        result = await sj300("monitor", "--url", broker.url, "--count", "1")
        assert result.code == 0, result.err
        rows = {line.split()[1]: line.split()[2:] for line in result.out.splitlines()}
        assert len(rows) == 64, result.out
        for gateway in GATEWAYS:
            for node in NODES:
                words = rows[f"{gateway}/{LINE}/{node:02d}"]
                if gateway == "gw-b":
                    assert words[:2] == ["offline", "(stale)"], words
                else:
                    assert words[0] == "online", words
                state = "tripped" if node == TRIPPED else "stopped"
                assert state in words, words
        # gw-a goes on publishing: its drives are not frozen in the broker.
        polled = watcher.states["gw-a", 1].time
        await wait_for(lambda: watcher.states["gw-a", 1].time > polled, "gw-a still publishing")
