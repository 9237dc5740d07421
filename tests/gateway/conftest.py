"""Fixtures of the gateway tests: a simulated line over TCP with its line log, and a gateway."""

from __future__ import annotations

import asyncio
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
    northbound = gateway.northbounds["http"]
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
async def running_gateway(text: str, *, tune_collector: bool = False) -> AsyncIterator[Gateway]:
    async with Gateway(parse_config(text, "test.toml"), tune_collector=tune_collector) as gateway:
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


class CuttableProxy:
    """A TCP proxy in front of the simulator that can cut the line and restore it."""

    def __init__(self, upstream_port: int) -> None:
        self.upstream_port = upstream_port
        self.server: asyncio.Server | None = None
        self.port = 0
        self._writers: list[asyncio.StreamWriter] = []
        #: Loop times at which an upstream connection was opened.
        self.connected_at: list[float] = []

    async def start(self) -> None:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", self.port)
        self.port = self.server.sockets[0].getsockname()[1]

    async def cut(self) -> None:
        """Close every connection and stop listening (reconnects are refused)."""
        assert self.server is not None
        self.server.close()
        for writer in self._writers:
            writer.transport.abort()
        self._writers.clear()
        await self.server.wait_closed()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        self.connected_at.append(asyncio.get_running_loop().time())
        self._writers += [writer, up_writer]

        async def pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
            with contextlib.suppress(OSError):
                while data := await src.read(4096):
                    dst.write(data)
            dst.transport.abort()

        await asyncio.gather(pump(reader, up_writer), pump(up_reader, writer))


@contextlib.asynccontextmanager
async def cuttable_line() -> AsyncIterator[tuple[SimulatedBus, LineLog, CuttableProxy]]:
    """Drives 1..4 over TCP behind a :class:`CuttableProxy`, with the line's log."""
    sim = SimulatedBus(range(1, 5))
    log = LineLog()
    server = await serve_tcp(sim, tap=log.record(asyncio.get_running_loop().time))
    async with server:
        proxy = CuttableProxy(server.port)
        await proxy.start()
        yield sim, log, proxy
