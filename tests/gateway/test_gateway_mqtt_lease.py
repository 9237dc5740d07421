"""The control lease over MQTT, with a real broker: a session-scoped lease, a pending lapse shown.

- With ``lease_scope = "connection"``, the MQTT holder's lease lapses the
  moment the gateway's session to the broker is lost (the broker stops),
  not ``lease_s`` later, and the drive is stopped.
- While a lapse's stop is not confirmed (the drive does not answer), the
  drive's state message says ``"lapse_pending": true``; once the drive
  answers and is stopped, ``false`` again.
"""

from __future__ import annotations

import asyncio
import textwrap

from mqtt_broker import Broker, publish
from waiting import wait_for

from sj300_async.gateway.mqtt import StateMessage, Topics
from sj300_async.simulator import RunState

from .conftest import SimLine, drive_of, gateway_toml, running_gateway
from .test_gateway_mqtt import GRANTS, bridge, broker, state_of, subscriber

__all__ = ["broker"]  # the fixture, shared with test_gateway_mqtt


def _toml(url: str, mqtt: Broker, lease: str) -> str:
    extra = f'[gateway]\nid = "gw1"\n[mqtt]\nurl = "{mqtt.url}"\nkeepalive_s = 30\n'
    return gateway_toml(url, extra=extra, line_extra=textwrap.dedent(lease) + GRANTS)


async def _run_drive_1(mqtt: Broker, sim_line: SimLine) -> None:
    """Take node 1's lease over MQTT and run it; return once the motor turns."""
    loop = asyncio.get_running_loop()
    topics = Topics("gw1")
    await publish(mqtt, topics.command("hall", 1, "lease"), "1")
    await publish(mqtt, topics.command("hall", 1, "frequency_hz"), "20")
    await publish(mqtt, topics.command("hall", 1, "command"), "run_forward")
    await wait_for(
        lambda: sim_line.sim.drives[1].state(loop.time()).outputting, "the motor running"
    )


async def test_a_session_scoped_lease_lapses_when_the_mqtt_session_is_lost(
    sim_line: SimLine, broker: Broker
) -> None:
    loop = asyncio.get_running_loop()
    lease = 'lease_s = 60\nlease_scope = "connection"\n'
    async with running_gateway(_toml(sim_line.url, broker, lease)) as gateway:
        mqtt = bridge(gateway)
        await wait_for(lambda: mqtt.connected, "connected to the broker")
        drive = drive_of(gateway, "hall", 1)
        await _run_drive_1(broker, sim_line)
        assert drive.lease.holder == "mqtt"
        await broker.stop()
        await wait_for(lambda: drive.lease.holder is None, "the lease lapsed with the session")
        controller = gateway.lines[0].controller
        await wait_for(lambda: controller.lapses == 1, "the lapse action")  # not 60 s later
        await wait_for(
            lambda: sim_line.sim.drives[1].state(loop.time()) is RunState.STOPPED,
            "the motor stopped",
            timeout=15,
        )


async def test_a_pending_lapse_is_in_the_drive_s_mqtt_state(
    sim_line: SimLine, broker: Broker
) -> None:
    async with (
        running_gateway(_toml(sim_line.url, broker, "lease_s = 2\n")) as gateway,
        subscriber(broker, Topics("gw1").state("hall", 1)) as sub,
    ):
        mqtt = bridge(gateway)
        await wait_for(lambda: mqtt.connected, "connected to the broker")
        drive = drive_of(gateway, "hall", 1)
        await _run_drive_1(broker, sim_line)
        sim_line.sim.faults.silence(1)  # the lapse's stop gets no answer
        # Silenced while the lease held (2 s from the heartbeat; the run came at once).
        assert drive.lease.holder == "mqtt"
        pending = await sub.until(
            lambda m: state_of(1)(m) and StateMessage.from_json(m.payload).lapse_pending,
            "a state with the lapse pending",
            timeout=15,
        )
        assert drive.lapse_pending, pending[-1]
        assert any("not confirmed" in p for p in gateway.problems())
        sim_line.sim.faults.silence(1, False)
        await wait_for(lambda: not drive.lapse_pending, "the stop confirmed", timeout=15)
        last = len(sub.messages)
        await wait_for(
            lambda: any(
                state_of(1)(m) and not StateMessage.from_json(m.payload).lapse_pending
                for m in sub.messages[last:]
            ),
            "a state without it",
        )
