"""What an earlier configuration left retained on the broker is cleared (issue 43).

A real gateway publishes retained states, availabilities and Home
Assistant configs for four drives (two with control) to a mosquitto of the
test's own; a second gateway with the same id serves two of them, one with
control. Once its start's sweep has run, a fresh subscriber finds nothing
retained of the removed drives and none of the taken-away controls, and
everything the second configuration publishes. Decommissioning
(``sweep(..., None)``) leaves nothing of the gateway id on the broker, and
touches another gateway's retained topics not at all.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from cli.clirun import closed_port, sj300
from mqtt_broker import READY, Broker, running_broker
from waiting import wait_for

from sj300_async.gateway import Gateway
from sj300_async.gateway.mqtt import MqttConfig, Topics
from sj300_async.gateway.mqtt._sweep import sweep

from .conftest import SimLine, running_gateway
from .test_gateway_mqtt import CONFIGS, CONTROLS, bridge, mqtt_toml, subscriber


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


async def retained(broker: Broker) -> set[str]:
    """Every topic the broker holds a retained message on, now (but the test's marker)."""
    async with subscriber(broker) as sub:
        await sub.barrier()
    return {m.topic for m in sub.messages if m.retained} - {READY}


async def served_once(gateway: Gateway) -> None:
    """Until *gateway*'s bridge has published every config and a state of each drive, and
    its start's sweep has run."""
    mqtt = bridge(gateway)
    await wait_for(lambda: mqtt.stats.published >= CONFIGS, "the configs published")
    await wait_for(lambda: len(mqtt.stats.states) == len(gateway.drives), "a state a drive")
    await wait_for(lambda: mqtt._sweeper is not None and mqtt._sweeper.done, "the sweep done")


async def test_removed_drives_and_controls_are_cleared_and_the_rest_kept(
    sim_line: SimLine, broker: Broker
) -> None:
    before = mqtt_toml(sim_line.url, broker)
    async with running_gateway(before) as gateway:
        await served_once(gateway)
        assert bridge(gateway).stats.swept == 0  # nothing left by an earlier one
    topics = Topics("gw1")
    first = await retained(broker)
    assert {topics.state("hall", n) for n in range(1, 5)} <= first
    # Drives 3 and 4 removed; drive 2 keeps its sensors but loses control.
    lines, grant = 'nodes = "1-4"', '[[lines.writes]]\nnodes = "1-2"'
    assert before.count(lines) == before.count(grant) == 1
    after = before.replace(lines, 'nodes = "1-2"').replace(grant, '[[lines.writes]]\nnodes = "1"')
    async with running_gateway(after) as gateway:
        mqtt = bridge(gateway)
        await served_once(gateway)
        now = await retained(broker)
        swept = mqtt.stats.swept
    gone = first - now
    assert not {t for t in now if "/hall/3/" in t or "/hall/4/" in t or "_hall_3/" in t
                or "_hall_4/" in t}  # fmt: skip
    assert {topics.state("hall", 3), topics.drive_availability("hall", 4)} <= gone
    node_2 = {t.split("/")[-2] for t in now if "/sj300_gw1_hall_2/" in t}
    assert not node_2 & set(CONTROLS)  # its control entities gone
    assert {"status", "output_frequency", "events"} <= node_2  # its sensors kept
    node_1 = {t.split("/")[-2] for t in now if "/sj300_gw1_hall_1/" in t}
    assert set(CONTROLS) <= node_1
    assert topics.availability in now  # the gateway's own (offline now, retained)
    assert swept == len(gone)


async def test_decommissioning_clears_every_topic_of_the_gateway_id_and_no_other(
    sim_line: SimLine, broker: Broker
) -> None:
    for gateway_id in ("gw1", "gw10"):  # gw10: a gateway whose id gw1 begins
        async with running_gateway(mqtt_toml(sim_line.url, broker, gateway=gateway_id)) as gw:
            await served_once(gw)
    before = await retained(broker)
    config = MqttConfig("127.0.0.1", broker.port, client_id="decommission")
    swept = await sweep(config, Topics("gw1"), None)
    left = await retained(broker)
    assert not {t for t in left if "/gw1/" in t or "sj300_gw1/" in t or "sj300_gw1_" in t}
    assert {t for t in before if "/gw10/" in t or "sj300_gw10" in t} <= left
    assert swept.topics == len(before - left)
    assert sorted(swept.drives) == [("hall", n) for n in range(1, 5)]


async def test_the_decommission_command_clears_the_gateway_and_says_so(
    sim_line: SimLine, broker: Broker, tmp_path: Path
) -> None:
    text = mqtt_toml(sim_line.url, broker)
    async with running_gateway(text) as gateway:
        await served_once(gateway)
    before = await retained(broker)
    path = tmp_path / "gateway.toml"
    path.write_text(text, encoding="utf-8")
    result = await sj300("gateway", "--config", str(path), "--decommission")
    assert result.code == 0, result.err
    assert result.out == (
        f"cleared {len(before)} retained topics of gateway gw1 on {broker.url} (4 drives)\n"
    )
    assert await retained(broker) == set()
    # A configuration without [mqtt], and a broker that is not there: one line each.
    path.write_text(text.split("[mqtt]")[0] + text.split("keepalive_s = 30\n", 1)[1])
    refused = await sj300("gateway", "--config", str(path), "--decommission")
    refused.assert_one_line_error(2, "--decommission clears what [mqtt] published")
    nobody = f"mqtt://127.0.0.1:{closed_port()}"
    path.write_text(text.replace(broker.url, nobody), encoding="utf-8")
    unreachable = await sj300("gateway", "--config", str(path), "--decommission")
    unreachable.assert_one_line_error(2, nobody, "nothing cleared")
