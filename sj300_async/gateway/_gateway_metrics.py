"""The gateway's own metric families: its lines and drives, publishing, reloads, lapses,
the loop, the log flood limit, then every northbound's and the trip recorder's.

Functions of the running :class:`~._gateway.Gateway` (whose ``metrics`` calls
:func:`all_metrics`), kept apart so that the gateway's module holds its running.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import TYPE_CHECKING

from ._metrics import drive_view, gateway_metrics

if TYPE_CHECKING:
    from prometheus_client.core import Metric

    from ._gateway import Gateway
    from .recorder._recorder import TripRecorder

__all__ = ["all_metrics"]


def all_metrics(gateway: Gateway) -> Iterator[Metric]:
    """The lines' and drives' families, then each northbound's."""
    now = asyncio.get_running_loop().time()
    stale = gateway.config.stale_after_s
    yield from gateway_metrics(
        gateway._line_views(), (drive_view(d.snapshot, now, stale) for d in gateway._drives)
    )
    from prometheus_client.core import CounterMetricFamily

    errors = CounterMetricFamily(
        "sj300_gateway_publish_errors",
        "Snapshots a northbound failed to take (its publish raised; logged).",
        labels=["northbound"],
    )
    for section in gateway.northbounds:
        errors.add_metric([section], gateway.publish_errors.get(section, 0))
    read_errors = CounterMetricFamily(
        "sj300_gateway_read_errors",
        "Reads beside the poll (trip history, set frequency) that failed; tried again.",
        labels=["line", "read"],
    )
    for line in gateway.lines:
        for what in ("trips", "setpoint"):
            count = gateway.read_errors.get((line.config.name, what), 0)
            read_errors.add_metric([line.config.name, what], count)
    yield errors
    yield read_errors
    yield from _reload_metrics(gateway)
    yield from _lapse_metrics(gateway)
    yield from gateway.loop_monitor.metrics()
    if gateway._flood is not None:
        yield from gateway._flood.metrics()
    if gateway.recorder is not None:
        yield from _recorder_metrics(gateway.recorder)
    for northbound in gateway.northbounds.values():
        yield from northbound.metrics()


def _reload_metrics(gateway: Gateway) -> Iterator[Metric]:
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    reloads = CounterMetricFamily(
        "sj300_gateway_config_reloads",
        "Reloads of the configuration (SIGHUP), by result: applied, or refused (the "
        "file did not read or check; the gateway runs on the configuration it had).",
        labels=["result"],
    )
    for result in ("applied", "refused"):
        reloads.add_metric([result], gateway.reloads[result])
    yield reloads
    yield GaugeMetricFamily(
        "sj300_gateway_config_last_reload_successful",
        "0 after a reload was refused, until one is applied; 1 otherwise.",
        int(gateway.last_reload_ok),
    )


def _lapse_metrics(gateway: Gateway) -> Iterator[Metric]:
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    lapses = CounterMetricFamily(
        "sj300_gateway_lapses",
        "Control leases that lapsed (their action ran).",
        labels=["line"],
    )
    failed = CounterMetricFamily(
        "sj300_gateway_lapse_failed_tries",
        "Tries of a lapse's stop that failed (link down, NAK, time-out) and were retried.",
        labels=["line"],
    )
    pending = GaugeMetricFamily(
        "sj300_gateway_lapse_pending",
        "1 while a lapsed lease's stop is not confirmed (being retried).",
        labels=["line", "node"],
    )
    for line in gateway.lines:
        name = line.config.name
        lapses.add_metric([name], line.controller.lapse.lapses)
        failed.add_metric([name], line.controller.lapse.failed_tries)
        for node, drive in line.drives.items():
            pending.add_metric([name, str(node)], int(drive.lapse_pending))
    yield from (lapses, failed, pending)


def _recorder_metrics(recorder: TripRecorder) -> Iterator[Metric]:
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    trips = CounterMetricFamily(
        "sj300_gateway_trips_seen",
        "New trips the trip recorder saw, by what saw them: poll, trip history.",
        labels=["seen_by"],
    )
    for seen_by in ("poll", "trip history"):
        trips.add_metric([seen_by], recorder.counts[seen_by])
    records = CounterMetricFamily(
        "sj300_gateway_trip_records",
        "Trip records by outcome: written, pruned (the oldest, past max_records or "
        "max_bytes), failed (not written: logged), dropped (too many pending), damaged "
        "(files skipped at start).",
        labels=["outcome"],
    )
    store = recorder.store
    for outcome in ("written", "pruned", "failed", "damaged"):
        records.add_metric([outcome], store.counts[outcome])
    records.add_metric(["dropped"], recorder.counts["dropped"])
    yield trips
    yield records
    yield GaugeMetricFamily("sj300_gateway_trip_records_kept", "Trip records kept now.", len(store))
    yield GaugeMetricFamily(
        "sj300_gateway_trip_records_bytes",
        "Bytes the trip records kept now take (JSON and pcapng).",
        store.size,
    )
    yield GaugeMetricFamily(
        "sj300_gateway_trip_records_pending",
        "Trips whose record waits for its after_s or its write.",
        recorder.pending,
    )
