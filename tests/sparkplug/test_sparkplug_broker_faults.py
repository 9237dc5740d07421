"""The edge node's subscriptions refused by the broker (an ACL): said, counted, on /healthz.

Against the tests' misbehaving broker (tests/mqtt_misbehaving.py), which
answers SUBACK 0x80 for the filters it is told to, as EMQX and HiveMQ do on
an ACL deny. Refused, the edge node would wait for a STATE that never comes
and never hear a command; before, nothing said so.
"""

from __future__ import annotations

import logging

import pytest
from mqtt_misbehaving import misbehaving_broker
from waiting import wait_for

from .conftest import SimLine, edge, running_gateway, spb_toml

STATE = "spBv1.0/STATE/scada"
NCMD = "spBv1.0/plant/NCMD/gw1"
DCMD = "spBv1.0/plant/DCMD/gw1/+"


async def test_refused_state_ncmd_and_dcmd_are_each_said_counted_and_a_problem(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.sparkplug")
    async with misbehaving_broker(refuse={STATE, NCMD, DCMD}) as broker:
        text = spb_toml(sim_line.url, broker, mqtt_extra='primary_host_id = "scada"')
        async with running_gateway(text) as gateway:
            node = edge(gateway)
            await wait_for(lambda: node.stats.connects == 1, "connected")
            problems = gateway.problems()
            families = {f.name: f for f in node.metrics()}
            born = node.born
    (seen,) = broker.connections
    assert [(f, code) for f, _, code in seen.subscriptions] == [
        (STATE, 0x80),
        (NCMD, 0x80),
        (DCMD, 0x80),
    ]
    unheard = {
        STATE: "the primary host's STATE",
        NCMD: "node commands (NCMD)",
        DCMD: "device commands (DCMD)",
    }
    for topic_filter, what in unheard.items():
        line = f"the broker refused the subscription to {{}} (SUBACK 0x80): {what} not received"
        assert f"Sparkplug: {line.format(topic_filter)}" in problems
        said = [
            r
            for r in caplog.records
            if r.getMessage() == f"Sparkplug: {line.format(repr(topic_filter))}"
        ]
        assert [r.levelno for r in said] == [logging.WARNING], topic_filter
    refused = families["sj300_sparkplug_subscriptions_refused"]
    assert {s.labels["filter"]: s.value for s in refused.samples} == {
        STATE: 1,
        NCMD: 1,
        DCMD: 1,
    }
    assert not born  # the host's STATE cannot come: /healthz says why


async def test_a_subscribe_never_answered_is_counted_and_the_node_connects_again(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    """The edge node subscribes before its birth: a SUBACK that never came held it unborn."""
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.sparkplug")
    async with misbehaving_broker(suback=False) as broker:
        text = spb_toml(sim_line.url, broker, mqtt_extra="keepalive_s = 1")
        async with running_gateway(text) as gateway:
            node = edge(gateway)
            await broker.until(lambda: broker.connections and broker.connections[0].swallowed,
                               "the first SUBSCRIBE swallowed")  # fmt: skip
            first = broker.connections[0]
            await broker.until(lambda: first.closed_at is not None, "the connection ended")
            broker.suback = True
            await wait_for(lambda: node.born, "born on the next connection", timeout=10)
            families = {f.name: f for f in node.metrics()}
    assert first.closed_at is not None
    stalled_s = first.closed_at - first.swallowed[0][1]
    assert 0.9 <= stalled_s <= 2.25, stalled_s
    assert not first.disconnected  # its will, the NDEATH, is published
    assert [f for f, _ in first.swallowed] == [NCMD]
    (timeouts,) = families["sj300_sparkplug_suback_timeouts"].samples
    assert timeouts.value == 1
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(said) == 1, said
    assert said[0].startswith(f"MQTT: cannot connect to {broker.url} (no SUBACK for 1."), said
    assert f"SUBSCRIBE packet 1 ({NCMD}) of client sj300-gw1-spb" in said[0], said


async def test_a_flood_under_way_at_a_connection_does_not_hang_its_set_up(
    sim_line: SimLine,
) -> None:
    """3,000 NCMDs right after NCMD's SUBACK, ahead of DCMD's: before the receiver ran while
    the node subscribed, the client stopped reading past its 1,000 queued, DCMD's SUBACK
    never came, and the node stayed unborn for ever, silent."""
    junk = [(NCMD, b"junk")] * 3000
    async with misbehaving_broker(deliver={NCMD: junk}) as broker:
        text = spb_toml(sim_line.url, broker, mqtt_extra="keepalive_s = 1")
        async with running_gateway(text) as gateway:
            node = edge(gateway)
            await wait_for(lambda: node.born, "born", timeout=10)
            await wait_for(lambda: node.stats.commands == len(junk), "the junk read")
            stats = node.stats
    assert len(broker.connections) == 1
    assert (stats.connects, stats.suback_timeouts, stats.losses) == (1, 0, 0)
    assert stats.bad_input["malformed"] == len(junk)
