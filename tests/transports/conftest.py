"""The transport contract fixture: the same simulated drives behind every transport.

``line`` yields an ``open()`` factory; ``async with line.open() as bus`` gives
a bus connected through the transport under test to a simulator whose
drives the test can inspect (``line.sim``). Transports:

- loopback: ``sim://`` (the in-memory transport and simulator endpoint)
- tcp:      raw TCP to the simulator's TCP server
- pty:      the library's serial transport (pyserial) on a real pseudo-terminal
            served by the simulator (a Linux pty refuses parity: 8N1)
- ser2net:  a socat pty pair, the simulator on one end, ser2net exposing the
            other end on loopback TCP, the library's TCP transport in front
- rfc2217:  the same pair, ser2net's accepter speaking telnet with RFC 2217,
            the library's RFC 2217 transport in front (it sets the line remotely)
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Protocol

import pytest

import sj300_async as sj
from sj300_async.simulator import open_pty_server, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .bridges import socat_ser2net

NODES = (1, 2, 3, 4)


class OpenBus(Protocol):
    """``line.open(timeout=..., retries=...)``: a bus through the transport under test."""

    def __call__(
        self, *, timeout: float | None = None, retries: int = 2
    ) -> contextlib.AbstractAsyncContextManager[sj.Bus[sj.Drive, sj.Broadcast]]: ...


@dataclass
class Line:
    kind: str
    sim: SimulatedBus
    url: str
    open: OpenBus


@contextlib.asynccontextmanager
async def _ser2net_bridge(sim: SimulatedBus, *, rfc2217: bool = False) -> AsyncIterator[str]:
    """The simulator on end A of :func:`socat_ser2net`; yields the bus URL."""
    from sj300_async.simulator import serve_serial_device

    async with socat_ser2net(rfc2217=rfc2217) as (a, port), await serve_serial_device(sim, a):
        yield f"{'rfc2217' if rfc2217 else 'tcp'}://127.0.0.1:{port}?baudrate=19200"


@pytest.fixture(params=["loopback", "tcp", "pty", "ser2net", "rfc2217"])
async def line(request: pytest.FixtureRequest) -> AsyncIterator[Line]:
    kind = request.param
    async with contextlib.AsyncExitStack() as stack:
        sim = SimulatedBus(nodes=NODES)
        if kind == "loopback":
            url = "sim://"
        elif kind == "tcp":
            server = await stack.enter_async_context(await serve_tcp(sim))
            url = f"tcp://127.0.0.1:{server.port}"
        elif kind == "pty":
            pty = await stack.enter_async_context(await open_pty_server(sim))
            url = f"serial://{pty.path}?baudrate=19200"
        else:
            bridge = _ser2net_bridge(sim, rfc2217=kind == "rfc2217")
            url = await stack.enter_async_context(bridge)

        def open_line(
            *, timeout: float | None = None, retries: int = 2
        ) -> contextlib.AbstractAsyncContextManager[sj.Bus[sj.Drive, sj.Broadcast]]:
            if kind == "loopback":
                return sj.open_bus(url, simulator=sim, timeout=timeout, retries=retries)
            return sj.open_bus(url, timeout=0.5 if timeout is None else timeout, retries=retries)

        yield Line(kind, sim, url, open_line)
