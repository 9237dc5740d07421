"""Home Assistant's births coalesce: a storm of them costs one re-discovery per window.

Anyone the broker lets publish on ``homeassistant/status`` can say ``online`` as
fast as the broker takes it; each one rebuilt and re-queued the whole discovery
on the loop (1,000 held it 1.3 s: tests/adversarial/test_probe_findings.py).
Checked here on the gate itself (sj300_async/gateway/mqtt/_births.py) with a
short window, and end to end through a mosquitto of the test's own. Every wait
is for a state (a count reached, a barrier delivered), never a guessed time.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from mqtt_broker import Broker, publish, running_broker
from waiting import wait_for

from sj300_async.gateway.mqtt import Topics
from sj300_async.gateway.mqtt._births import MIN_INTERVAL_S, Rediscovery
from sj300_async.gateway.mqtt._stats import BridgeStats

from .conftest import SimLine, running_gateway
from .test_gateway_mqtt import CONFIGS, bridge, configs, configs_settled, mqtt_toml, subscriber

_log = logging.getLogger("sj300_async.gateway.mqtt")
#: The window in these tests: short, so the one at its end comes soon.
WINDOW_S = 0.3


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


class _Gate:
    def __init__(self) -> None:
        self.announced = 0
        self.stats = BridgeStats()
        self.gate = Rediscovery(self._announce, self.stats, _log, interval_s=WINDOW_S)

    def _announce(self) -> None:
        self.announced += 1


async def _announced(g: _Gate, count: int) -> None:
    await wait_for(lambda: g.announced == count, f"re-discovery {count}")


def test_the_window_is_ten_seconds() -> None:
    assert MIN_INTERVAL_S == 10.0


async def test_a_storm_of_births_is_one_re_discovery_now_and_one_at_the_window_s_end(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="sj300_async.gateway.mqtt")
    g = _Gate()
    for _ in range(1000):
        g.gate.birth()
    # The first at once; the second scheduled at the window's end; 998 add nothing.
    assert g.announced == 1
    assert g.gate.scheduled
    assert g.stats.births_coalesced == 998
    await wait_for(lambda: g.announced == 2, "the re-discovery at the window's end")
    assert not g.gate.scheduled  # nothing else can come: no timer is left
    assert g.stats.rediscoveries == 2
    said = [r for r in caplog.records if "faster than one re-discovery" in r.getMessage()]
    assert len(said) == 1, said


async def test_a_flapping_storm_over_three_windows_is_exactly_four_re_discoveries() -> None:
    g = _Gate()
    for burst in range(3):
        for _ in range(300):
            g.gate.birth()
        # Each burst after the first lands within the window of the re-discovery that
        # just ran: one more at that window's end, the rest coalesced.
        await _announced(g, burst + 2)
        assert not g.gate.scheduled
    assert g.announced == 4
    assert g.stats.births_coalesced == 300 - 2 + 2 * (300 - 1)


async def test_home_assistant_starting_twice_quickly_gets_its_configs_at_the_window_s_end(
    sim_line: SimLine, broker: Broker
) -> None:
    async with (
        subscriber(broker) as sub,
        running_gateway(mqtt_toml(sim_line.url, broker)) as gateway,
    ):
        mqtt = bridge(gateway)
        mqtt._rediscovery.interval_s = 1.0
        availability = Topics("gw1").drive_availability("hall", 4)
        await sub.until(lambda m: m.topic == availability, "node 4 polled")
        connected = await configs_settled(sub)  # the connect's own
        # Home Assistant starts: its configs at once (the connect's announce does not
        # open a window).
        await publish(broker, "homeassistant/status", "online")
        await sub.until(lambda m: m.topic.endswith("/config") and not m.retained,
                        "the configs again", count=connected + CONFIGS)  # fmt: skip
        # It starts again within the window, then a storm: the configs once more, at the
        # window's end, and only once.
        await publish(broker, "homeassistant/status", "online")
        for _ in range(50):
            await publish(broker, "homeassistant/status", "online")
        await wait_for(lambda: mqtt.stats.rediscoveries == 2, "the window's end", timeout=10)
        await sub.until(lambda m: m.topic.endswith("/config") and not m.retained,
                        "the configs at the window's end",
                        count=connected + 2 * CONFIGS)  # fmt: skip
        await sub.barrier()
        assert len(configs(sub, retained=False)) == connected + 2 * CONFIGS
        assert mqtt.stats.births_coalesced == 50
        assert not mqtt._rediscovery.scheduled
        counted = {f.name: f.samples[0].value for f in mqtt.metrics() if not f.samples[0].labels}
        assert counted["sj300_mqtt_births_coalesced"] == 50
        assert counted["sj300_mqtt_rediscoveries"] == 2
