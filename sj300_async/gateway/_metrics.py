"""Prometheus metrics of the gateway, built at scrape time from what the gateway already counts.

Decisions:

- Nothing is updated per transaction for Prometheus. The bus already keeps
  its counters (:class:`~sj300_async.bus.BusStats`), the gateway's cache
  knows each drive's state; :class:`GatewayCollector` reads both when
  ``/metrics`` is scraped and builds the metric families then. The one
  counter that exists only for the exporter, :class:`ClientCounters`, is a
  pair of plain dicts: a dict increment on the Modbus server's hot path,
  no prometheus_client object and no lock.
- The scrape runs on the event loop (see :mod:`._http`), like everything
  that updates those counters, so one scrape sees one consistent state
  and the live objects are never read from another thread. Its cost is
  O(lines + drives + clients).
- The collector sees the gateway through small read-only views
  (:class:`LineView`, :class:`DriveView`, :class:`MetricsSource`): it
  depends on neither the poller nor the Modbus server, and a test can feed
  it real buses without a gateway around them.
- It is registered on a :class:`~prometheus_client.CollectorRegistry` of
  its own (:func:`make_registry`), never the global default one: two
  gateways in one process (tests) do not collide, and no process or
  platform collector sneaks in.
- Names follow the Prometheus exporter guidelines: base units (seconds,
  bytes, hertz, amperes), ``_total`` on counters, small label sets
  (``line``, ``node``, ``code``, ``client``, ``kind``, ``direction``).
- Error codes (a drive's NAK code, a Modbus exception code) are labelled
  in decimal, ``str(int(code))``, for both protocols: one rule, whatever
  notation each manual uses.
- A Modbus client is labelled by its IP address only (the port changes on
  every connection). Past :data:`MAX_CLIENTS` distinct addresses the rest
  are counted as ``client="other"``: a scan of the port must not turn into
  an unbounded number of series.
- Line utilisation is not a gauge sampled at some instant: the exporter
  gives ``sj300_line_busy_seconds_total``, the wire time of every byte
  written and received, and ``rate()`` of it over a window is the
  fraction of that window the line was busy.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, Protocol

from prometheus_client import CollectorRegistry
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)

from ..bus import Bus
from ..bus._stats import LATENCY_BUCKETS_S, BusStats

if TYPE_CHECKING:  # the bridge imports aiomqtt: not needed to read its counters
    from ._mqtt import BridgeStats

__all__ = [
    "MAX_CLIENTS",
    "OTHER_CLIENT",
    "ClientCounters",
    "DriveView",
    "GatewayCollector",
    "LineView",
    "MetricsSource",
    "busy_seconds",
    "cumulative_buckets",
    "line_problems",
    "make_registry",
]

_log = logging.getLogger("sj300_async.gateway.metrics")

#: Distinct client addresses labelled one by one; the rest share :data:`OTHER_CLIENT`.
MAX_CLIENTS: Final = 64
OTHER_CLIENT: Final = "other"


@dataclass(frozen=True, slots=True)
class LineView:
    """One line the gateway owns."""

    #: The line's name (the ``line`` label).
    name: str
    bus: Bus[Any, Any]


@dataclass(frozen=True, slots=True)
class DriveView:
    """One drive's state, as the gateway's cache knows it right now."""

    line: str
    node: int
    online: bool
    #: Seconds since the last good sample, None if there never was one.
    sample_age_s: float | None
    output_frequency_hz: float | None
    output_current_a: float | None


class MetricsSource(Protocol):
    """What the collector reads at each scrape."""

    def lines(self) -> Iterable[LineView]: ...

    def drives(self) -> Iterable[DriveView]: ...


class ClientCounters:
    """Requests and exception replies per Modbus client, for the exporter.

    Args:
        max_clients: distinct addresses counted under their own label; the
            next ones are counted as :data:`OTHER_CLIENT` (see the module
            docstring).
    """

    __slots__ = ("_known", "_max_clients", "exceptions", "requests")

    def __init__(self, max_clients: int = MAX_CLIENTS) -> None:
        self._max_clients = max_clients
        #: The addresses labelled one by one so far.
        self._known: set[str] = set()
        #: Requests by client address.
        self.requests: dict[str, int] = {}
        #: Exception replies by (client address, Modbus exception code).
        self.exceptions: dict[tuple[str, int], int] = {}

    def request(self, client: str) -> None:
        """Count one request of *client* (its IP address, without the port)."""
        client = self._label(client)
        self.requests[client] = self.requests.get(client, 0) + 1

    def exception(self, client: str, code: int) -> None:
        """Count one exception reply with *code* sent to *client*."""
        key = (self._label(client), code)
        self.exceptions[key] = self.exceptions.get(key, 0) + 1

    def _label(self, client: str) -> str:
        if client in self._known:
            return client
        if len(self._known) < self._max_clients:
            self._known.add(client)
            return client
        if OTHER_CLIENT not in self._known:
            # Once, when the cap is first reached: later newcomers are not news.
            self._known.add(OTHER_CLIENT)
            _log.warning(
                "more than %d Modbus client addresses: %s and later ones are counted as %r",
                self._max_clients,
                client,
                OTHER_CLIENT,
            )
        return OTHER_CLIENT


def cumulative_buckets(counts: Iterable[int]) -> list[tuple[str, float]]:
    """Prometheus buckets from per-bucket counts over :data:`LATENCY_BUCKETS_S`.

    The bus counts each round trip in one bucket (its ``latency_counts``,
    the last element for those slower than every bound); Prometheus wants
    each bucket to count everything at or below its bound, ending with +Inf.
    """
    bounds = [repr(float(bound)) for bound in LATENCY_BUCKETS_S] + ["+Inf"]
    counts = list(counts)
    if len(counts) != len(bounds):
        raise ValueError(f"{len(bounds)} bucket counts expected, got {len(counts)}")
    out: list[tuple[str, float]] = []
    running = 0
    for bound, count in zip(bounds, counts, strict=True):
        running += count
        out.append((bound, running))
    return out


def busy_seconds(bus: Bus[Any, Any]) -> float:
    """Wire time of every byte the line carried: (written + received - echo) x char time.

    The bytes of a local echo are counted twice by the bus (written, then
    received back) but took the line once: they are taken off. On an
    instant line (``baudrate=0``) the character time, and so this, is 0.
    """
    stats = bus.stats
    carried = stats.bytes_written + stats.bytes_received - stats.echo_bytes
    return carried * bus.line.char_time_s


def line_problems(source: MetricsSource) -> list[str]:
    """The lines whose link is down, one ``"line NAME: link down"`` each (for /healthz)."""
    return [f"line {line.name}: link down" for line in source.lines() if not line.bus.connected]


class GatewayCollector:
    """A prometheus_client collector reading *source* and *clients* at each scrape."""

    def __init__(
        self,
        source: MetricsSource,
        clients: ClientCounters,
        mqtt: Callable[[], BridgeStats | None] = lambda: None,
    ) -> None:
        self._source = source
        self._clients = clients
        self._mqtt = mqtt

    def collect(self) -> Iterator[Metric]:
        """Yield every metric family, built now (see the module docstring)."""
        yield from _line_metrics(list(self._source.lines()))
        yield from _drive_metrics(list(self._source.drives()))
        yield from _client_metrics(self._clients)
        stats = self._mqtt()
        if stats is not None:
            yield from _mqtt_metrics(stats)


def make_registry(
    source: MetricsSource,
    clients: ClientCounters,
    mqtt: Callable[[], BridgeStats | None] = lambda: None,
) -> CollectorRegistry:
    """A new registry holding only the gateway's collector (not the global default one)."""
    registry = CollectorRegistry()
    registry.register(GatewayCollector(source, clients, mqtt))
    return registry


#: The MQTT bridge's counters: (name, HELP, BridgeStats attribute).
_MQTT_COUNTERS: Final = (
    ("sj300_mqtt_connects", "Connections to the broker made.", "connects"),
    ("sj300_mqtt_losses", "Connections to the broker lost.", "losses"),
    ("sj300_mqtt_published", "Messages the broker took.", "published"),
    ("sj300_mqtt_lost", "Messages being sent when the connection broke.", "lost"),
    ("sj300_mqtt_errors_dropped", "Error replies dropped (too many waiting).", "errors_dropped"),
)
#: Command messages by what became of them: (label, BridgeStats attribute).
_MQTT_COMMANDS: Final = (
    ("received", "commands"),
    ("refused", "refused"),
    ("discarded", "discarded"),
    ("ignored", "ignored"),
)


def _mqtt_metrics(stats: BridgeStats) -> Iterator[Metric]:
    for name, help_text, attribute in _MQTT_COUNTERS:
        family = CounterMetricFamily(name, help_text)
        family.add_metric([], getattr(stats, attribute))
        yield family
    commands = CounterMetricFamily(
        "sj300_mqtt_commands",
        "Command messages: received, refused (answered on the error topic), discarded "
        "(the connection was lost first), ignored (no drive of this gateway).",
        labels=["result"],
    )
    for label, attribute in _MQTT_COMMANDS:
        commands.add_metric([label], getattr(stats, attribute))
    yield commands
    replaced = CounterMetricFamily(
        "sj300_mqtt_states_replaced",
        "State messages replaced by a newer one before the broker took them (coalesced).",
    )
    replaced.add_metric([], sum(stats.replaced.values()))
    yield replaced


# -- lines ---------------------------------------------------------------------------------

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


def _line_metrics(lines: list[LineView]) -> Iterator[Metric]:
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


def _drive_metrics(drives: list[DriveView]) -> Iterator[Metric]:
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


# -- Modbus clients ------------------------------------------------------------------------


def _client_metrics(clients: ClientCounters) -> Iterator[Metric]:
    requests = CounterMetricFamily(
        "sj300_modbus_requests",
        "Modbus TCP requests received, by client IP address.",
        labels=["client"],
    )
    for client, count in sorted(clients.requests.items()):
        requests.add_metric([client], count)
    yield requests
    exceptions = CounterMetricFamily(
        "sj300_modbus_exceptions",
        "Modbus exception replies sent, by client IP address and exception code (decimal).",
        labels=["client", "code"],
    )
    for (client, code), count in sorted(clients.exceptions.items()):
        exceptions.add_metric([client, str(code)], count)
    yield exceptions
