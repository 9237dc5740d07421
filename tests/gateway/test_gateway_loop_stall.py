"""The gateway's own stall is not lease time (issue 41).

A SCADA in its own process holds drive 1's lease with a heartbeat every
quarter of ``lease_s`` and runs the motor. The gateway's event loop is
then blocked for twice ``lease_s`` (the test's own ``time.sleep`` on the
loop, standing for a password check or a big parse on it): the SCADA's
heartbeats wait unread in its socket the whole time. When the loop runs
again, the lease must still be the SCADA's and the motor must still run:
the stall is credited to the lease (``_control``), measured by the loop
monitor (``_looplag``), and shown on ``/healthz`` and ``/metrics``.

A holder that really went away still loses the lease: the lease's clock
only stops while the loop is stuck, so it lapses at most ``lease_s`` after
the loop runs again.
"""

from __future__ import annotations

import asyncio
import signal
import sys
import time

from waiting import wait_for

from sj300_async.simulator import RunState

from .conftest import SimLine, drive_of, gateway_toml, modbus_port, running_gateway
from .test_gateway_lease import SCADA, WRITES

LEASE_S = 1.0


async def _scada(port: int) -> asyncio.subprocess.Process:
    scada = await asyncio.create_subprocess_exec(
        sys.executable, "-c", SCADA, str(port), str(LEASE_S), stdout=asyncio.subprocess.PIPE
    )
    assert scada.stdout is not None
    assert await asyncio.wait_for(scada.stdout.readline(), 20) == b"running\n"
    return scada


async def test_a_heartbeating_scada_keeps_its_lease_through_the_gateways_own_stall(
    sim_line: SimLine,
) -> None:
    loop = asyncio.get_running_loop()
    motor = sim_line.sim.drives[1]
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        scada = await _scada(modbus_port(gateway))
        try:
            await wait_for(lambda: motor.state(loop.time()) is not RunState.STOPPED, "running")
            lease = drive_of(gateway, "hall", 1).lease
            renewed = lease.expires_at
            await wait_for(lambda: lease.expires_at > renewed, "a heartbeat", timeout=LEASE_S)
            monitor = gateway.loop_monitor
            mark = monitor.mark()
            time.sleep(2 * LEASE_S)  # the stall under test: nothing on the loop runs
            after = loop.time()
            # Heartbeats read after the stall renew it: from then on as usual.
            await wait_for(lambda: lease.expires_at - LEASE_S > after, "a heartbeat after")
            assert lease.holder == "127.0.0.1"
            assert gateway.lines[0].controller.lapses == 0
            assert motor.state(loop.time()) is not RunState.STOPPED
            assert monitor.since(mark).max_s >= 2 * LEASE_S - 0.1
            assert monitor.stalled() >= 2 * LEASE_S - 0.2
            assert any("event loop lagged" in problem for problem in gateway.problems())
        finally:
            scada.send_signal(signal.SIGKILL)
            await scada.wait()
        # Gone for good: the lease lapses and the motor stops, stall or no stall.
        await wait_for(lambda: gateway.lines[0].controller.lapses == 1, "the lapse", timeout=10)
        await wait_for(lambda: motor.state(loop.time()) is RunState.STOPPED, "stopped", timeout=30)


async def test_a_silent_holder_lapses_within_its_lease_of_the_loop_running_again(
    sim_line: SimLine,
) -> None:
    loop = asyncio.get_running_loop()
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        scada = await _scada(modbus_port(gateway))
        lease = drive_of(gateway, "hall", 1).lease
        scada.send_signal(signal.SIGKILL)
        await scada.wait()
        time.sleep(3 * LEASE_S)  # a stall longer than the lease, the holder silent
        running_again = loop.time()
        await wait_for(lambda: gateway.lines[0].controller.lapses == 1, "the lapse", timeout=10)
        assert loop.time() - running_again <= LEASE_S + 0.5
        assert 2 * LEASE_S <= lease.credited_s <= 3 * LEASE_S + 0.5
        assert lease.holder is None
