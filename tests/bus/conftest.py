"""Fixtures for the async stack (helpers live in scripted.py)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Callable

import pytest

import sj300_async as sj
from sj300_async import bus as sjbus
from sj300_async.bus._bus import Bus
from sj300_async.transports import LineFaults, loopback_connector
from sj300_async.wire._line import INSTANT_LINE

from .scripted import MakeRig, Responder, Rig, ScriptedPeer, answer_all


@pytest.fixture
def scripted() -> MakeRig:
    """``async with scripted(respond, timeout=..., retries=...) as rig:``"""

    @contextlib.asynccontextmanager
    async def make(
        respond: Responder = answer_all,
        *,
        to_host: LineFaults | None = None,
        to_peer: LineFaults | None = None,
        strip_echo: bool = False,
        **bus_kwargs: object,
    ) -> AsyncIterator[Rig]:
        peers: list[ScriptedPeer] = []
        bus_kwargs.setdefault("line", INSTANT_LINE)
        bus_kwargs.setdefault("timing", sj.BusTiming(margin_s=0.05))
        line = bus_kwargs["line"]
        timing = bus_kwargs["timing"]
        assert isinstance(line, sj.LineSettings)
        assert isinstance(timing, sj.BusTiming)
        # A drive on a line with a speed answers no sooner than the fastest line
        # it can run carries the request and the reply (10 bits a character).
        baud = max(line.baudrate, timing.plausible_baudrate) if line.baudrate else 0
        char_s = 10 / baud if baud else 0.0

        def factory(send: Callable[[bytes], None]) -> ScriptedPeer:
            peers.append(ScriptedPeer(respond, send, char_s=char_s))
            return peers[-1]

        trace: list[sjbus.TraceRecord] = []
        bus = Bus(
            loopback_connector(factory, to_peer=to_peer, to_host=to_host),
            description="scripted",
            trace=trace.append,
            strip_echo=strip_echo,
            **bus_kwargs,  # type: ignore[arg-type]
        )
        async with bus:
            yield Rig(bus, peers, trace)

    return make
