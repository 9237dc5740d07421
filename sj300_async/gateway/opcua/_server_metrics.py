"""The OPC UA northbound's metric families, built when /metrics is read."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from prometheus_client.core import Metric

    from ._calls import Calls
    from ._defences import Defences
    from ._server import OpcuaServer
    from ._trip_events import TripEvents

__all__ = ["server_metrics"]


def server_metrics(
    server: OpcuaServer, calls: Calls | None, trips: TripEvents | None, defences: Defences
) -> Iterator[Metric]:
    """The OPC UA northbound's own families (its sessions, writes, pushes, trip events,
    defences)."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    sessions = GaugeMetricFamily(
        "sj300_opcua_sessions", "OPC UA sessions open (asyncua's external sessions)."
    )
    sessions.add_metric([], server.session_count)
    yield sessions
    results = CounterMetricFamily(
        "sj300_opcua_writes",
        "Method calls and variable writes, by the status code answered.",
        labels=["status"],
    )
    for status, count in sorted((calls.results if calls else {}).items()):
        results.add_metric([status], count)
    yield results
    pushed = CounterMetricFamily(
        "sj300_opcua_values_pushed", "Changed values pushed to subscriptions."
    )
    pushed.add_metric([], server.pushed)
    yield pushed
    if trips is not None:
        events = CounterMetricFamily(
            "sj300_opcua_trip_events",
            "Trip records announced as events: emitted, dropped (too many waiting), "
            "failed (asyncua raised: logged).",
            labels=["result"],
        )
        for result, count in trips.counts.items():
            events.add_metric([result], count)
        yield events
    yield from defences.metrics()
