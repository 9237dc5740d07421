"""A real gateway for the workbench's browser tests: simulated lines over TCP, HTTP on loopback.

:func:`workbench_gateway` starts one :class:`~sj300_async.SimulatedBus` per
line, each served over TCP on a free loopback port (as the gateway tests'
``sim_line``), and a :class:`~sj300_async.gateway.Gateway` polling them that
serves the workbench on ``127.0.0.1:0``. Everything stops when the block
ends.

The HTTP northbound's ``publish`` is wrapped for the block: each snapshot it
is handed is recorded with the Unix time it was handed over (:attr:`Bench.published`),
so a test can tell how long the page took to show a change from the moment
the gateway published it.

Enter it in the test itself, not in an async fixture: the poller's task
group must be left by the task that entered it, and pytest-asyncio runs a
fixture's teardown in another task.
"""

from __future__ import annotations

import asyncio
import contextlib
import textwrap
import time
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Final, cast

import aiohttp
import pytest

from sj300_async.gateway import Gateway, ServedDrive, parse_config
from sj300_async.gateway.http._northbound import HttpNorthbound
from sj300_async.profiles import DriveSnapshot
from sj300_async.simulator import SimulatorServer, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus, SimulatedDrive
from sj300_async.sj300 import Drive

__all__ = ["GATEWAY_ID", "INTERVAL_S", "Bench", "Published", "workbench_gateway"]

#: The poll interval of every line (s): short, so that a change shows quickly.
INTERVAL_S: Final = 0.2
#: The gateway's id (the page's header shows it).
GATEWAY_ID: Final = "hall-gw"


@dataclass(frozen=True, slots=True)
class Published:
    """A snapshot the gateway handed to the HTTP northbound, and when (Unix seconds)."""

    at: float
    snapshot: DriveSnapshot


@dataclass
class Bench:
    """A running gateway on simulated lines (see the module docstring)."""

    gateway: Gateway
    sims: dict[str, SimulatedBus]
    session: aiohttp.ClientSession
    published: list[Published] = field(default_factory=list)

    @property
    def port(self) -> int:
        northbound = self.gateway.northbounds["http"]
        assert isinstance(northbound, HttpNorthbound)
        return northbound.port

    @property
    def url(self) -> str:
        """The workbench's address (the origin, with its trailing slash)."""
        return f"http://127.0.0.1:{self.port}/"

    def sim(self, line: str, node: int) -> SimulatedDrive:
        """The simulated drive *node* of *line* (to trip it, as a fault inside it would)."""
        return self.sims[line].drives[node]

    def drive(self, line: str, node: int) -> Drive:
        """The SJ300 drive *node* on the gateway's own bus of *line* (commands queue with polls)."""
        bus = next(each.bus for each in self.gateway.lines if each.config.name == line)
        return cast(Drive, bus.drive(node))

    def snapshot(self, line: str, node: int) -> DriveSnapshot:
        """The gateway's latest snapshot of a drive."""
        drive = self.gateway.drive(line, node)
        assert drive is not None, (line, node)
        return drive.snapshot

    def publications(self, line: str, node: int) -> list[Published]:
        """What was published of one drive, oldest first."""
        return [p for p in self.published if (p.snapshot.line, p.snapshot.node) == (line, node)]

    async def get_json(self, path: str) -> Any:
        """GET *path* (``api/v1/...``) of the gateway's API, outside the browser."""
        async with self.session.get(self.url + path) as response:
            assert response.status == 200, (path, response.status, await response.text())
            return await response.json()

    async def start(self, line: str, node: int, hz: float) -> None:
        """Set a drive's frequency and run it forward, through the gateway's bus."""
        drive = self.drive(line, node)
        await drive.set_frequency(hz)
        await drive.run_forward()

    def trip(self, line: str, node: int, code: int) -> None:
        """Trip a simulated drive now with trip factor *code* (7: E07)."""
        assert self.sim(line, node).trip(code, now=asyncio.get_running_loop().time())

    def set_ramp(self, line: str, node: int, seconds: float) -> None:
        """Set a simulated drive's acceleration and deceleration times (F002, F003; 0.01 s).

        The factory's ramp takes 30 s to 50 Hz; a short one brings a drive to speed in a test.
        """
        for code in ("F002", "F003"):
            self.sim(line, node).set_parameter(code, round(seconds * 100))

    def reset(self, line: str, node: int) -> None:
        """Clear a simulated drive's trip (its RS terminal)."""
        assert self.sim(line, node).reset(now=asyncio.get_running_loop().time())


def _config(urls: Mapping[str, str], nodes: Mapping[str, range], extra: str = "") -> str:
    text = (
        textwrap.dedent(
            f"""
        [gateway]
        id = "{GATEWAY_ID}"
        [http]
        listen = "127.0.0.1:0"
        """
        )
        + extra
    )
    for index, (name, url) in enumerate(urls.items()):
        span = nodes[name]
        text += textwrap.dedent(
            f"""
            [[lines]]
            name = "{name}"
            url = "{url}"
            nodes = "{span.start}-{span.stop - 1}"
            interval_s = {INTERVAL_S}
            unit_offset = {32 * index}
            """
        )
    return text


@contextlib.asynccontextmanager
async def workbench_gateway(lines: Mapping[str, range], extra: str = "") -> AsyncIterator[Bench]:
    """A gateway serving the workbench on simulated *lines* (name: nodes), stopped on exit;
    *extra*: sections added to its configuration (``[recorder]``)."""
    async with contextlib.AsyncExitStack() as stack:
        sims: dict[str, SimulatedBus] = {}
        urls: dict[str, str] = {}
        for name, nodes in lines.items():
            sim = SimulatedBus(nodes)
            server: SimulatorServer = await stack.enter_async_context(await serve_tcp(sim))
            sims[name] = sim
            urls[name] = f"tcp://127.0.0.1:{server.port}"
        session = await stack.enter_async_context(aiohttp.ClientSession())
        gateway = await stack.enter_async_context(
            Gateway(parse_config(_config(urls, lines, extra), "workbench.toml"))
        )
        bench = Bench(gateway, sims, session)
        northbound = gateway.northbounds["http"]
        assert isinstance(northbound, HttpNorthbound)
        publish = northbound.publish

        def recorded(served: ServedDrive) -> None:
            bench.published.append(Published(time.time(), served.snapshot))
            publish(served)

        patch = stack.enter_context(pytest.MonkeyPatch.context())
        patch.setattr(northbound, "publish", recorded)
        yield bench
