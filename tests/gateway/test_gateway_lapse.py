"""A lapsed lease always ends with the drive stopped: the race, the cut link, the stop from anyone.

The adversary's findings (issue 26), each a test:

- A run command accepted while the lease was valid, but still waiting for
  the line behind polls when the lease lapsed, must not reach the drive
  after the lapse's stop. 200 tries (``--soak``; 48 in the default suite,
  where nearly every one is a real race) on a 9600-baud paced line with
  four drives polled back to back, each command sent 0..60 ms before the
  lapse.
- A lapse whose stop cannot reach the drive (the link cut by a proxy) is
  retried until the drive is confirmed stopped, and shows as pending in
  the metrics and /healthz; when the link comes back, the stop is the
  first request on it, before any poll.
- A stop is accepted from any client allowed to control the drive, lease or
  not; a pending lapse keeps new leases out.
- A connection-scoped lease lapses the moment its connection closes.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
import textwrap
from collections import Counter
from collections.abc import AsyncIterator

import pytest
from waiting import wait_for

from sj300_async import sj300 as sj3
from sj300_async.gateway import (
    Gateway,
    GatewayConfigError,
    GatewayDrive,
    Heartbeat,
    Refusal,
    RunCommand,
    SetFrequency,
    parse_config,
)
from sj300_async.simulator import LinePacing, RunState, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.wire import Direction

from .conftest import LineLog, cuttable_line, drive_of, modbus_client, polled, running_gateway

SCADA = "10.0.0.5"
OPERATOR = "10.0.0.6"
#: Tries of the race: rounds x the line's four drives (--soak, the default suite).
RACE_ROUNDS = 50
RACE_ROUNDS_SHORT = 12
#: The latest a command is sent before the lapse, in seconds.
RACE_LEAD_S = 0.060
RACE_LEASE_S = 0.3


def _toml(url: str, *, lease_s: float, extra: str = "", interval_s: float = 0.05) -> str:
    return textwrap.dedent(
        f"""
        [[lines]]
        name = "hall"
        url = "{url}"
        nodes = "1-4"
        interval_s = {interval_s}
        parameters = ["F001"]
        trips_interval_s = 0
        lease_s = {lease_s}
        on_lapse = "stop"
        {extra}
        [[lines.writes]]
        nodes = "1-4"
        control = true
        """
    )


def _run_requests(log: LineLog, node: int) -> list[tuple[float, bytes]]:
    """The run-command requests (``00``) to *node* that crossed the line: (time, data)."""
    parser = sj3.RequestParser()
    out = []
    for when, direction, data in log.chunks:
        if direction != "rx":
            continue
        for event in parser.feed(data):
            if (
                isinstance(event, sj3.Request)
                and event.command == sj3.Command.RUN
                and event.node in (node, sj3.BROADCAST)
            ):
                out.append((when, event.data))
    return out


async def _settled(gateway: Gateway, drive: GatewayDrive, timeout: float = 10.0) -> None:
    """Wait until *drive*'s lease is gone and its lapse action has ended."""
    controller = gateway.lines[0].controller
    await wait_for(
        lambda: drive.lease.holder is None and controller.pending_lapses == 0,
        "the lapse carried out",
        timeout=timeout,
    )


@contextlib.asynccontextmanager
async def _paced_line(baudrate: int) -> AsyncIterator[tuple[SimulatedBus, str, LineLog]]:
    """Four drives on a TCP line paced at *baudrate* (8N1), with its log."""
    sim = SimulatedBus(range(1, 5))
    log = LineLog()
    server = await serve_tcp(
        sim,
        pacing=LinePacing(baudrate, 8, "N", 1),
        tap=log.record(asyncio.get_running_loop().time),
    )
    async with server:
        yield sim, f"tcp://127.0.0.1:{server.port}?baudrate={baudrate}&parity=N", log


@pytest.mark.soak
async def test_no_run_command_reaches_a_drive_after_its_lease_lapsed(soak: bool) -> None:
    rounds = RACE_ROUNDS if soak else RACE_ROUNDS_SHORT
    loop = asyncio.get_running_loop()
    rng = random.Random(26)
    results: Counter[str] = Counter()
    left_running: list[str] = []
    async with (
        _paced_line(9600) as (sim, url, log),
        running_gateway(_toml(url, lease_s=RACE_LEASE_S)) as gateway,
    ):
        await polled(gateway)

        async def one_try(node: int, lead_s: float) -> None:
            drive = drive_of(gateway, "hall", node)
            assert (await gateway.write(SCADA, drive, Heartbeat())).ok
            # The adversary's timing: the command goes out lead_s before the lapse.
            await asyncio.sleep(max(0.0, drive.lease.expires_at - lead_s - loop.time()))
            result = await gateway.write(SCADA, drive, RunCommand(Direction.FORWARD))
            if result.ok:
                results["done before the lapse"] += 1
            elif "lapsed before the command was confirmed" in result.detail:
                results["accepted, cut by the lapse"] += 1
            else:
                results[f"refused: {result}"] += 1
            await _settled(gateway, drive)
            runs = _run_requests(log, node)
            if runs and runs[-1][1] != b"0":
                left_running.append(f"node {node}: {runs[-1]} after the lapse (lead {lead_s})")
            state = sim.drives[node].state(loop.time())
            if state in (RunState.ACCELERATING, RunState.CONSTANT_SPEED):
                left_running.append(f"node {node}: {state} after the lapse (lead {lead_s})")

        for _ in range(rounds):
            await asyncio.gather(
                *(one_try(node, rng.uniform(0.0, RACE_LEAD_S)) for node in range(1, 5))
            )
        lapses = gateway.lines[0].controller.lapses
        # Runs that reached a drive (each then stopped by its lapse).
        on_the_wire = sum(
            data == b"1" for node in range(1, 5) for _, data in _run_requests(log, node)
        )
    print(
        f"\n{rounds * 4} tries at 9600 baud: {dict(results)}, {lapses} lapses, "
        f"{on_the_wire} runs reached a drive before its lapse's stop"
    )
    assert lapses == rounds * 4
    assert left_running == []
    # The race was real: commands accepted under the lease were still waiting at its lapse.
    assert results["accepted, cut by the lapse"] > 0


async def test_a_lapse_behind_a_cut_link_stops_the_drive_first_thing_when_it_is_back() -> None:
    loop = asyncio.get_running_loop()
    async with cuttable_line() as (sim, log, proxy):
        text = _toml(f"tcp://127.0.0.1:{proxy.port}", lease_s=0.5, interval_s=0.05)
        async with running_gateway(text) as gateway:
            await polled(gateway)
            drive = drive_of(gateway, "hall", 1)
            assert (await gateway.write(SCADA, drive, Heartbeat())).ok
            assert (await gateway.write(SCADA, drive, SetFrequency(20.0))).ok
            assert (await gateway.write(SCADA, drive, RunCommand(Direction.FORWARD))).ok
            bus = gateway.lines[0].bus
            await proxy.cut()
            await wait_for(lambda: not bus.connected, "the link down")
            # The lease lapses with the link down: the stop cannot go, and is retried.
            await wait_for(lambda: "not connected" in drive.lapse_error, "the lapse waiting")
            assert drive.lapse_pending
            problems = gateway.problems()
            assert any("node 1" in p and "not confirmed" in p for p in problems), problems
            metrics = {
                (m.name, tuple(s.labels.values())): s.value
                for m in gateway.metrics()
                for s in m.samples
            }
            assert metrics[("sj300_gateway_lapse_pending", ("hall", "1"))] == 1
            assert (await gateway.write(OPERATOR, drive, Heartbeat())).refusal is Refusal.BUSY
            assert sim.drives[1].state(loop.time()) is not RunState.STOPPED  # out of reach
            cut_at = loop.time()
            await proxy.start()  # the same port: the link comes back
            await wait_for(lambda: not drive.lapse_pending, "the stop confirmed", timeout=15)
            reconnected_at = next(t for t in proxy.connected_at if t > cut_at)
            parser = sj3.RequestParser()
            after = [
                event
                for when, direction, data in log.chunks
                if direction == "rx" and when >= reconnected_at
                for event in parser.feed(data)
            ]
            first = after[0]
            assert isinstance(first, sj3.Request), after[:3]
            assert (first.node, first.command, first.data) == (1, sj3.Command.RUN, b"0"), after[:3]
            assert (await gateway.write(OPERATOR, drive, Heartbeat())).ok  # free again
            assert not gateway.problems()
        await wait_for(
            lambda: sim.drives[1].state(loop.time()) is RunState.STOPPED, "the motor stopped"
        )


async def test_a_stop_needs_no_lease_and_a_run_does() -> None:
    loop = asyncio.get_running_loop()
    async with (
        _paced_line(19200) as (sim, url, _),
        running_gateway(_toml(url, lease_s=5.0, interval_s=0.1)) as gateway,
    ):
        await polled(gateway)
        drive = drive_of(gateway, "hall", 2)
        assert (await gateway.write(SCADA, drive, Heartbeat())).ok
        assert (await gateway.write(SCADA, drive, RunCommand(Direction.FORWARD))).ok
        await wait_for(lambda: sim.drives[2].state(loop.time()).outputting, "running")
        run = await gateway.write(OPERATOR, drive, RunCommand(Direction.FORWARD))
        assert run.refusal is Refusal.LEASE_HELD
        assert (await gateway.write(OPERATOR, drive, RunCommand(Direction.STOP))).ok
        await wait_for(lambda: sim.drives[2].state(loop.time()) is RunState.STOPPED, "stopped")
        assert drive.lease.holder == SCADA  # the stop did not take the lease away
        counts = gateway.audit.counts
        assert counts["ok"] == 3, counts  # the heartbeat is audited too
        assert counts["lease_held"] == 1, counts


async def test_a_connection_scoped_lease_lapses_when_its_connection_closes() -> None:
    async with (
        _paced_line(19200) as (_, url, log),
        running_gateway(
            _toml(url, lease_s=30.0, interval_s=0.1, extra='lease_scope = "connection"')
        ) as gateway,
    ):
        await polled(gateway)
        drive = drive_of(gateway, "hall", 3)
        heartbeat = await gateway.write(SCADA, drive, Heartbeat(), connection=f"{SCADA}:5000")
        assert heartbeat.ok
        assert (await gateway.write(SCADA, drive, RunCommand(Direction.FORWARD))).ok
        gateway.disconnected(f"{SCADA}:5001")  # another connection of the same client
        assert drive.lease.holder == SCADA
        gateway.disconnected(f"{SCADA}:5000")
        assert drive.lease.holder is None  # at once, not 30 s later
        await _settled(gateway, drive)
        assert _run_requests(log, 3)[-1][1] == b"0"


async def test_a_client_scoped_lease_outlives_a_closed_connection() -> None:
    async with (
        _paced_line(19200) as (_, url, _),
        running_gateway(_toml(url, lease_s=30.0, interval_s=0.1)) as gateway,
    ):
        await polled(gateway)
        drive = drive_of(gateway, "hall", 3)
        assert (await gateway.write(SCADA, drive, Heartbeat(), connection=f"{SCADA}:5000")).ok
        gateway.disconnected(f"{SCADA}:5000")
        assert drive.lease.holder == SCADA


def test_a_lease_scope_is_client_or_connection() -> None:
    text = _toml("sim://?nodes=1-4", lease_s=1.0, extra='lease_scope = "conection"')
    with pytest.raises(GatewayConfigError) as caught:
        parse_config(text, "plant.toml")
    assert str(caught.value) == (
        "plant.toml:11: lines[0].lease_scope: unknown scope 'conection' "
        "(did you mean 'connection'?)"
    )
    assert (
        parse_config(text.replace("conection", "connection"), "plant.toml").lines[0].lease_scope
        == "connection"
    )


async def test_over_modbus_a_second_operator_stops_and_a_closed_connection_lapses() -> None:
    """Modbus end to end: another address may stop (not run); a connection-scoped lease
    lapses when its TCP connection closes."""
    loop = asyncio.get_running_loop()
    extra = 'lease_scope = "connection"\n'
    async with _paced_line(19200) as (sim, url, log):
        text = '[modbus]\nlisten = "127.0.0.1:0"\n' + _toml(
            url, lease_s=30.0, interval_s=0.1, extra=extra
        )
        async with running_gateway(text) as gateway:
            await polled(gateway)
            drive = drive_of(gateway, "hall", 1)
            async with modbus_client(gateway, "127.0.0.1") as scada:
                for register, value in ((1000, 1), (1003, 1500), (1002, 1)):
                    reply = await scada.write_register(register, value, device_id=1)
                    assert not reply.isError(), (register, reply)
                await wait_for(lambda: sim.drives[1].state(loop.time()).outputting, "running")
                async with modbus_client(gateway, "127.0.0.2") as operator:
                    run = await operator.write_register(1002, 1, device_id=1)
                    assert run.isError()
                    assert run.exception_code == 0x06  # lease held: no run
                    stop = await operator.write_register(1002, 0, device_id=1)
                    assert not stop.isError(), stop  # stop: always
                await wait_for(
                    lambda: sim.drives[1].state(loop.time()) is RunState.STOPPED, "stopped"
                )
                assert drive.lease.holder == "127.0.0.1"
            # The holder's connection closed: its lease lapses now, not 30 s later.
            await wait_for(lambda: drive.lease.holder is None, "the lease lapsed", timeout=5)
            await _settled(gateway, drive)
            assert _run_requests(log, 1)[-1][1] == b"0"
