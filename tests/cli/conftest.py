"""Fixtures of the command-line tests: a TCP simulator whose state outlives each command."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .clirun import TcpSim


@pytest.fixture
async def tcp_sim() -> AsyncIterator[TcpSim]:
    bus = SimulatedBus(range(1, 5))
    server = await serve_tcp(bus, "127.0.0.1", 0)
    try:
        yield TcpSim(bus, f"tcp://127.0.0.1:{server.port}")
    finally:
        server.close()
        await server.wait_closed()
