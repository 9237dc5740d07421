"""The metric families of the gateway's lines and drives (prometheus-client's types).

Imported at the first scrape (:func:`~._metrics.gateway_metrics`); the
decisions behind the names and labels are :mod:`._metrics`'.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Final

from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)

from ..bus import BusStats
from ._metrics import DriveView, LineView, busy_seconds, cumulative_buckets

__all__ = ["drive_families", "line_families"]


#: Per-line counters read straight off the bus's transaction totals: (name, HELP, attribute).
_TRANSACTION_COUNTERS: Final = (
    ("sj300_line_requests", "Requests written to the line, each attempt once.", "requests"),
    ("sj300_line_replies", "Valid answers received, positive or NAK.", "replies"),
    ("sj300_line_retries", "Attempts repeated after a transmission error or time-out.", "retries"),
    ("sj300_line_timeouts", "Attempts that ended without an answer.", "timeouts"),
    ("sj300_line_broadcasts", "Broadcasts written (no answer expected).", "broadcasts"),
    (
        "sj300_line_protocol_errors",
        "Attempts that ended with a corrupted answer.",
        "protocol_errors",
    ),
    (
        "sj300_line_transport_errors",
        "Attempts failed because the link was down or dropped.",
        "transport_errors",
    ),
)

#: Per-line counters read off the bus's line-level stats: (name, HELP, attribute).
_LINE_COUNTERS: Final = (
    (
        "sj300_line_bad_frames",
        "Complete frames rejected by the parser (bad check, bad characters).",
        "bad_frames",
    ),
    ("sj300_line_discarded_bytes", "Bytes thrown away by the reply parser.", "discarded_bytes"),
    (
        "sj300_line_resyncs",
        "Sync requests sent to a node after it missed an answer (also counted as requests).",
        "resyncs",
    ),
    (
        "sj300_line_reconnects",
        "Times the link was lost, each followed by reconnection attempts.",
        "disconnects",
    ),
)

#: The ``kind`` label of sj300_line_discarded_frames_total, and the BusStats attribute it reads.
_DISCARDED_KINDS: Final = (
    ("stray", "stray_frames"),
    ("unsolicited", "unsolicited_frames"),
    ("early", "early_frames"),
)


def line_families(lines: list[LineView]) -> Iterator[Metric]:
    """The line families: link state, transactions, NAKs, discarded frames, bytes, latency."""
    yield _line_up(lines)
    for name, documentation, attribute in _TRANSACTION_COUNTERS:
        family = CounterMetricFamily(name, documentation, labels=["line"])
        for line in lines:
            family.add_metric([line.name], getattr(line.bus.stats.transactions, attribute))
        yield family
    for name, documentation, attribute in _LINE_COUNTERS:
        family = CounterMetricFamily(name, documentation, labels=["line"])
        for line in lines:
            family.add_metric([line.name], getattr(line.bus.stats, attribute))
        yield family
    yield _naks(lines)
    yield _discarded_frames(lines)
    yield _bytes(lines)
    yield _busy(lines)
    yield _latency(lines)


def _line_up(lines: list[LineView]) -> Metric:
    family = GaugeMetricFamily(
        "sj300_line_up", "1 if the line's link is connected now, else 0.", labels=["line"]
    )
    for line in lines:
        family.add_metric([line.name], 1.0 if line.bus.connected else 0.0)
    return family


def _naks(lines: list[LineView]) -> Metric:
    family = CounterMetricFamily(
        "sj300_line_naks",
        "Negative replies (NAK) by the drive's error code, in decimal.",
        labels=["line", "code"],
    )
    for line in lines:
        # Sorted so that a scrape's order does not depend on which NAK came first.
        for code, count in sorted(line.bus.stats.transactions.naks.items()):
            family.add_metric([line.name, str(int(code))], count)
    return family


def _discarded_frames(lines: list[LineView]) -> Metric:
    family = CounterMetricFamily(
        "sj300_line_discarded_frames",
        "Valid frames thrown away: stray (during a transaction, not its answer), "
        "unsolicited (no transaction waiting), early (sooner than the line allows).",
        labels=["line", "kind"],
    )
    for line in lines:
        for kind, attribute in _DISCARDED_KINDS:
            family.add_metric([line.name, kind], getattr(line.bus.stats, attribute))
    return family


def _bytes(lines: list[LineView]) -> Metric:
    family = CounterMetricFamily(
        "sj300_line_bytes",
        "Bytes written (tx, local echo included) and received (rx) on the line.",
        labels=["line", "direction"],
    )
    for line in lines:
        stats: BusStats = line.bus.stats
        family.add_metric([line.name, "tx"], stats.bytes_written)
        family.add_metric([line.name, "rx"], stats.bytes_received)
    return family


def _busy(lines: list[LineView]) -> Metric:
    family = CounterMetricFamily(
        "sj300_line_busy_seconds",
        "Wire time of the bytes written and received at the line's speed (a local echo "
        "once; 0 on an instant line). Utilisation: rate(sj300_line_busy_seconds_total[1m]).",
        labels=["line"],
    )
    for line in lines:
        family.add_metric([line.name], busy_seconds(line.bus))
    return family


def _latency(lines: list[LineView]) -> Metric:
    family = HistogramMetricFamily(
        "sj300_line_latency_seconds",
        "Round-trip time of the answered requests, from the write to the answer's arrival.",
        labels=["line"],
    )
    for line in lines:
        totals = line.bus.stats.transactions
        family.add_metric(
            [line.name], cumulative_buckets(totals.latency_counts), totals.latency_sum_s
        )
    return family


# -- drives --------------------------------------------------------------------------------


def drive_families(drives: list[DriveView]) -> Iterator[Metric]:
    """The drive families: online, sample age, output frequency and current."""
    labels = ["line", "node"]
    online = GaugeMetricFamily(
        "sj300_drive_online", "1 if the drive answers its polls, else 0.", labels=labels
    )
    age = GaugeMetricFamily(
        "sj300_drive_sample_age_seconds",
        "Seconds since the drive's last good sample (absent before the first).",
        labels=labels,
    )
    frequency = GaugeMetricFamily(
        "sj300_drive_output_frequency_hertz",
        "The drive's output frequency in its last good sample.",
        labels=labels,
    )
    current = GaugeMetricFamily(
        "sj300_drive_output_current_amperes",
        "The drive's output current in its last good sample.",
        labels=labels,
    )
    for drive in drives:
        key = [drive.line, str(drive.node)]
        online.add_metric(key, 1.0 if drive.online else 0.0)
        # Unknown is no sample, not a made-up 0 that a dashboard would draw.
        _add_known(age, key, drive.sample_age_s)
        _add_known(frequency, key, drive.output_frequency_hz)
        _add_known(current, key, drive.output_current_a)
    yield from (online, age, frequency, current)


def _add_known(family: GaugeMetricFamily, labels: list[str], value: float | None) -> None:
    if value is not None:
        family.add_metric(labels, value)
