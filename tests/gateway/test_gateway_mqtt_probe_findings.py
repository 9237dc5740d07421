"""What an adversarial review of the new MQTT features found, each shown failing, then fixed.

An attacker here may publish and subscribe on the broker (under the
gateway's prefix, too) but holds no gateway credentials. A real mosquitto
of the test's own and a simulated line:

- A node level that Python calls digits but ``int`` refuses (``²``, or
  5,000 ASCII digits) killed the bridge's receiver: one retained message on
  a command topic made the bridge reconnect for ever, and one on a state
  topic made the start's sweep fail at every connection, silently.
- The sweep cleared the discovery configs of *another* gateway whose node
  id is written alike (``gw1_b``'s ``hall`` 1 and ``gw1``'s ``b_hall`` 1
  are both ``sj300_gw1_b_hall_1``): one retained junk state under ``gw1``
  made ``gw1`` clear them. It clears only a config that names its topics.
- Home Assistant's birth (or its will and a birth) heard while a command
  from MQTT was being carried out made the bridge keep, and renew for
  ever, the lease that command took under the presence before: the birth
  is meant to end the renewals.
- The sweep's two rounds shared one barrier topic, which every subscriber
  sees: replayed, it ended the second round before its retained configs
  came, and a removed drive's configs stayed (the sweep said done).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterable
from pathlib import Path
from typing import cast

import pytest
from mqtt_broker import Broker, publish, running_broker
from waiting import wait_for

from sj300_async.gateway import GatewayDrive, RunCommand, WriteRequest, WriteResult
from sj300_async.gateway.mqtt import MqttConfig, Topics, parse_state_topic
from sj300_async.gateway.mqtt._sweep import Sweeper, sweep
from sj300_async.gateway.mqttlink.client import Client, Message

from .conftest import SimLine, drive_of, running_gateway
from .test_gateway_mqtt import bridge, mqtt_toml
from .test_gateway_mqtt_presence import LEASE_S, STATUS, toml
from .test_gateway_mqtt_sweep import retained, served_once

TOPICS = Topics("gw1")


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


def test_a_node_level_that_is_not_ascii_digits_is_no_node() -> None:
    assert TOPICS.parse_command("sj300/gw1/hall/²/set/lease") is None
    assert TOPICS.parse_command(f"sj300/gw1/hall/{'9' * 5000}/set/lease") is None
    assert TOPICS.parse_command("sj300/gw1/hall/12/set/lease") == ("hall", 12, "lease")
    assert parse_state_topic("sj300/gw1/hall/²/state") is None
    assert parse_state_topic("sj300/gw1/hall/3/state") == ("gw1", "hall", 3)


async def test_junk_node_levels_neither_break_the_connection_nor_the_sweep(
    sim_line: SimLine, broker: Broker
) -> None:
    junk_command = "sj300/gw1/hall/²/set/command"
    junk_state = "sj300/gw1/hall/²/state"
    await publish(broker, junk_command, "run_forward", retain=True)
    await publish(broker, junk_state, "{}", retain=True)
    try:
        async with running_gateway(mqtt_toml(sim_line.url, broker)) as gateway:
            mqtt = bridge(gateway)
            await wait_for(lambda: mqtt.stats.ignored >= 1 or mqtt.stats.losses >= 1,
                           "the retained junk command handled")  # fmt: skip
            await publish(broker, f"sj300/gw1/hall/{'9' * 5000}/set/lease", "1")
            await wait_for(lambda: mqtt.stats.ignored >= 2 or mqtt.stats.losses >= 1,
                           "the long junk command handled")  # fmt: skip
            assert mqtt.stats.losses == 0
            assert mqtt.stats.connects == 1
            await served_once(gateway)  # the sweep ran to its end
            assert junk_state not in await retained(broker)
            # And the connection serves commands as before.
            await publish(broker, TOPICS.command("hall", 1, "lease"), "1")
            lease = drive_of(gateway, "hall", 1).lease
            await wait_for(lambda: lease.holder == "mqtt", "the lease taken")
    finally:
        await publish(broker, junk_command, None, retain=True)


async def test_the_sweep_leaves_another_gateway_s_configs_written_alike(
    sim_line: SimLine, broker: Broker
) -> None:
    async with running_gateway(mqtt_toml(sim_line.url, broker, gateway="gw1_b")) as gateway:
        await served_once(gateway)
    theirs = {t for t in await retained(broker) if "/sj300_gw1_b_hall_1/" in t}
    assert len(theirs) > 5
    # Someone allowed to publish under sj300/gw1/ leaves a state of a drive gw1 never had,
    # whose discovery node id is gw1_b's hall 1.
    junk = "sj300/gw1/b_hall/1/state"
    await publish(broker, junk, "{}", retain=True)
    async with running_gateway(mqtt_toml(sim_line.url, broker)) as gateway:
        await served_once(gateway)
    left = await retained(broker)
    assert theirs <= left
    assert junk not in left  # its own topic: cleared
    # Decommissioning gw1 leaves them too.
    await publish(broker, junk, "{}", retain=True)
    config = MqttConfig("127.0.0.1", broker.port, client_id="decommission")
    await sweep(config, TOPICS, None)
    left = await retained(broker)
    assert theirs <= left
    assert not {t for t in left if t.startswith("sj300/gw1/") or "/sj300_gw1_hall_" in t}


@pytest.mark.parametrize("said", [["online"], ["offline", "online"]])
async def test_a_birth_during_a_command_ends_the_lease_it_took(
    sim_line: SimLine, broker: Broker, said: list[str]
) -> None:
    loop = asyncio.get_running_loop()
    async with running_gateway(toml(sim_line.url, broker)) as gateway:
        mqtt = bridge(gateway)
        await wait_for(lambda: mqtt.connected, "connected")
        await publish(broker, STATUS, "online")
        await wait_for(lambda: mqtt._presence.present is True, "HA's presence")
        await wait_for(lambda: drive_of(gateway, "hall", 1).readings.polled, "drive 1 polled")
        write = gateway.write

        async def write_hearing_a_birth(
            client: str,
            drive: GatewayDrive,
            request: WriteRequest,
            *,
            connection: str | None = None,
        ) -> WriteResult:
            result = await write(client, drive, request, connection=connection)
            if isinstance(request, RunCommand):
                # Home Assistant restarted while the run was being carried out.
                for payload in said:
                    mqtt._presence.heard(payload.encode())
            return result

        gateway.write = write_hearing_a_birth  # type: ignore[method-assign]
        await publish(broker, TOPICS.command("hall", 1, "command"), "run_forward")
        motor = sim_line.sim.drives[1]
        await wait_for(lambda: motor.state(loop.time()).outputting, "the motor running")
        controller = gateway.lines[0].controller
        # Nobody renews the lease now: it lapses within lease_s, and the motor stops.
        await wait_for(lambda: controller.lapses == 1, "the lapse", timeout=LEASE_S + 2)
        await wait_for(lambda: not motor.state(loop.time()).outputting, "stopped", timeout=30)


class _ReplayingBroker:
    """A client for :class:`Sweeper` whose broker hands over each round's retained
    messages just after its barrier was published, with an attacker who saw the
    earlier barriers (they go to every subscriber) replaying them first."""

    def __init__(self, rounds: list[list[Message]]) -> None:
        self.rounds, self.barriers, self.cleared = rounds, list[str](), list[str]()
        self.sweeper: Sweeper | None = None

    async def subscribe(self, filters: list[tuple[str, int]], qos: int) -> list[int]:
        return [qos] * len(filters)

    async def unsubscribe(self, filters: list[str]) -> None:
        pass

    async def publish(self, topic: str, payload: bytes, qos: int) -> None:
        sweeper = self.sweeper
        assert sweeper is not None
        for seen in self.barriers:
            sweeper.feed(Message(seen, b"", 1, False, 0))
        self.barriers.append(topic)
        retained = self.rounds.pop(0)
        barrier = Message(topic, b"", 1, False, 0)
        loop = asyncio.get_running_loop()
        loop.call_soon(lambda: [sweeper.feed(m) for m in (*retained, barrier)])

    async def publish_many(self, messages: Iterable[tuple[str, bytes, bool]], qos: int) -> None:
        self.cleared += [topic for topic, _, _ in messages]


async def test_a_replayed_barrier_does_not_end_the_sweep_s_next_round() -> None:
    gone_state = TOPICS.state("old", 1)
    gone_config = "homeassistant/sensor/sj300_gw1_old_1/status/config"
    body = f'{{"state_topic":"{gone_state}"}}'.encode()
    client = _ReplayingBroker(
        [
            [Message(gone_state, b"{}", 1, True, 2)],
            [Message(gone_config, body, 1, True, len(body))],
        ]
    )
    sweeper = client.sweeper = Sweeper(MqttConfig("b", 1883), TOPICS)
    swept = await sweeper.run(cast(Client, client), None)
    assert sorted(client.cleared) == sorted([gone_state, gone_config])
    assert len(set(client.barriers)) == 2  # a barrier of its own each round
    assert swept.topics == 2
