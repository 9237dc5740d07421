"""A trip record as an OPC UA event (issue 45), received by an asyncua client subscribed
to the Server object's events, as a SCADA alarm list subscribes."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from asyncua import ua
from waiting import wait_for

from sj300_async.gateway.opcua._trip_events import EVENT_TYPE, SEVERITY

from .conftest import NAMESPACE, connected, opcua_gateway, opcua_toml, polled

#: A record a second after the trip (the recorder's after_s), of a short window.
RECORDER = "\n[recorder]\nbefore_s = 1\nafter_s = 0.5\n"


class Events:
    """asyncua's subscription handler: every event notification, kept."""

    def __init__(self) -> None:
        self.received: list[Any] = []

    def event_notification(self, event: Any) -> None:
        self.received.append(event)


async def test_a_trip_record_is_an_event_of_the_server_object(tmp_path: Path) -> None:
    text = opcua_toml(tmp_path) + RECORDER
    async with opcua_gateway(text) as (gateway, server), connected(server.url) as client:
        await polled(gateway)
        namespace = await client.get_namespace_index(NAMESPACE)
        event_type = await client.nodes.base_event_type.get_child(f"{namespace}:{EVENT_TYPE}")
        events = Events()
        subscription = await client.create_subscription(50, events)
        await subscription.subscribe_events(client.nodes.server, event_type)
        simulator = gateway.lines[0].bus.simulator
        assert simulator.drives[3].trip(7, now=asyncio.get_running_loop().time())
        await wait_for(lambda: events.received, "the trip's event", timeout=10)
        assert gateway.trip_records is not None
        summary = gateway.trip_records.summaries()[0]
        drive = await client.nodes.objects.get_child(
            [f"{namespace}:Lines", f"{namespace}:hall", f"{namespace}:Drive3"]
        )
    (event,) = events.received
    assert event.SourceNode == drive.nodeid
    assert event.SourceName == "hall/3"
    assert event.Severity == SEVERITY
    assert (event.TripCode, event.RecordId) == ("E07", summary.id)
    assert summary.meaning
    assert event.Message == ua.LocalizedText(f"hall/3 tripped: {summary.meaning} (E07)")
    assert abs(event.Time.timestamp() - summary.time) < 0.002
