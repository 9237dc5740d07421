"""Fixtures of the Sparkplug tests: a broker, Tahu's codec, a gateway's configuration.

Each test gets its own mosquitto (tests/mqtt_broker.py) and its own node
process with Eclipse Tahu's codec (host.py), and enters its gateway in its
own task.
"""

from __future__ import annotations

import contextlib
import textwrap
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from mqtt_broker import Broker, running_broker
from mqtt_misbehaving import MisbehavingBroker
from waiting import wait_for

from sj300_async.gateway import Gateway, GatewayDrive, parse_config
from sj300_async.gateway.sparkplug import EdgeNode
from sj300_async.simulator import SimulatorServer, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .host import Codec, codec

#: Drives 1-2 may be run and have A004 and F002 written; 3-4 are read-only.
GRANTS = """
    [[lines.writes]]
    nodes = "1-2"
    parameters = ["A004", "F002"]
    control = true
"""


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


@pytest.fixture
async def tahu() -> AsyncIterator[Codec]:
    async with codec() as c:
        yield c


@dataclass
class SimLine:
    sim: SimulatedBus
    server: SimulatorServer

    @property
    def url(self) -> str:
        return f"tcp://127.0.0.1:{self.server.port}"


@pytest.fixture
async def sim_line() -> AsyncIterator[SimLine]:
    """SJ300 drives 1..4 served over TCP."""
    sim = SimulatedBus(range(1, 5))
    server = await serve_tcp(sim)
    async with server:
        yield SimLine(sim, server)


def spb_toml(
    url: str,
    broker: Broker | MisbehavingBroker,
    *,
    mqtt_extra: str = "",
    interval_s: float = 0.1,
) -> str:
    """A gateway ``gw1`` on *url* (drives 1-4, GRANTS) with Sparkplug in group ``plant``."""
    return textwrap.dedent(
        f"""
            [gateway]
            id = "gw1"
            stale_after_s = 2
            [sparkplug]
            url = "{broker.url}"
            group_id = "plant"
            {mqtt_extra}
            [[lines]]
            name = "hall"
            url = "{url}"
            nodes = "1-4"
            interval_s = {interval_s}
            parameters = ["A004", "F002"]
            lease_scope = "connection"
            lease_s = 60
            """
    ) + textwrap.dedent(GRANTS)


@contextlib.asynccontextmanager
async def running_gateway(text: str) -> AsyncIterator[Gateway]:
    async with Gateway(parse_config(text, "test.toml")) as gateway:
        yield gateway


def edge(gateway: Gateway) -> EdgeNode:
    node = gateway.northbounds["sparkplug"]
    assert isinstance(node, EdgeNode)
    return node


def drive(gateway: Gateway, node: int) -> GatewayDrive:
    found = gateway.drive("hall", node)
    assert found is not None
    return found


async def polled(gateway: Gateway) -> None:
    await wait_for(
        lambda: all(d.readings.last_ok is not None for d in gateway.drives), "a first good sample"
    )
