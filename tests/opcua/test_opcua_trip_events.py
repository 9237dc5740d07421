"""A trip record as an OPC UA event (issue 45), received by an asyncua client subscribed
to the Server object's events, as a SCADA alarm list subscribes."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from asyncua import ua
from host_pauses import LoopLag
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


def _where(elements: int) -> ua.ContentFilter:
    """A where clause of *elements* elements: Or chained down to one comparison."""
    clause = ua.ContentFilter()
    for index in range(elements - 1):
        element = ua.ContentFilterElement(FilterOperator=ua.FilterOperator.Or)
        element.FilterOperands = [ua.ElementOperand(Index=index + 1)] * 2
        clause.Elements.append(element)
    severity = ua.SimpleAttributeOperand(
        TypeDefinitionId=ua.NodeId(ua.ObjectIds.BaseEventType),
        BrowsePath=[ua.QualifiedName("Severity", 0)],
        AttributeId=ua.AttributeIds.Value,
    )
    last = ua.ContentFilterElement(FilterOperator=ua.FilterOperator.Equals)
    last.FilterOperands = [
        severity,
        ua.LiteralOperand(Value=ua.Variant(800, ua.VariantType.UInt16)),
    ]
    clause.Elements.append(last)
    return clause


def _names(results: list[Any]) -> list[str]:
    """asyncua's answers to CreateMonitoredItems: an item's handle (made) or its status."""
    return [r.name if isinstance(r, ua.StatusCode) else "Good" for r in results]


def _event_item(client: Any, handle: int, event_filter: ua.EventFilter) -> Any:
    parameters = ua.MonitoringParameters(ClientHandle=handle, QueueSize=1, Filter=event_filter)
    return ua.MonitoredItemCreateRequest(
        ItemToMonitor=ua.ReadValueId(
            NodeId=client.nodes.server.nodeid, AttributeId=ua.AttributeIds.EventNotifier
        ),
        MonitoringMode=ua.MonitoringMode.Reporting,
        RequestedParameters=parameters,
    )


async def test_an_anonymous_session_s_event_items_are_bounded(tmp_path: Path) -> None:
    """asyncua evaluates each event item's where clause at each event, on the loop: a
    filter past MAX_WHERE_ELEMENTS is refused, and a session holds at most
    EVENT_ITEMS_PER_SESSION event items; trips go on being announced, the loop at pace."""
    from asyncua.common.events import get_filter_from_event_type

    from sj300_async.gateway.opcua._subscriptions import (
        EVENT_ITEMS_PER_SESSION,
        MAX_WHERE_ELEMENTS,
    )

    text = opcua_toml(tmp_path) + RECORDER
    async with opcua_gateway(text) as (gateway, server), connected(server.url) as client:
        await polled(gateway)
        events = Events()
        subscription = await client.create_subscription(100, events)
        base = await get_filter_from_event_type([client.nodes.base_event_type])
        big = ua.EventFilter(SelectClauses=base.SelectClauses, WhereClause=_where(900))
        fits = ua.EventFilter(
            SelectClauses=base.SelectClauses, WhereClause=_where(MAX_WHERE_ELEMENTS)
        )
        refused = await subscription.create_monitored_items(
            [_event_item(client, 1, big), _event_item(client, 2, fits)]
        )
        assert _names(refused) == ["BadEventFilterInvalid", "Good"]
        many = await subscription.create_monitored_items(
            [_event_item(client, 10 + i, fits) for i in range(2 * EVENT_ITEMS_PER_SESSION)]
        )
        statuses = _names(many)
        assert statuses.count("Good") == EVENT_ITEMS_PER_SESSION - 1  # one made above
        assert set(statuses[EVENT_ITEMS_PER_SESSION - 1 :]) == {"BadTooManyMonitoredItems"}
        # The loop's own work, not the clock's lateness (host_pauses.LoopLag): on the
        # clock, a suite's other worker took this process's core for 0.24 s in a clean run.
        with LoopLag() as probe:
            simulator = gateway.lines[0].bus.simulator
            for node in (1, 2, 3, 4):
                assert simulator.drives[node].trip(7, now=asyncio.get_running_loop().time())
            store = gateway.trip_records
            assert store is not None
            await wait_for(lambda: len(store) == 4, "four records", timeout=10)
            await wait_for(lambda: events.received, "their events", timeout=10)
        assert probe.close() < 0.1, probe.describe()
