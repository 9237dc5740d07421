"""The control lease: a controller that disappears does not leave a motor running.

A separate process plays the SCADA: it takes the lease of drive 1, sets a
frequency, runs the drive, and keeps writing the heartbeat. The test kills
it (SIGKILL: no goodbye, as a crashed SCADA or a cut cable) and measures,
on the simulator's line log, when the stop reaches the drive: within the
lease time plus one transaction of the last heartbeat. The figures are
printed (``pytest -s``).
"""

from __future__ import annotations

import asyncio
import signal
import sys
import textwrap

from waiting import wait_for

from sj300_async import sj300 as sj3
from sj300_async.gateway import Heartbeat
from sj300_async.simulator import RunState

from .conftest import SimLine, drive_of, gateway_toml, modbus_port, running_gateway

LEASE_S = 1.0
#: One transaction on the simulated line: a stop and its answer cross a
#: 19200-baud line in about 10 ms; the bound leaves room for a loaded machine.
ONE_TRANSACTION_S = 0.1

SCADA = textwrap.dedent(
    """
    import asyncio, sys
    from pymodbus.client import AsyncModbusTcpClient

    async def main() -> None:
        client = AsyncModbusTcpClient("127.0.0.1", port=int(sys.argv[1]), retries=0)
        assert await client.connect()
        for address, value in ((1000, 1), (1003, 2000), (1002, 1)):
            reply = await client.write_register(address, value, device_id=1)
            assert not reply.isError(), (address, reply)
        print("running", flush=True)
        while True:
            await asyncio.sleep(float(sys.argv[2]) / 4)
            assert not (await client.write_register(1000, 1, device_id=1)).isError()

    asyncio.run(main())
    """
)

WRITES = f"""
    lease_s = {LEASE_S}
    on_lapse = "stop"
    [[lines.writes]]
    nodes = "1"
    control = true
    """


def _stops(line: SimLine) -> list[float]:
    """When each stop request for node 1 crossed the line."""
    parser = sj3.RequestParser()
    out = []
    for when, direction, data in line.log.chunks:
        if direction != "rx":
            continue
        for event in parser.feed(data):
            if not isinstance(event, sj3.Request):
                continue
            if event.command == sj3.Command.RUN and event.node == 1 and event.data == b"0":
                out.append(when)
    return out


async def test_a_killed_controller_gets_its_drive_stopped_within_the_lease(
    sim_line: SimLine,
) -> None:
    loop = asyncio.get_running_loop()
    drive = sim_line.sim.drives[1]
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        scada = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            SCADA,
            str(modbus_port(gateway)),
            str(LEASE_S),
            stdout=asyncio.subprocess.PIPE,
        )
        try:
            assert scada.stdout is not None
            assert await asyncio.wait_for(scada.stdout.readline(), 20) == b"running\n"
            await wait_for(
                lambda: drive.state(loop.time()) is not RunState.STOPPED, "motor running"
            )
            lease = drive_of(gateway, "hall", 1).lease
            # Let it keep the lease over a few heartbeats, then pull the plug.
            renewed = lease.expires_at
            await wait_for(lambda: lease.expires_at > renewed, "a heartbeat", timeout=LEASE_S)
            scada.send_signal(signal.SIGKILL)
            killed_at = loop.time()
        finally:
            if scada.returncode is None:
                scada.kill()
            await scada.wait()
        last_heartbeat = lease.expires_at - LEASE_S
        await wait_for(lambda: _stops(sim_line), "the stop", timeout=LEASE_S + 5)
        stopped_at = _stops(sim_line)[0]
        after_heartbeat = stopped_at - last_heartbeat
        print(
            f"\nlease {LEASE_S:.1f} s: stop on the line {after_heartbeat * 1000:.0f} ms after "
            f"the last heartbeat, {(stopped_at - killed_at) * 1000:.0f} ms after the kill"
        )
        assert LEASE_S <= after_heartbeat <= LEASE_S + ONE_TRANSACTION_S
        await wait_for(
            lambda: drive.state(loop.time()) is RunState.STOPPED, "the motor stopped", timeout=30
        )
        assert gateway.lines[0].controller.lapses == 1
    assert len(_stops(sim_line)) == 1  # closing the gateway sent no second stop: no lease held


async def test_a_holder_that_releases_the_lease_leaves_no_lapse_behind(sim_line: SimLine) -> None:
    """Controller.release: the holder hands the lease back; only the holder can; the next
    client takes it at once; the released lease's end passes with no stop."""
    loop = asyncio.get_running_loop()
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        drive = drive_of(gateway, "hall", 1)
        controller = gateway.lines[0].controller
        assert (await gateway.write("scada", drive, Heartbeat())).ok
        released_end = drive.lease.expires_at
        assert not controller.release("intruder", drive)
        assert drive.lease.holder == "scada"
        assert controller.release("scada", drive)
        assert drive.lease.holder is None
        assert not controller.release("scada", drive)  # nothing left to release
        # The next client takes it at once, and hands it back too.
        assert (await gateway.write("panel", drive, Heartbeat())).ok
        assert drive.lease.holder == "panel"
        assert controller.release("panel", drive)
        await wait_for(lambda: loop.time() > released_end + ONE_TRANSACTION_S, "the lease's end")
        assert controller.lapses == 0
        assert controller.pending_lapses == 0
        assert not drive.lapse_pending
    assert _stops(sim_line) == []  # nothing stopped: not at the lease's end, not at the close
