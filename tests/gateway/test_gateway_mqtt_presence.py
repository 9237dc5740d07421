"""The control lease Home Assistant's presence keeps (issue 43, mqtt/_presence.py).

A real gateway on a simulated line and a mosquitto of the test's own; Home
Assistant's presence is what it publishes on ``homeassistant/status``
(here by the test, as HA's birth and last will would). With HA present, a
run command from MQTT needs no lease taken first and no heartbeat: the
bridge keeps the lease for twice its ``lease_s`` and more. HA's
``offline`` or its next birth ends that, and the lapse stops the motor
within ``lease_s``. Without HA's word, or with ``home_assistant_lease =
false``, leases are as plain as before.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from mqtt_broker import Broker, publish, running_broker
from waiting import wait_for

from sj300_async.gateway import Gateway
from sj300_async.gateway.mqtt import Topics
from sj300_async.simulator import RunState

from .conftest import SimLine, drive_of, gateway_toml, running_gateway
from .test_gateway_mqtt import GRANTS, bridge, errors, subscriber

LEASE_S = 1.0
STATUS = "homeassistant/status"
TOPICS = Topics("gw1")


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


def toml(url: str, broker: Broker, mqtt_extra: str = "") -> str:
    extra = f'[gateway]\nid = "gw1"\n[mqtt]\nurl = "{broker.url}"\n{mqtt_extra}\n'
    lease = f'lease_s = {LEASE_S}\non_lapse = "stop"\n'
    return gateway_toml(url, extra=extra, line_extra=lease + GRANTS)


def presence(gateway: Gateway) -> tuple[float, ...]:
    """The metrics of Home Assistant's presence: (present, leases kept for it)."""
    names = ("sj300_mqtt_home_assistant_present", "sj300_mqtt_home_assistant_leases")
    found = {f.name: f.samples[0].value for f in bridge(gateway).metrics() if f.name in names}
    return tuple(float(found[name]) for name in names)


async def running(gateway: Gateway, sim_line: SimLine, broker: Broker) -> None:
    """Run drive 1 forward from MQTT, with no lease taken first; until it runs."""
    loop = asyncio.get_running_loop()
    await wait_for(lambda: bridge(gateway).connected, "connected")
    await wait_for(lambda: drive_of(gateway, "hall", 1).readings.polled, "drive 1 polled")
    await publish(broker, TOPICS.command("hall", 1, "command"), "run_forward")
    motor = sim_line.sim.drives[1]
    await wait_for(lambda: motor.state(loop.time()) is not RunState.STOPPED, "the motor running")


async def test_home_assistant_present_keeps_the_lease_and_its_will_stops_the_motor(
    sim_line: SimLine, broker: Broker
) -> None:
    loop = asyncio.get_running_loop()
    motor = sim_line.sim.drives[1]
    await publish(broker, STATUS, "online", retain=True)  # HA's birth, before the gateway
    try:
        async with running_gateway(toml(sim_line.url, broker)) as gateway:
            lease = drive_of(gateway, "hall", 1).lease
            await wait_for(lambda: presence(gateway)[0] == 1, "HA's presence heard")
            await running(gateway, sim_line, broker)
            assert lease.holder == "mqtt"  # taken for the run, by no one's heartbeat
            # HA there, and the lease kept for it once the run's write has finished
            await wait_for(lambda: presence(gateway) == (1.0, 1.0), "the lease kept for HA")
            held_from = loop.time()
            # Three lease times and no heartbeat from anyone: still running, still held.
            await wait_for(lambda: loop.time() > held_from + 3 * LEASE_S, "three lease times",
                           timeout=10)  # fmt: skip
            assert motor.state(loop.time()) is not RunState.STOPPED
            assert lease.held_by("mqtt", loop.time())
            controller = gateway.lines[0].controller
            assert controller.lapses == 0
            # Home Assistant's last will: the lease lapses within lease_s, the motor stops.
            said = loop.time()
            await publish(broker, STATUS, "offline")
            await wait_for(lambda: controller.lapses == 1, "the lapse", timeout=LEASE_S + 2)
            assert loop.time() - said <= LEASE_S + 0.5
            assert presence(gateway) == (0.0, 0.0)
            await wait_for(lambda: motor.state(loop.time()) is RunState.STOPPED, "stopped",
                           timeout=30)  # fmt: skip
    finally:
        await publish(broker, STATUS, None, retain=True)


async def test_a_birth_ends_the_lease_home_assistant_kept(
    sim_line: SimLine, broker: Broker
) -> None:
    async with running_gateway(toml(sim_line.url, broker)) as gateway:
        await wait_for(lambda: bridge(gateway).connected, "connected")
        await publish(broker, STATUS, "online")
        await wait_for(lambda: presence(gateway)[0] == 1, "HA's presence")
        await running(gateway, sim_line, broker)
        lease = drive_of(gateway, "hall", 1).lease
        taken = lease.expires_at
        await wait_for(lambda: lease.expires_at > taken, "a renewal by the bridge")
        controller = gateway.lines[0].controller
        await publish(broker, STATUS, "online")  # Home Assistant restarted
        await wait_for(lambda: controller.lapses == 1, "the lapse", timeout=LEASE_S + 2)


@pytest.mark.parametrize("how", ["no word from home assistant", "home_assistant_lease = false"])
async def test_without_home_assistant_s_lease_a_run_needs_the_lease_taken(
    sim_line: SimLine, broker: Broker, how: str
) -> None:
    off = how.startswith("home_assistant_lease")
    async with (
        subscriber(broker) as sub,
        running_gateway(toml(sim_line.url, broker, how if off else "")) as gateway,
    ):
        mqtt = bridge(gateway)
        await wait_for(lambda: mqtt.connected, "connected")
        if off:
            await publish(broker, STATUS, "online")
            await sub.until(lambda m: m.topic == STATUS, "HA's birth through the broker")
        await wait_for(lambda: drive_of(gateway, "hall", 1).readings.polled, "drive 1 polled")
        await publish(broker, TOPICS.command("hall", 1, "command"), "run_forward")
        await sub.until(lambda m: m.topic == TOPICS.error("hall", 1), "the refusal")
        assert errors(sub, 1)[0]["reason"] == "no_lease"
        assert drive_of(gateway, "hall", 1).lease.holder is None
