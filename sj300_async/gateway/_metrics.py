"""The gateway's own Prometheus metrics (lines, drives), built at scrape time from what it counts.

Decisions:

- Nothing is updated per transaction for Prometheus. The bus already keeps
  its counters (:class:`~sj300_async.bus.BusStats`), each drive's snapshot
  its state; :func:`gateway_metrics` reads both when ``/metrics`` is
  scraped and builds the metric families then. Each northbound adds its
  own families the same way (``Northbound.metrics``), and the HTTP
  northbound serves them all.
- The scrape runs on the event loop, like everything that updates those
  counters, so one scrape sees one consistent state and the live objects
  are never read from another thread. Its cost is O(lines + drives).
- The families are built from small read-only views (:class:`LineView`,
  :class:`DriveView`): a test can feed real buses without a gateway
  around them.
- Names follow the Prometheus exporter guidelines: base units (seconds,
  bytes, hertz, amperes), ``_total`` on counters, small label sets
  (``line``, ``node``, ``code``, ``client``, ``kind``, ``direction``).
- Error codes (a drive's NAK code, a Modbus exception code) are labelled
  in decimal, ``str(int(code))``, for both protocols: one rule, whatever
  notation each manual uses.
- Line utilisation is not a gauge sampled at some instant: the exporter
  gives ``sj300_line_busy_seconds_total``, the wire time of every byte
  written and received, and ``rate()`` of it over a window is the
  fraction of that window the line was busy.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..bus import LATENCY_BUCKETS_S, Bus
from ..profiles import DriveSnapshot, is_fresh

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = [
    "DriveView",
    "LineView",
    "busy_seconds",
    "cumulative_buckets",
    "drive_view",
    "gateway_metrics",
    "line_problems",
]


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


def drive_view(snapshot: DriveSnapshot, now: float, stale_after_s: float) -> DriveView:
    """*snapshot* as the metrics show it at loop time *now*: stale values left out."""
    fresh = is_fresh(snapshot.monitor_at, now, stale_after_s)
    return DriveView(
        line=snapshot.line,
        node=snapshot.node,
        online=snapshot.online,
        sample_age_s=snapshot.sample_age_s(now),
        output_frequency_hz=snapshot.output_frequency_hz if fresh else None,
        output_current_a=snapshot.output_current_a if fresh else None,
    )


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


def line_problems(lines: Iterable[LineView]) -> list[str]:
    """The lines whose link is down, one ``"line NAME: link down"`` each (for /healthz)."""
    return [f"line {line.name}: link down" for line in lines if not line.bus.connected]


def gateway_metrics(lines: Iterable[LineView], drives: Iterable[DriveView]) -> Iterator[Metric]:
    """Every line and drive metric family, built now (see the module docstring).

    prometheus-client (the gateway extra) is imported here, at the first
    scrape: the gateway's core and its configuration do not need it.
    """
    from ._families import drive_families, line_families

    yield from line_families(list(lines))
    yield from drive_families(list(drives))


# -- lines ---------------------------------------------------------------------------------
