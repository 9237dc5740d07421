"""Stopping the gateway with a leased motor running says what the drive confirmed (issue 41).

Every clean stop of ``sj300 gateway`` with a leased motor running logged
``stop given up after 6 tries ... no answer`` at ERROR, though the drive had
answered every try and did stop: it took the stop and was still
decelerating (the simulator's F003 is 30 s from 50 Hz) when the 5 s the
gateway waits for the confirmation ran out, and the give-up knew no better
than "no answer". Each lapse given up at the stop now says what is known,
at the level it deserves:

- the drive took the stop and still reads running (decelerating): a
  WARNING naming it; no ERROR, and the drive really stops;
- the drive took the stop, then stopped answering: a WARNING naming the
  failure;
- the drive never answered the stop: an ERROR that says so.

And a drive that stops within the wait is confirmed: a decelerating drive
is read every 0.25 s, not with the failures' back-off, which read it at
0.7 s and next at 1.5 s (at 3.1 s and next at 5.1 s in the real 5 s wait).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Callable

import pytest
from waiting import wait_for

from sj300_async import sj300 as sj3
from sj300_async.gateway import Gateway, _control
from sj300_async.simulator import RunState, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .conftest import polled, running_gateway
from .test_gateway_lapse import _toml
from .test_gateway_lapse_retry import _running

NODE = 3
#: How long the stopping gateway waits here for its lapses (the real one waits 5 s):
#: under drive 3's 4 s ramp down, over a try that times out (3 x the line's time-out).
CLOSE_S = 1.5


def _config(port: int) -> str:
    """Drive 3's lease held until the gateway stops; a try that times out ends in 0.3 s."""
    return _toml(f"tcp://127.0.0.1:{port}", lease_s=30, extra="timeout_s = 0.1")


def _sim() -> SimulatedBus:
    """Drives 1..4; drive 3 reaches 20 Hz in 0.2 s and needs 4 s to stop from it."""
    sim = SimulatedBus(range(1, 5))
    sim.drives[NODE].set_parameter("F002", 50)  # 0.5 s from 0 to 50 Hz (A004)
    sim.drives[NODE].set_parameter("F003", 1000)  # 10 s from 50 Hz to 0
    return sim


def _records(caplog: pytest.LogCaptureFixture, level: int) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.name.startswith("sj300_async") and r.levelno == level
    ]


def _lapse_audits(caplog: pytest.LogCaptureFixture) -> list[str]:
    """The audit records of the lapses (their end: confirmed, or given up)."""
    return [
        r.getMessage()
        for r in caplog.records
        if r.name == "sj300_async.gateway.audit" and "lease lapsed: stop" in r.getMessage()
    ]


@contextlib.asynccontextmanager
async def _leased_motor(
    sim: SimulatedBus, tap: Callable[[str, bytes], None] | None = None
) -> AsyncIterator[Gateway]:
    """A gateway on *sim* (served over TCP, *tap* seeing its bytes) whose client holds
    node NODE's lease and runs it; the gateway stops as the block ends, the line after."""
    server = await serve_tcp(sim, tap=tap)
    async with server, running_gateway(_config(server.port)) as gateway:
        await polled(gateway)
        await _running(gateway, sim, NODE)
        yield gateway


@pytest.fixture
def close_soon(monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setattr(_control, "CLOSE_LAPSE_S", CLOSE_S)
    caplog.set_level(logging.INFO, "sj300_async")


@pytest.mark.usefixtures("close_soon")
async def test_a_motor_still_decelerating_at_the_stop_is_a_warning_not_an_error(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.get_running_loop()
    sim = _sim()
    async with _leased_motor(sim) as gateway:
        await wait_for(
            lambda: sim.drives[NODE].state(loop.time()) is RunState.CONSTANT_SPEED, "20 Hz"
        )
    # The stop reached the drive before the line closed: it ramps down on its own.
    assert sim.drives[NODE].state(loop.time()) is RunState.DECELERATING
    await wait_for(
        lambda: sim.drives[NODE].state(loop.time()) is RunState.STOPPED, "stopped", timeout=10
    )
    assert _records(caplog, logging.ERROR) == []
    warned = [m for m in _records(caplog, logging.WARNING) if f"node {NODE}: lease lapsed" in m]
    assert len(warned) == 1, warned
    assert "the drive took the stop and still read decelerating" in warned[0]
    assert "given up" not in warned[0]
    audited = _lapse_audits(caplog)
    assert len(audited) == 1, audited
    assert "not_confirmed" in audited[0]
    assert "decelerating" in audited[0]
    assert gateway.audit.counts.get("not_confirmed") == 1, gateway.audit.counts


@pytest.mark.usefixtures("close_soon")
async def test_a_drive_silent_after_taking_the_stop_is_a_warning_naming_the_failure(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.get_running_loop()
    sim = _sim()
    parser = sj3.RequestParser()
    stop_seen = False

    def tap(direction: str, data: bytes) -> None:
        """Node 3 leaves the line right after it answered the stop."""
        nonlocal stop_seen
        if direction == "rx":
            stop_seen = stop_seen or any(
                isinstance(r, sj3.Request)
                and r.node == NODE
                and r.command == sj3.Command.RUN
                and r.data == b"0"
                for r in parser.feed(data)
            )
        elif stop_seen:
            sim.faults.silence(NODE)

    async with _leased_motor(sim, tap=tap):
        await wait_for(
            lambda: sim.drives[NODE].state(loop.time()) is RunState.CONSTANT_SPEED, "20 Hz"
        )
    assert sim.faults.is_silent(NODE)
    assert sim.drives[NODE].state(loop.time()) is RunState.DECELERATING
    # The failed status read is an ERROR as any lapse's first failure is; the give-up is not.
    assert not any("lease lapsed" in m for m in _records(caplog, logging.ERROR))
    warned = [m for m in _records(caplog, logging.WARNING) if f"node {NODE}: lease lapsed" in m]
    assert len(warned) == 1, warned
    # Its latest try failed, or was cut short with the failure of the one before.
    assert "the drive took the stop, then: " in warned[0]
    assert "node 03 did not answer command 04" in warned[0]  # the status read


@pytest.mark.usefixtures("close_soon")
async def test_a_drive_that_never_answers_the_stop_is_an_error_that_says_so(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.get_running_loop()
    sim = _sim()
    async with _leased_motor(sim):
        sim.faults.silence(NODE)  # the stop at close never reaches it
    assert sim.drives[NODE].state(loop.time()).outputting
    errors = [m for m in _records(caplog, logging.ERROR) if f"node {NODE}: lease lapsed" in m]
    assert len(errors) == 1, _records(caplog, logging.ERROR)
    assert "given up" in errors[0]
    assert "the drive never acknowledged the stop: " in errors[0]
    assert "node 03 did not answer command 00" in errors[0]  # the stop


@pytest.mark.usefixtures("close_soon")
async def test_a_motor_that_stops_within_the_wait_is_confirmed(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.get_running_loop()
    sim = _sim()
    sim.drives[NODE].set_parameter("F003", 225)  # 20 Hz to 0 in 0.9 s, within CLOSE_S
    async with _leased_motor(sim) as gateway:
        await wait_for(
            lambda: sim.drives[NODE].state(loop.time()) is RunState.CONSTANT_SPEED, "20 Hz"
        )
    assert sim.drives[NODE].state(loop.time()) is RunState.STOPPED
    assert _records(caplog, logging.ERROR) == []
    assert gateway.audit.counts.get("not_confirmed") is None, gateway.audit.counts
    audited = _lapse_audits(caplog)
    assert len(audited) == 1, audited
    assert "confirmed stopped" in audited[0]
