"""A trip record announced by the doors (issue 45): MQTT's ``…/trip`` message and Home
Assistant's event entity for it, read by mosquitto_sub from a real mosquitto."""

from __future__ import annotations

import asyncio
import textwrap

from ha_discovery_schema import check
from mqtt_broker import Broker
from waiting import wait_for

from sj300_async.gateway import Gateway
from sj300_async.gateway.mqtt import Topics

from .conftest import running_gateway
from .test_gateway_mqtt import Message, broker, subscriber

__all__ = ["broker"]  # the fixture: a mosquitto of this test's own

TRIP_TOPIC = Topics("gw1").trip("hall", 1)
TRIPS_CONFIG = "homeassistant/event/sj300_gw1_hall_1/trips/config"


def _text(broker: Broker) -> str:
    return textwrap.dedent(
        f"""
        [gateway]
        id = "gw1"
        [mqtt]
        url = "{broker.url}"
        [recorder]
        before_s = 1
        after_s = 0.5
        [[lines]]
        name = "hall"
        url = "sim://?nodes=1-2"
        nodes = "1-2"
        interval_s = 0.05
        trips_interval_s = 60
        """
    )


def _trip_message(m: Message) -> bool:
    return m.topic == TRIP_TOPIC


async def test_a_record_is_announced_on_the_trip_topic_with_its_event_entity(
    broker: Broker,
) -> None:
    async with subscriber(broker) as sub, running_gateway(_text(broker)) as gateway:
        config = (await sub.until(lambda m: m.topic == TRIPS_CONFIG, "the trips' entity"))[0]
        await wait_for(lambda: gateway.drive("hall", 1) is not None and _polled(gateway), "a poll")
        simulator = gateway.lines[0].bus.simulator
        assert simulator.drives[1].trip(7, now=asyncio.get_running_loop().time())
        message = (await sub.until(_trip_message, "the trip record's message", timeout=10))[0]
        assert gateway.trip_records is not None
        summary = gateway.trip_records.summaries()[0]
    assert not message.retained
    assert message.json() == {
        "event_type": "trip",
        "code": "E07",
        "meaning": summary.meaning,
        "record": summary.id,
        "seen_by": "poll",
        "time": summary.time,
    }
    assert summary.meaning
    body = config.json()
    assert (body["state_topic"], body["event_types"]) == (TRIP_TOPIC, ["trip"])
    assert check("event", body) == []
    assert len(sub.where(_trip_message)) == 1  # one record, one message


def _polled(gateway: Gateway) -> bool:
    return all(d.readings.last_ok is not None for d in gateway.drives)
