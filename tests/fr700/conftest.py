"""The FR-700 transport-contract fixture: simulated FR-700 drives behind every transport.

``fr700_line`` yields an ``open()`` factory; ``async with fr700_line.open() as bus``
gives an FR-700 bus connected through the transport under test to a
simulator whose drives the test can inspect (``fr700_line.sim``):

- loopback: ``sim://?protocol=fr700`` (the in-memory transport and endpoint)
- tcp:      raw TCP to the simulator's TCP server
- pty:      the library's serial transport (pyserial) on a real pseudo-terminal

Each runs with the drives' factory line settings (waiting-time field, CR)
and with the other extreme (no field, CR LF, the host's ACK after data).
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

import pytest

import sj300_async as sj
from sj300_async.simulator import open_pty_server, serve_tcp
from sj300_async.simulator.fr700 import Fr700SimulatedBus

STATIONS = (0, 1, 2, 3)
#: Line options: (simulator kwargs, URL query).
OPTIONS = {
    "factory": ({}, "protocol=fr700"),
    "crlf-nowait-ack": (
        {"wait_field": False, "terminator": "\r\n"},
        "protocol=fr700&wait_field=0&terminator=crlf&ack=1",
    ),
}


@dataclass
class Fr700Line:
    kind: str
    sim: Fr700SimulatedBus
    url: str
    open: Callable[..., contextlib.AbstractAsyncContextManager[sj.Bus]]


@pytest.fixture(params=[(t, o) for t in ("loopback", "tcp", "pty") for o in OPTIONS], ids=str)
async def fr700_line(request: pytest.FixtureRequest) -> AsyncIterator[Fr700Line]:
    kind, option = request.param
    sim_kwargs, query = OPTIONS[option]
    async with contextlib.AsyncExitStack() as stack:
        sim = Fr700SimulatedBus(STATIONS, **sim_kwargs)  # type: ignore[arg-type]
        if kind == "loopback":
            url = f"sim://?{query}"
        elif kind == "tcp":
            server = await stack.enter_async_context(await serve_tcp(sim))
            url = f"tcp://127.0.0.1:{server.port}?{query}"
        else:
            pty = await stack.enter_async_context(await open_pty_server(sim))
            url = f"serial://{pty.path}?baudrate=19200&{query}"

        def open_line(**kwargs: object) -> contextlib.AbstractAsyncContextManager[sj.Bus]:
            if kind == "loopback":
                kwargs["simulator"] = sim
            else:
                kwargs.setdefault("timeout", 0.5)
            return sj.open_bus(url, protocol="fr700", **kwargs)  # type: ignore[call-overload]

        yield Fr700Line(kind, sim, url, open_line)
