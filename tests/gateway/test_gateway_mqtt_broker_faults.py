"""The MQTT session tells the truth against a broker that misbehaves (tests/mqtt_misbehaving.py).

Two faults seen in the field that mosquitto never shows: a broker that
answers every PINGREQ and never acknowledges a publish (the JSON side froze,
silent, its retained availability still ``online``), and a SUBACK that
refuses a subscription (the gateway ran deaf to commands). Each is checked
where an operator sees it: the log, /metrics, /healthz, and at the broker
(a second CONNECT; a socket ended without DISCONNECT, so the will speaks).
"""

from __future__ import annotations

import asyncio
import logging

import pytest
from mqtt_misbehaving import MisbehavingBroker, misbehaving_broker
from waiting import wait_for

from sj300_async.gateway import Gateway
from sj300_async.gateway.mqtt import Topics
from sj300_async.gateway.mqtt._bridge import MqttBridge
from sj300_async.gateway.sparkplug import EdgeNode

from .conftest import SimLine, gateway_toml, metrics_port, running_gateway
from .test_gateway_metrics import fetch, scrape, value

TOPICS = Topics("gw1")
#: The Sparkplug edge node's command filter for its devices (group "plant").
DCMD = "spBv1.0/plant/DCMD/gw1/+"


def toml(url: str, broker: MisbehavingBroker, *, keepalive_s: int = 30, mqtt: str = "") -> str:
    """A gateway ``gw1`` with /metrics and /healthz, on MQTT at *broker*."""
    extra = (
        '[gateway]\nid = "gw1"\n[metrics]\nlisten = "127.0.0.1:0"\n'
        f'[mqtt]\nurl = "{broker.url}"\nkeepalive_s = {keepalive_s}\n{mqtt}'
    )
    return gateway_toml(url, extra=extra)


def bridge(gateway: Gateway) -> MqttBridge:
    northbound = gateway.northbounds["mqtt"]
    assert isinstance(northbound, MqttBridge)
    return northbound


def warnings(caplog: pytest.LogCaptureFixture, logger: str) -> list[str]:
    return [
        r.getMessage() for r in caplog.records if r.name == logger and r.levelno >= logging.WARNING
    ]


async def test_a_broker_that_never_acknowledges_loses_the_connection_within_the_keepalive(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.mqtt")
    async with (
        misbehaving_broker() as broker,
        running_gateway(toml(sim_line.url, broker, keepalive_s=1)) as gateway,
    ):
        mqtt = bridge(gateway)
        await wait_for(lambda: mqtt.connected and mqtt.stats.states.total() > 4, "states")
        broker.acknowledge = False  # pings are still answered
        first = broker.connections[0]
        await broker.until(lambda: first.closed_at is not None, "the connection ended")
        broker.acknowledge = True  # the next connection is served well
        await broker.until(lambda: len(broker.connections) == 2, "a second CONNECT")
        await wait_for(lambda: mqtt.connected, "connected again")
        async with asyncio.timeout(10):
            samples = await scrape(metrics_port(gateway))
        stats = mqtt.stats
    assert first.first_swallowed_at is not None
    assert first.closed_at is not None
    stalled_s = first.closed_at - first.first_swallowed_at
    assert 0.9 <= stalled_s <= 2.25, stalled_s  # keepalive_s to 1.5 keepalive_s, and slack
    assert any(t > first.first_swallowed_at for t in first.pings)  # alive by its pings
    # Ended without DISCONNECT, so a real broker publishes this will: the truth.
    assert not first.disconnected
    assert first.will == (TOPICS.availability, b"offline", True)
    assert (stats.puback_timeouts, stats.losses, stats.connects) == (1, 1, 2)
    assert value(samples, "sj300_mqtt_puback_timeouts_total") == 1
    (warning,) = warnings(caplog, "sj300_async.gateway.mqtt")
    assert warning.startswith(f"MQTT: lost {broker.url} (no PUBACK for 1."), warning
    assert "(keepalive_s 1): QoS 1 publish, packet " in warning
    assert "of client sj300-gw1, the oldest of " in warning
    assert warning.endswith("waiting); reconnecting"), warning
    # The second connection said online again (its own availability, retained).
    second = broker.connections[1]
    assert (TOPICS.availability, b"online", 1) in second.publishes


async def test_a_refused_subscription_is_said_counted_and_on_healthz_until_granted(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    """The JSON bridge's commands and the Sparkplug node's DCMD, two northbounds on one broker."""
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway")
    refused = {TOPICS.command_filter, DCMD}
    spb = 'sparkplug = true\ngroup_id = "plant"\n'
    async with (
        misbehaving_broker(refuse=refused) as broker,
        running_gateway(toml(sim_line.url, broker, mqtt=spb)) as gateway,
    ):
        mqtt = bridge(gateway)
        node = gateway.northbounds["sparkplug"]
        assert isinstance(node, EdgeNode)
        await wait_for(lambda: mqtt.connected and node.born, "both connected")
        mqtt_problem = (
            f"MQTT: the broker refused the subscription to {TOPICS.command_filter} "
            "(SUBACK 0x80): commands not received"
        )
        spb_problem = (
            f"Sparkplug: the broker refused the subscription to {DCMD} "
            "(SUBACK 0x80): device commands (DCMD) not received"
        )
        problems = gateway.problems()
        assert mqtt_problem in problems
        assert spb_problem in problems
        port = metrics_port(gateway)
        async with asyncio.timeout(10):
            health = await fetch(port, "/healthz")
            samples = await scrape(port)
        # Not deaf to everything: the bridge goes on publishing the drives' states.
        states = TOPICS.state("hall", 1)
        json_side = next(c for c in broker.connections if c.client_id == "sj300-gw1")
        await broker.until(lambda: any(t == states for t, _, _ in json_side.publishes),
                           "a state published")  # fmt: skip

        # The ACL fixed, the next connections' SUBACKs clear the problems.
        broker.refuse.clear()
        broker.drop()
        await wait_for(lambda: mqtt.stats.connects == 2 and node.stats.connects == 2,
                       "both connected again")  # fmt: skip
        await wait_for(lambda: mqtt.connected and node.born, "both set up again")
        after = gateway.problems()
    assert health.status == 503
    assert f"{mqtt_problem}\n".encode() in health.body
    assert f"{spb_problem}\n".encode() in health.body
    assert value(samples, "sj300_mqtt_subscriptions_refused_total",
                 filter=TOPICS.command_filter) == 1  # fmt: skip
    assert value(samples, "sj300_mqtt_subscriptions_refused_total",
                 filter="homeassistant/status") == 0  # fmt: skip
    assert value(samples, "sj300_sparkplug_subscriptions_refused_total", filter=DCMD) == 1
    assert not [p for p in after if "subscription" in p], after
    said = warnings(caplog, "sj300_async.gateway.mqtt")
    assert len(said) == 2, said
    assert said[0] == (
        f"MQTT: the broker refused the subscription to {TOPICS.command_filter!r} "
        "(SUBACK 0x80): commands not received"
    )
    assert said[1].startswith(f"MQTT: lost {broker.url} (connection lost"), said  # the drop
    assert (
        f"Sparkplug: the broker refused the subscription to {DCMD!r} (SUBACK 0x80): "
        "device commands (DCMD) not received"
    ) in warnings(caplog, "sj300_async.gateway.sparkplug")
    granted = [r.getMessage() for r in caplog.records if "granted" in r.getMessage()]
    assert granted == [
        f"MQTT: the broker granted the subscription to {TOPICS.command_filter!r} again",
        f"Sparkplug: the broker granted the subscription to {DCMD!r} again",
    ] or granted == [  # the two connections in either order
        f"Sparkplug: the broker granted the subscription to {DCMD!r} again",
        f"MQTT: the broker granted the subscription to {TOPICS.command_filter!r} again",
    ], granted


async def test_a_subscribe_never_answered_ends_the_set_up_within_the_keepalive(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    """The bridge subscribes before it says online: a SUBACK that never came hung it there
    for ever, silent, with nothing published and /healthz none the wiser."""
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.mqtt")
    async with (
        misbehaving_broker(suback=False) as broker,
        running_gateway(toml(sim_line.url, broker, keepalive_s=1)) as gateway,
    ):
        mqtt = bridge(gateway)
        await broker.until(lambda: broker.connections and broker.connections[0].swallowed,
                           "the first SUBSCRIBE swallowed")  # fmt: skip
        first = broker.connections[0]
        await broker.until(lambda: first.closed_at is not None, "the connection ended")
        broker.suback = True  # the next connection is served well
        await wait_for(lambda: mqtt.connected, "connected", timeout=10)
        async with asyncio.timeout(10):
            samples = await scrape(metrics_port(gateway))
        stats = mqtt.stats
    asked = first.swallowed[0][1]
    assert first.swallowed == [(TOPICS.command_filter, asked)]  # the first of its two
    assert first.closed_at is not None
    stalled_s = first.closed_at - asked
    assert 0.9 <= stalled_s <= 2.25, stalled_s  # keepalive_s to 1.5 keepalive_s, and slack
    assert any(t > asked for t in first.pings)  # alive by its pings meanwhile
    assert not first.disconnected  # a real broker publishes the will ("offline")
    assert not first.publishes  # it never got as far as "online"
    # Never up, so not one of the losses; counted as what it was.
    assert (stats.suback_timeouts, stats.losses, stats.connects) == (1, 0, 1)
    assert value(samples, "sj300_mqtt_suback_timeouts_total") == 1
    assert value(samples, "sj300_mqtt_puback_timeouts_total") == 0
    (warning,) = warnings(caplog, "sj300_async.gateway.mqtt")
    assert warning.startswith(f"MQTT: cannot connect to {broker.url} (no SUBACK for 1."), warning
    assert warning.endswith(
        f"(keepalive_s 1): SUBSCRIBE packet 1 ({TOPICS.command_filter}) of client sj300-gw1, "
        "the oldest of 1 waiting); retrying"
    ), warning
    second = broker.connections[1]
    filters = [f for f, _, _ in second.subscriptions]
    assert filters[:2] == [TOPICS.command_filter, "homeassistant/status"]
    # Then the sweep's (mqtt/_sweep.py), on the same connection: this gateway's own topics.
    assert all(f.startswith(("sj300/gw1/", "homeassistant/+/sj300_gw1")) for f in filters[2:])
    assert (TOPICS.availability, b"online", 1) in second.publishes


async def test_a_clean_stop_lets_the_batch_on_its_way_be_acknowledged_and_counts_it_delivered(
    sim_line: SimLine,
) -> None:
    # A broker slow to acknowledge: the stop comes while a batch of states waits for
    # its PUBACKs. Cancelled there, the bridge counted as lost states the broker had
    # (the flaky count of test_a_state_message_per_drive_per_poll, one run in ~50).
    async with misbehaving_broker() as broker:
        broker.puback_delay_s = 0.4
        async with running_gateway(toml(sim_line.url, broker)) as gateway:
            mqtt = bridge(gateway)
            await wait_for(lambda: mqtt.connected and mqtt.stats.states.total() >= 4, "states")
            first = broker.connections[0]
            sent = len(first.publishes)
            await broker.until(lambda: len(first.publishes) > sent, "a batch on its way")
            stats = mqtt.stats
        # (the gateway stopped: the bridge's close returned)
    states = [p for p in first.publishes if p[0].endswith("/state")]
    assert stats.lost == 0
    assert len(states) == stats.states.total()  # every state the broker has, counted
    assert first.disconnected  # clean: the will is dropped
    assert first.publishes[-1] == (TOPICS.availability, b"offline", 1)
