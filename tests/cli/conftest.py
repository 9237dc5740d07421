"""Fixtures of the command-line tests: a TCP simulator whose state outlives each command.

The simulator answers as fast as a 115200-baud line would carry the frames,
and the URL says so (``?baudrate=115200``): a parameter backup is 335 round
trips, which at the default 19200 baud take 4 s a backup, at 115200 under
1 s. The commands under test do the same thing either way; the line's
speed is what the client and the simulator agree on, as on a real line.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Final

import pytest

from sj300_async.simulator import LinePacing, PlausibleLine, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .clirun import TcpSim

#: The line speed the TCP simulator answers at and its URL declares.
FAST_BAUD: Final = 115200


@pytest.fixture
async def tcp_sim() -> AsyncIterator[TcpSim]:
    bus = SimulatedBus(range(1, 5))
    line = PlausibleLine(LinePacing(FAST_BAUD, 8, "N", 1))
    server = await serve_tcp(bus, "127.0.0.1", 0, line=line)
    try:
        yield TcpSim(bus, f"tcp://127.0.0.1:{server.port}?baudrate={FAST_BAUD}")
    finally:
        server.close()
        await server.wait_closed()
