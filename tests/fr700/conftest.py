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
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Protocol, TypedDict

import pytest

import sj300_async as sj
from sj300_async.simulator import open_pty_server, serve_tcp
from sj300_async.simulator.fr700 import Fr700SimulatedBus

STATIONS = (0, 1, 2, 3)


class SimOptions(TypedDict, total=False):
    """Line options of the simulated drives (Fr700SimulatedBus keyword arguments)."""

    wait_field: bool
    terminator: str


#: Line options: (simulator kwargs, URL query).
OPTIONS: dict[str, tuple[SimOptions, str]] = {
    "factory": ({}, "protocol=fr700"),
    "crlf-nowait-ack": (
        {"wait_field": False, "terminator": "\r\n"},
        "protocol=fr700&wait_field=0&terminator=crlf&ack=1",
    ),
}


class OpenFr700Bus(Protocol):
    """``fr700_line.open(timeout=..., retries=...)``: a bus through the transport under test."""

    def __call__(
        self, *, timeout: float | None = None, retries: int = 2
    ) -> contextlib.AbstractAsyncContextManager[sj.Bus[sj.Fr700Drive, None]]: ...


@dataclass
class Fr700Line:
    kind: str
    sim: Fr700SimulatedBus
    url: str
    open: OpenFr700Bus


@pytest.fixture(params=[(t, o) for t in ("loopback", "tcp", "pty") for o in OPTIONS], ids=str)
async def fr700_line(request: pytest.FixtureRequest) -> AsyncIterator[Fr700Line]:
    kind, option = request.param
    sim_kwargs, query = OPTIONS[option]
    async with contextlib.AsyncExitStack() as stack:
        sim = Fr700SimulatedBus(STATIONS, **sim_kwargs)
        if kind == "loopback":
            url = f"sim://?{query}"
        elif kind == "tcp":
            server = await stack.enter_async_context(await serve_tcp(sim))
            url = f"tcp://127.0.0.1:{server.port}?{query}"
        else:
            pty = await stack.enter_async_context(await open_pty_server(sim))
            url = f"serial://{pty.path}?baudrate=19200&{query}"

        def open_line(
            *, timeout: float | None = None, retries: int = 2
        ) -> contextlib.AbstractAsyncContextManager[sj.Bus[sj.Fr700Drive, None]]:
            if kind == "loopback":
                return sj.open_bus(
                    url, protocol="fr700", simulator=sim, timeout=timeout, retries=retries
                )
            timeout = 0.5 if timeout is None else timeout
            return sj.open_bus(url, protocol="fr700", timeout=timeout, retries=retries)

        yield Fr700Line(kind, sim, url, open_line)
