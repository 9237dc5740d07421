"""A pending lapse's retries: a link that comes back mid-pause, the broadcast stop, giving up
at stop, and writes that end by cancellation are all audited (issue 26's review).

- A link cut and restored while the lapse waits between tries: the stop is
  still the first request on the new connection (nothing a poll had
  waiting on the old one moves over), and while the link is down the
  drives show offline (nothing holds the polls then).
- After a reconnect, another client's write waits for the pending stop, and
  a lapse that never confirms leaves the other drives' trip reads going.
- ``broadcast_stop`` sends the broadcast, which no drive acknowledges, and
  then the lapsed drive's own stop, which it does.
- A gateway that stops with a lapse still unconfirmed audits it as given up.
- A write whose caller goes away (cancelled) is audited, not lost.
- A Modbus connection that closes with its run command still waiting lapses
  its connection-scoped lease at once: the last command is the stop.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import struct
from collections.abc import AsyncIterator

import pytest
from waiting import wait_for

from sj300_async import sj300 as sj3
from sj300_async.gateway import (
    Gateway,
    Heartbeat,
    ParameterWrite,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
    _control,
)
from sj300_async.simulator import LinePacing, RunState, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.wire import Direction

from .conftest import (
    CuttableProxy,
    LineLog,
    cuttable_line,
    drive_of,
    modbus_port,
    polled,
    running_gateway,
)
from .test_gateway_lapse import _run_requests, _settled, _toml

SCADA = "10.0.0.5"
OPERATOR = "10.0.0.6"


def _requests_after(log: LineLog, since: float) -> list[sj3.Request]:
    """The requests that reached the drives at or after loop time *since*, in order."""
    parser = sj3.RequestParser()
    return [
        event
        for when, direction, data in log.chunks
        if direction == "rx"
        for event in parser.feed(data)
        if when >= since and isinstance(event, sj3.Request)
    ]


async def _running(gateway: Gateway, sim: SimulatedBus, node: int) -> None:
    """Take *node*'s lease as SCADA and run it; return once the simulated motor turns."""
    drive = drive_of(gateway, "hall", node)
    loop = asyncio.get_running_loop()
    for request in (Heartbeat(), SetFrequency(20.0), RunCommand(Direction.FORWARD)):
        assert (await gateway.write(SCADA, drive, request)).ok, request
    await wait_for(lambda: sim.drives[node].state(loop.time()).outputting, "running")


@contextlib.asynccontextmanager
async def _running_behind_a_proxy(
    trips_interval_s: float = 0,
) -> AsyncIterator[tuple[SimulatedBus, LineLog, CuttableProxy, Gateway]]:
    """A gateway over a line behind a proxy that can cut it, drive 1 running under a
    0.5 s lease that is not renewed."""
    async with cuttable_line() as (sim, log, proxy):
        text = _toml(f"tcp://127.0.0.1:{proxy.port}", lease_s=0.5).replace(
            "trips_interval_s = 0", f"trips_interval_s = {trips_interval_s}"
        )
        async with running_gateway(text) as gateway:
            await polled(gateway)
            await _running(gateway, sim, 1)
            yield sim, log, proxy, gateway


async def test_a_link_back_in_the_lapse_pause_gets_the_stop_first_and_down_it_shows_offline() -> (
    None
):
    loop = asyncio.get_running_loop()
    async with _running_behind_a_proxy() as (sim, log, proxy, gateway):
        line = gateway.lines[0]
        drive = drive_of(gateway, "hall", 1)
        sim.faults.silence(1)  # the lapse's stops time out: it pauses between tries
        await wait_for(lambda: line.controller.lapse.failed_tries >= 2, "2 failed tries")
        sim.faults.silence(1, False)
        await proxy.cut()
        await wait_for(lambda: not line.bus.connected, "the link down")
        # Down, nothing holds the polls: every drive goes offline, not frozen online.
        await wait_for(
            lambda: not any(line.poller.health(line.bus, n).online for n in range(1, 5)),
            "every drive offline",
        )
        assert drive.lapse_pending
        cut_at = loop.time()
        await proxy.start()
        await wait_for(lambda: not drive.lapse_pending, "the stop confirmed", timeout=15)
        back = next(t for t in proxy.connected_at if t > cut_at)
        after = _requests_after(log, back)
        stop = next(i for i, r in enumerate(after) if r.command == sj3.Command.RUN and r.node == 1)
        # Before the stop, at most the sync request the arbiter sends ahead of it
        # (node 1 missed answers): one request, to node 1. Never a poll.
        before = [(r.node, r.command) for r in after[:stop]]
        assert len(before) <= 1, before
        assert all(node == 1 for node, _ in before), before
        assert after[stop].data == b"0"
        await wait_for(lambda: sim.drives[1].state(loop.time()) is RunState.STOPPED, "stopped")


async def test_after_a_reconnect_another_clients_write_waits_for_the_pending_stop() -> None:
    loop = asyncio.get_running_loop()
    async with _running_behind_a_proxy() as (_, log, proxy, gateway):
        line = gateway.lines[0]
        drive, other = drive_of(gateway, "hall", 1), drive_of(gateway, "hall", 2)
        await proxy.cut()
        await wait_for(lambda: drive.lapse_pending, "the lapse pending", timeout=10)
        # An operator's stop of drive 2 asked the moment the link is back.
        writes: list[asyncio.Future[WriteResult]] = []
        line.bus.on_connected(
            lambda: writes.append(
                asyncio.ensure_future(gateway.write(OPERATOR, other, RunCommand(Direction.STOP)))
            )
        )
        cut_at = loop.time()
        await proxy.start()
        await wait_for(lambda: not drive.lapse_pending, "the stop confirmed", timeout=15)
        assert (await writes[0]).ok
        back = next(t for t in proxy.connected_at if t > cut_at)
        after = [(r.node, r.command, r.data) for r in _requests_after(log, back)]
        stop = after.index((1, sj3.Command.RUN, b"0"))
        assert all(node == 1 for node, _, _ in after[:stop]), after[: stop + 1]
        assert (2, sj3.Command.RUN, b"0") in after[stop:]


async def test_a_lapse_that_never_confirms_leaves_the_other_drives_trip_reads_going() -> None:
    loop = asyncio.get_running_loop()
    async with _running_behind_a_proxy(trips_interval_s=0.2) as (sim, _, _, gateway):
        drive, other = drive_of(gateway, "hall", 1), drive_of(gateway, "hall", 2)
        sim.faults.silence(1)  # gone for good: its lapse stays pending
        await wait_for(lambda: drive.lapse_pending, "the lapse pending", timeout=10)
        since = loop.time()
        await wait_for(lambda: other.readings.trips_at > since, "drive 2's trips read")
        assert drive.lapse_pending


async def test_broadcast_stop_is_followed_by_the_lapsed_drives_own_acknowledged_stop() -> None:
    loop = asyncio.get_running_loop()
    sim = SimulatedBus(range(1, 5))
    log = LineLog()
    server = await serve_tcp(sim, tap=log.record(loop.time))
    async with server:
        text = _toml(f"tcp://127.0.0.1:{server.port}", lease_s=0.5).replace(
            'on_lapse = "stop"', 'on_lapse = "broadcast_stop"'
        )
        async with running_gateway(text) as gateway:
            await polled(gateway)
            drive = drive_of(gateway, "hall", 2)
            await _running(gateway, sim, 2)
            await _settled(gateway, drive)
            assert gateway.audit.counts.get("not_confirmed", 0) == 0, gateway.audit.counts
            runs = [
                (r.node, r.data) for r in _requests_after(log, 0.0) if r.command == sj3.Command.RUN
            ]
            broadcast = runs.index((sj3.BROADCAST, b"0"))
            assert (2, b"0") in runs[broadcast + 1 :], runs
        await wait_for(lambda: sim.drives[2].state(loop.time()) is RunState.STOPPED, "stopped")


async def test_a_lapse_not_confirmed_when_the_gateway_stops_is_audited_as_given_up(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(_control, "CLOSE_LAPSE_S", 0.3)
    caplog.set_level(logging.INFO, "sj300_async.gateway.audit")
    sim = SimulatedBus(range(1, 5))
    server = await serve_tcp(sim)
    async with server:
        async with running_gateway(_toml(f"tcp://127.0.0.1:{server.port}", lease_s=30)) as gateway:
            await polled(gateway)
            drive = drive_of(gateway, "hall", 3)
            await _running(gateway, sim, 3)
            sim.faults.silence(3)  # the stop at close cannot be confirmed
        assert gateway.audit.counts.get("not_confirmed") == 1, gateway.audit.counts
        given_up = [
            r.getMessage()
            for r in caplog.records
            if r.name == "sj300_async.gateway.audit" and "given up" in r.getMessage()
        ]
        assert len(given_up) == 1, given_up
        assert "lease lapsed: stop" in given_up[0]
        assert "when the gateway stopped" in given_up[0]
        assert not drive.lapse_pending


async def test_a_write_whose_caller_goes_away_is_audited() -> None:
    sim = SimulatedBus(range(1, 5))
    server = await serve_tcp(sim, pacing=LinePacing(9600, 8, "N", 1))
    async with server:
        url = f"tcp://127.0.0.1:{server.port}?baudrate=9600&parity=N"
        text = (
            _toml(url, lease_s=30, interval_s=0.05)
            .replace("control = true", 'control = true\nparameters = ["A004"]')
            .replace('parameters = ["F001"]', 'parameters = ["F001", "A004"]')
        )
        async with running_gateway(text) as gateway:
            await polled(gateway)
            drive = drive_of(gateway, "hall", 4)
            assert (await gateway.write(SCADA, drive, Heartbeat())).ok
            before = sum(gateway.audit.counts.values())
            writes: list[WriteRequest] = [SetFrequency(12.5), ParameterWrite("A004", 500)]
            for request in writes:
                # Sent, then its caller is gone: behind the polls, or under way.
                task = asyncio.create_task(gateway.write(SCADA, drive, request))
                await asyncio.sleep(0)
                task.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await task
            counts = gateway.audit.counts
            assert sum(counts.values()) - before == len(writes), counts
            assert counts.get("no_answer") == len(writes), counts


def _frame(tid: int, unit: int, function: int, address: int, value: int) -> bytes:
    return struct.pack(">HHHBBHH", tid, 0, 6, unit, function, address, value)


async def test_a_modbus_connection_closed_with_its_run_under_way_lapses_at_once() -> None:
    """The connection's end lapses its connection-scoped lease at once, cancelling its run
    command still under way (not after it), and the last command the drive gets is the stop."""
    loop = asyncio.get_running_loop()
    sim = SimulatedBus(range(1, 5))
    log = LineLog()
    server = await serve_tcp(sim, pacing=LinePacing(9600, 8, "N", 1), tap=log.record(loop.time))
    async with server:
        url = f"tcp://127.0.0.1:{server.port}?baudrate=9600&parity=N"
        text = '[modbus]\nlisten = "127.0.0.1:0"\n' + _toml(
            url, lease_s=30.0, interval_s=0.05, extra='lease_scope = "connection"'
        )
        async with running_gateway(text) as gateway:
            await polled(gateway)
            drive = drive_of(gateway, "hall", 1)
            reader, writer = await asyncio.open_connection("127.0.0.1", modbus_port(gateway))
            writer.write(_frame(1, 1, 6, 1000, 1))  # heartbeat
            assert (await reader.readexactly(12))[7] == 6  # answered, no exception
            sim.faults.silence(1)  # the run goes unanswered: it is under way for a while
            writer.write(_frame(2, 1, 6, 1002, 1))  # run forward, then gone at once
            writer.transport.get_extra_info("socket").setsockopt(
                socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0)
            )
            writer.close()
            await wait_for(lambda: drive.lease.holder is None, "the lease lapsed", timeout=5)
            # Cancelled by the lapse (no_lease), not left to time out (no_answer).
            await wait_for(lambda: gateway.audit.counts.get("no_lease") == 1, "the run audited")
            assert "no_answer" not in gateway.audit.counts, gateway.audit.counts
            sim.faults.silence(1, False)
            await _settled(gateway, drive)
            runs = _run_requests(log, 1)
            assert runs, "no run command at all"
            assert runs[-1][1] == b"0", runs
