"""Fixtures of the gateway tests: a simulated line over TCP with its line log, and a gateway."""

from __future__ import annotations

import contextlib
import textwrap
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field

import pytest
from pymodbus.client import AsyncModbusTcpClient
from waiting import wait_for

from sj300_async import sj300 as sj3
from sj300_async.gateway import Gateway, GatewayDrive, parse_config
from sj300_async.gateway.http._northbound import HttpNorthbound
from sj300_async.gateway.modbus._northbound import ModbusNorthbound
from sj300_async.simulator import SimulatorServer, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.wire import BadFrame, Discarded


@dataclass
class LineLog:
    """Every chunk that crossed the simulated line, with the loop time it did."""

    chunks: list[tuple[float, str, bytes]] = field(default_factory=list)

    def record(self, clock: Callable[[], float]) -> Callable[[str, bytes], None]:
        return lambda direction, data: self.chunks.append((clock(), direction, data))

    def frames(self) -> list[tuple[float, str, int, object]]:
        """Whole frames in line order: ``(time, "rx" | "tx", node, event)``."""
        parsers: dict[str, sj3.RequestParser | sj3.ReplyParser] = {
            "rx": sj3.RequestParser(),
            "tx": sj3.ReplyParser(),
        }
        out: list[tuple[float, str, int, object]] = []
        for when, direction, data in self.chunks:
            for event in parsers[direction].feed(data):
                if isinstance(event, BadFrame | Discarded):
                    raise AssertionError(f"damaged {direction} bytes on a clean line: {event}")
                out.append((when, direction, event.node, event))
        return out

    def requests(self) -> list[sj3.Request]:
        parser = sj3.RequestParser()
        return [
            e
            for _, d, data in self.chunks
            if d == "rx"
            for e in parser.feed(data)
            if isinstance(e, sj3.Request)
        ]

    def interleaved(self) -> list[str]:
        """Where a request went out before the previous one's answer (none on a one-master line)."""
        problems = []
        waiting: object = None
        for when, direction, node, event in self.frames():
            if direction == "rx":
                if waiting is not None:
                    problems.append(f"{when:.4f}: {event} sent while {waiting} was unanswered")
                waiting = None if node == sj3.BROADCAST else event
            else:
                if waiting is None or getattr(waiting, "node", None) != node:
                    problems.append(f"{when:.4f}: answer {event} to no request of node {node}")
                waiting = None
        return problems


@dataclass
class SimLine:
    sim: SimulatedBus
    server: SimulatorServer
    log: LineLog

    @property
    def url(self) -> str:
        return f"tcp://127.0.0.1:{self.server.port}"


@pytest.fixture
async def sim_line() -> AsyncIterator[SimLine]:
    """Drives 1..4 served over TCP (replies as soon as a 19200-baud line allows)."""
    import asyncio

    sim = SimulatedBus(range(1, 5))
    log = LineLog()
    server = await serve_tcp(sim, tap=log.record(asyncio.get_running_loop().time))
    async with server:
        yield SimLine(sim, server, log)


def gateway_toml(url: str, extra: str = "", line_extra: str = "") -> str:
    """A gateway on *url* serving Modbus on a free loopback port."""
    return textwrap.dedent(
        f"""
            [modbus]
            listen = "127.0.0.1:0"
            {extra}
            [[lines]]
            name = "hall"
            url = "{url}"
            nodes = "1-4"
            interval_s = 0.1
            parameters = ["F001", "A004", "F002"]
            """
    ) + textwrap.dedent(line_extra)


def modbus_port(gateway: Gateway) -> int:
    """The port of the gateway's running Modbus northbound."""
    northbound = gateway.northbounds["modbus"]
    assert isinstance(northbound, ModbusNorthbound)
    return northbound.port


def metrics_port(gateway: Gateway) -> int:
    """The port of the gateway's running HTTP northbound (/metrics, /healthz)."""
    northbound = gateway.northbounds["metrics"]
    assert isinstance(northbound, HttpNorthbound)
    return northbound.port


def drive_of(gateway: Gateway, line: str, node: int) -> GatewayDrive:
    """The gateway's drive *node* of *line* (it must have it)."""
    drive = gateway.drive(line, node)
    assert drive is not None, (line, node)
    return drive


async def polled(gateway: Gateway) -> None:
    """Return once every drive of the gateway has had a first good sample."""
    await wait_for(
        lambda: all(d.readings.last_ok is not None for d in gateway.drives), "a first good sample"
    )


@contextlib.asynccontextmanager
async def running_gateway(text: str) -> AsyncIterator[Gateway]:
    async with Gateway(parse_config(text, "test.toml")) as gateway:
        yield gateway


@contextlib.asynccontextmanager
async def modbus_client(
    gateway: Gateway, source: str = "127.0.0.1"
) -> AsyncIterator[AsyncModbusTcpClient]:
    client = AsyncModbusTcpClient(
        "127.0.0.1", port=modbus_port(gateway), source_address=(source, 0), timeout=5, retries=0
    )
    assert await client.connect()
    try:
        yield client
    finally:
        client.close()
