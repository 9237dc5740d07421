"""``sj300 monitor``: one record for a drive sample, one meaning of ``--count`` (issue 27, item 2).

- ``--json`` prints one record shape (:class:`~sj300_async.cli._record.DriveRecord`)
  whether the sample was polled on a bus or received from a gateway on a
  broker: the same names for the same values, one wall-clock ``time`` (the
  sample's), and what only one source knows null on the other. The same
  drives are shown both ways: a TCP simulator polled by the monitor, then
  by a real ``sj300 gateway`` publishing to a real mosquitto.
- ``--count N`` is N cycles (one sample of every drive) on both.

Nothing sleeps for a state: the running monitors are read line by line
until what is awaited shows.
"""

from __future__ import annotations

import asyncio
import json
import signal
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from mqtt_broker import Broker, running_broker

import sj300_async as sj
from sj300_async.cli._board import Board
from sj300_async.cli._record import FIELDS
from sj300_async.gateway.mqtt import Fleet, FleetUrl, StateMessage, Topics
from sj300_async.profiles import get_profile

from .clirun import TIMEOUT, TcpSim, cli_env, running, sj300

#: The values a bus and a broker show alike for one drive (parameters differ: the
#: monitor polls the set frequency as F001, the gateway reads it apart).
_SAME_VALUES = (
    "node", "protocol", "online", "state", "running", "tripped", "trip", "trip_meaning",
    "direction", "output_frequency_hz", "set_frequency_hz", "output_current_a",
    "output_voltage_v", "output_torque_percent", "power_kw", "status",
)  # fmt: skip


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


async def _records_until(proc: asyncio.subprocess.Process, done: Any) -> dict[int, dict[str, Any]]:
    """Read *proc*'s JSON lines until ``done(latest by node)``; the latest record of each node."""
    assert proc.stdout is not None
    latest: dict[int, dict[str, Any]] = {}
    async with asyncio.timeout(TIMEOUT):
        while not done(latest):
            line = await proc.stdout.readline()
            assert line, "the monitor ended early"
            record = json.loads(line)
            assert list(record) == list(FIELDS), record
            latest[record["node"]] = record
    return latest


async def _stop(proc: asyncio.subprocess.Process) -> None:
    proc.send_signal(signal.SIGTERM)
    _, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 0, err


def _named(latest: dict[int, dict[str, Any]]) -> bool:
    """Node 2's trip named and node 3's set frequency read (the gateway reads it apart)."""
    return (
        latest.get(2, {}).get("trip") is not None
        and latest.get(3, {}).get("set_frequency_hz") is not None
    )


# --- item 2: one record ----------------------------------------------------------------------


async def test_a_drive_sample_is_one_record_from_a_bus_and_from_a_broker(
    tcp_sim: TcpSim, broker: Broker
) -> None:
    loop = asyncio.get_running_loop()
    tcp_sim.bus.drives[2].trip(7, now=loop.time())  # E07 over-voltage
    tcp_sim.bus.drives[3].set_parameter("F001", 4500)
    start = time.time()

    # The bus, polled by the monitor.
    args = ("--url", tcp_sim.url, "--nodes", "2-3", "--interval", "0.05", "--json")
    async with running("monitor", *args) as proc:
        bus = await _records_until(proc, _named)
        await _stop(proc)

    # The same drives, polled by a gateway and shown from its broker.
    gateway = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sj300_async", "gateway", "--url", tcp_sim.url, "--nodes", "2-3",
        "--mqtt", broker.url, "--id", "gw-x",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env=cli_env(),
    )  # fmt: skip
    try:
        async with running("monitor", "--url", broker.url, "--json") as proc:
            mqtt = await _records_until(proc, _named)
            await _stop(proc)
    finally:
        gateway.terminate()
        await asyncio.wait_for(gateway.communicate(), TIMEOUT)
    end = time.time()

    for node in (2, 3):
        b, m = bus[node], mqtt[node]
        assert {name: b[name] for name in _SAME_VALUES} == {name: m[name] for name in _SAME_VALUES}
        # One clock: the wall clock, at the sample (an event loop's would be far from now).
        assert start <= b["time"] <= end
        assert start <= m["time"] <= end
        # What only a bus knows, and only a broker says: null on the other.
        assert (b["gateway"], b["gateway_online"], b["lapse_pending"]) == (None, None, None)
        assert b["line"].startswith("tcp://127.0.0.1:")  # the bus itself
        assert b["error"] is None
        assert isinstance(b["latency_s"], float)
        assert (m["gateway"], m["line"], m["gateway_online"]) == ("gw-x", "line1", True)
        assert (m["error"], m["latency_s"], m["lapse_pending"]) == (None, None, False)
    assert bus[2]["state"] == "tripped"
    assert (bus[2]["trip"], bus[2]["trip_meaning"]) == ("E07", "over-voltage")
    assert (bus[3]["state"], bus[3]["direction"]) == ("stopped", "stop")
    assert bus[3]["set_frequency_hz"] == 45.0
    assert bus[3]["status"] == {"a": "STOPPING", "b": "STOPPED", "c": "STOP"}
    assert bus[3]["parameters"] == {"F001": 45.0}


async def test_a_bus_records_time_is_its_samples_not_when_it_is_printed() -> None:
    async with sj.open_bus("sim://?nodes=1") as bus:
        board = Board(bus, get_profile("sj300"), [1], demo=False)
        poller = sj.Poller(interval_s=0.01)
        poller.add(bus, [1])
        async with poller:
            sample = await anext(poller.samples())
        loop = asyncio.get_running_loop()
        wall, now = time.time(), loop.time()
        # The same sample, taken 60 s ago by the event loop's clock.
        old = type(sample)(**{**_fields(sample), "timestamp": now - 60.0})
        board.update(old)
        record = board.record(old)
    assert abs(record.time - (wall - 60.0)) < 1.0
    assert record.line == "sim://(nodes 1)"


def _fields(sample: sj.Sample) -> dict[str, Any]:
    return {name: getattr(sample, name) for name in sample.__dataclass_fields__}


# --- item 2: --count means the same on both ---------------------------------------------------


def _state(gateway: str, node: int, *, online: bool = True, hz: float = 10.0) -> StateMessage:
    return StateMessage(
        gateway, "hall", node, "sj300", time.time(), online, hz, 1.0, 200.0, "forward",
        True, False, state="running",
    )  # fmt: skip


async def _publish(broker: Broker, message: StateMessage, *, retain: bool) -> None:
    topic = Topics(message.gateway).state(message.line, message.node)
    await broker.publish(topic, message.to_json(), retain=retain)


async def test_count_counts_cycles_of_every_drive_on_a_broker_as_on_a_bus(
    broker: Broker,
) -> None:
    """A cycle waits for every drive that is online, whose gateway is: not the others."""
    await broker.publish(Topics("gw-b").availability, "offline", retain=True)  # its last will
    retained = [
        _state("gw-a", 1),
        _state("gw-a", 2),
        _state("gw-a", 3, online=False),  # offline: not waited for
        _state("gw-b", 1),  # its gateway is gone: not waited for
    ]
    for message in retained:
        await _publish(broker, message, retain=True)
    async with running("monitor", "--url", broker.url, "--json", "--count", "2") as proc:
        assert proc.stdout is not None
        first = [json.loads(await proc.stdout.readline()) for _ in retained]
        # Cycle 2: gw-a/1 twice, then gw-a/2 completes it: the view ends there.
        for node, hz in ((1, 21.0), (1, 22.0), (2, 23.0)):
            await _publish(broker, _state("gw-a", node, hz=hz), retain=False)
        out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 0, err
    assert sorted((r["gateway"], r["node"]) for r in first) == [
        ("gw-a", 1), ("gw-a", 2), ("gw-a", 3), ("gw-b", 1),
    ]  # fmt: skip
    second = [json.loads(line) for line in out.decode().splitlines()]
    assert [(r["node"], r["output_frequency_hz"]) for r in second] == [
        (1, 21.0),
        (1, 22.0),
        (2, 23.0),
    ]


async def test_count_1_on_a_broker_nobody_publishes_to_ends_after_the_timeout(
    broker: Broker,
) -> None:
    """The retained states are the first cycle; no drive sends again: --timeout ends it."""
    for node in (1, 2, 3):
        await _publish(broker, _state("gw-a", node), retain=True)
    args = ("--url", broker.url, "--json", "--count", "1", "--timeout", "1")
    result = await sj300("monitor", *args)
    assert result.code == 0, result.err
    assert sorted(r["node"] for r in result.json_lines()) == [1, 2, 3]


async def test_count_ends_when_a_gateway_dies_mid_count(broker: Broker) -> None:
    """A review's view hung: the gateway killed after the first cycle, its last will
    came, and no state would ever end the cycle. --timeout without a state ends it."""
    for node in (1, 2):
        await _publish(broker, _state("gw-a", node), retain=True)
    args = ("--url", broker.url, "--json", "--count", "5", "--timeout", "0.5")
    async with running("monitor", *args) as proc:
        assert proc.stdout is not None
        first = [json.loads(await proc.stdout.readline()) for _ in range(2)]
        await _publish(broker, _state("gw-a", 1, hz=21.0), retain=False)  # cycle 2 begins
        await broker.publish(Topics("gw-a").availability, "offline", retain=True)  # the will
        out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 0, err
    assert sorted(r["node"] for r in first) == [1, 2]
    assert [json.loads(line)["node"] for line in out.decode().splitlines()] == [1]


def test_the_fleets_cycles() -> None:
    fleet = Fleet(FleetUrl("mqtt", "h", 1883))

    def receive(message: StateMessage) -> tuple[int, int]:
        topic = Topics(message.gateway).state(message.line, message.node)
        assert fleet.receive(topic, message.to_json()) is not None
        return fleet.cycle, fleet.cycles

    # The first cycle: every drive once, however many; it ends when one sends again.
    assert receive(_state("gw-a", 1)) == (1, 0)
    assert receive(_state("gw-a", 2)) == (1, 0)
    assert receive(_state("gw-b", 1)) == (1, 0)
    assert receive(_state("gw-a", 1)) == (2, 1)
    assert receive(_state("gw-a", 2)) == (2, 1)
    assert receive(_state("gw-b", 1)) == (2, 2)  # every drive: the second cycle is complete
    # A gateway gone, a drive offline: the cycle does not wait for them.
    assert fleet.receive(Topics("gw-b").availability, b"offline") is None
    assert receive(_state("gw-a", 2, online=False)) == (3, 2)
    assert receive(_state("gw-a", 1)) == (3, 3)
    # A drive first heard of during a cycle is in it; a later one waits for it.
    assert receive(_state("gw-a", 9)) == (4, 3)
    assert receive(_state("gw-a", 1)) == (4, 4)
    assert receive(_state("gw-a", 1)) == (5, 4)
    assert receive(_state("gw-a", 9)) == (5, 5)

    # A gateway that dies mid-cycle sends no state that would end it: recheck() does.
    assert fleet.receive(Topics("gw-b").availability, b"online") is None
    assert receive(_state("gw-b", 1)) == (6, 5)  # back during cycle 6: in it, not awaited
    assert receive(_state("gw-a", 1)) == (6, 5)
    assert receive(_state("gw-a", 9)) == (6, 6)
    assert receive(_state("gw-a", 1)) == (7, 6)
    assert receive(_state("gw-a", 9)) == (7, 6)  # cycle 7 waits for gw-b/1 too
    assert fleet.receive(Topics("gw-b").availability, b"offline") is None  # its last will
    assert fleet.cycles == 6
    fleet.recheck()
    assert fleet.cycles == 7

    # Nothing sent again (nobody publishes): the consumer ends the first cycle.
    quiet = Fleet(FleetUrl("mqtt", "h", 1883))
    quiet.end_first_cycle()
    assert quiet.cycles == 0  # nothing heard: no cycle
    topic = Topics("gw-a").state("hall", 1)
    quiet.receive(topic, _state("gw-a", 1).to_json())
    quiet.end_first_cycle()
    assert (quiet.cycle, quiet.cycles) == (1, 1)


async def test_count_says_what_it_counts_in_the_help() -> None:
    result = await sj300("monitor", "--help")
    assert result.code == 0
    text = " ".join(result.out.split())
    assert "stop after N cycles, a cycle being one sample of every drive" in text
    assert "on mqtt:// the states the broker hands over on subscribing" in text
