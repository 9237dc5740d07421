"""The primary host: nothing is born before its STATE says online; its going offline is a death.

The STATE messages are published by mosquitto_pub as a host application
would (retained, JSON); the edge node's messages are read by the
independent subscriber (host.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator

from mqtt_broker import Broker
from waiting import wait_for

from sj300_async.gateway import Gateway
from sj300_async.gateway.sparkplug import EdgeNode

from .conftest import SimLine, drive, edge, polled, running_gateway, spb_toml
from .host import Codec, host
from .test_sparkplug_commands import metric
from .test_sparkplug_lifecycle import names, seqs_follow

STATE = "spBv1.0/STATE/scada"
WITH_HOST = 'primary_host_id = "scada"'


async def say(broker: Broker, online: bool, timestamp: int) -> None:
    """The host's STATE, as Sparkplug 3.0 has a host publish it (retained, QoS 1)."""
    body = json.dumps({"online": online, "timestamp": timestamp})
    await broker.publish(STATE, body, retain=True)


@contextlib.asynccontextmanager
async def born_with_host(
    sim_line: SimLine, broker: Broker
) -> AsyncIterator[tuple[Gateway, EdgeNode]]:
    """A gateway whose edge node waits for host ``scada``, born: the host said online."""
    await say(broker, True, 1000)
    async with running_gateway(spb_toml(sim_line.url, broker, mqtt_extra=WITH_HOST)) as gateway:
        node = edge(gateway)
        await wait_for(lambda: node.born, "born")
        yield gateway, node


async def malformed_reach(node: EdgeNode, total: int, what: str) -> None:
    await wait_for(lambda: node.stats.bad_input["malformed"] == total, what)


async def test_the_edge_node_is_born_only_while_its_primary_host_is_online(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    loop = asyncio.get_running_loop()
    text = spb_toml(sim_line.url, broker, mqtt_extra=WITH_HOST)
    await say(broker, False, 1000)
    async with host(broker, tahu) as h:
        async with running_gateway(text) as gateway:
            node = edge(gateway)
            node.host_rebirth_s = 2.0  # (10 s in service) after the host's death
            await wait_for(lambda: node.host_online is False, "the host's STATE read")
            await polled(gateway)
            assert h.of("NBIRTH") == []
            assert node.bdseq == 0
            await say(broker, True, 2000)
            await h.until(lambda m: m.kind == "DBIRTH", "the births", count=4)
            first_birth = node._nbirth_at
            await h.command("DCMD", [metric(h, "hall-1", "Control/Lease", "Boolean", True)],
                            "hall-1")  # fmt: skip
            one = drive(gateway, 1)
            await wait_for(lambda: one.lease.held_by("sparkplug", loop.time()), "the lease")
            # A STATE older than the last one seen changes nothing.
            await say(broker, False, 1500)
            await wait_for(lambda: node.stats.bad_input["stale_state"] == 1, "the stale STATE")
            assert node.born
            assert node.host_online
            # The host goes offline: NDEATH, the connection-scoped lease lapses, and the
            # edge node reconnects (the next bdSeq) to wait for the host again.
            await say(broker, False, 3000)
            await h.until(lambda m: m.kind == "NDEATH", "the death")
            await wait_for(lambda: not one.lease.held_by("sparkplug", loop.time()), "the lapse")
            await wait_for(lambda: node.stats.connects == 2 and node.host_online is False,
                           "connected again, the host still offline")  # fmt: skip
            assert node.bdseq == 1
            assert len(h.of("NBIRTH")) == 1
            await say(broker, True, 4000)
            await h.until(lambda m: m.kind == "DBIRTH", "the births again", count=8)
            # A flapping STATE is a death and a rebirth at most once per window.
            assert node._nbirth_at - first_birth >= node.host_rebirth_s
            assert node.stats.host_offline == 1
        await h.until(lambda m: m.kind == "NDEATH", "the clean stop's NDEATH", count=2)
    first, second = h.of("NBIRTH")
    (death, _) = h.of("NDEATH")  # the host's offline, then the clean stop
    assert names(first)["bdSeq"]["value"] == names(death)["bdSeq"]["value"] == 0
    assert names(second)["bdSeq"]["value"] == 1
    assert h.messages.index(death) < h.messages.index(second)
    seqs_follow(h.messages)


async def test_a_state_that_is_no_state_is_counted_and_ignored(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    text = spb_toml(sim_line.url, broker, mqtt_extra=WITH_HOST)
    async with host(broker, tahu) as h, running_gateway(text) as gateway:
        node = edge(gateway)
        await wait_for(lambda: node.stats.connects == 1, "subscribed (then connected)")
        bad = ("online", '{"online": "yes", "timestamp": 5}', '{"online": true}',
               '{"online": true, "timestamp": true}', "\xff")  # fmt: skip
        for number, text in enumerate(bad, start=1):
            await broker.publish(STATE, text)
            await malformed_reach(node, number, f"{text!r} counted")
        assert node.host_online is None
        assert h.of("NBIRTH") == []
        await say(broker, True, 1)
        await h.until(lambda m: m.kind == "DBIRTH", "the births", count=4)


async def test_after_a_broker_restart_the_host_must_say_online_again(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    # The restarted broker is empty (no persistence): no STATE says the host is online,
    # so the edge node is not born on it, and takes no command, until one does.
    async with born_with_host(sim_line, broker) as (gateway, node):
        await broker.stop()
        await broker.start()  # the same port
        async with host(broker, tahu) as h:
            await wait_for(lambda: node.stats.connects == 2, "connected to the new broker")
            assert not node.born
            assert node.host_online is None
            await h.command("DCMD", [{"name": "Control/Lease", "type": "Boolean", "value": True},
                                     {"name": "Direction", "type": "String", "value": "forward"}],
                            "hall-1")  # fmt: skip
            await wait_for(lambda: node.stats.bad_input["not_born"] == 2, "both refused")
            assert node.stats.bad_input["offline"] == 0  # the drive is there: not what refused
            assert drive(gateway, 1).lease.holder != "sparkplug"
            assert h.of("NBIRTH") == []
            await say(broker, True, 2000)
            await h.until(lambda m: m.kind == "DBIRTH", "the births", count=4)
        assert names(h.of("NBIRTH")[0])["bdSeq"]["value"] == 1


async def test_a_state_too_deep_or_too_long_is_counted_and_the_session_goes_on(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    async with born_with_host(sim_line, broker) as (_, node):
        await broker.publish(STATE, "[" * 1000)  # json.loads recurses past its limit
        await malformed_reach(node, 1, "the deep STATE counted")
        await broker.publish(STATE, '{"online": false, "timestamp": 5000, "pad": "' + "x" * 2000)
        await wait_for(lambda: node.stats.bad_input["oversized"] == 1, "the long one counted")
        assert node.born
        assert (node.stats.connects, node.stats.losses) == (1, 0)
