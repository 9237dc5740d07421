"""What the Sparkplug edge node counts, and the metric families it adds to /metrics."""

from __future__ import annotations

import collections
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from ..mqttlink import SessionStats, refused_subscriptions

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["BAD_INPUTS", "SparkplugStats", "sparkplug_families"]

#: Why a received message, or one metric of it, changed nothing (the counter's labels).
BAD_INPUTS: Final = (
    "malformed",  # not a Sparkplug B payload (or a STATE that is no JSON of the form)
    "unknown_metric",  # an alias or name the device's birth did not have
    "wrong_type",  # a value of another type than the metric's, or none
    "offline",  # a command to a device that is dead (a stop is still tried)
    "not_born",  # a command while the edge node is not born (a stop is still tried)
    "retained",  # a command the broker kept: nobody sent it now
    "oversized",  # longer than the edge node reads
    "unknown_device",  # a DCMD to no device of this edge node
    "stale_state",  # a primary host STATE older than the one already seen
    "too_many",  # metrics past the most one command may carry
)


@dataclass
class SparkplugStats(SessionStats):
    """What the edge node did (nothing is dropped silently)."""

    #: Messages published, by Sparkplug message type (NBIRTH, DBIRTH, DDATA, ...).
    published: collections.Counter[str] = field(default_factory=collections.Counter)
    #: Samples handed over, and samples replaced by a newer one of the same drive
    #: before they were published (their changes go out with the newer one).
    samples: int = 0
    replaced: int = 0
    #: NCMD and DCMD messages received.
    commands: int = 0
    #: Writes the gateway carried out, and writes refused (here or by the gateway).
    writes: int = 0
    refused: int = 0
    #: Received input that changed nothing, by reason (:data:`BAD_INPUTS`).
    bad_input: collections.Counter[str] = field(default_factory=collections.Counter)
    #: Rebirths done on an NCMD's request.
    rebirths: int = 0
    #: Times the primary host went offline while the edge node was born.
    host_offline: int = 0
    #: Messages being sent when the connection broke (their session is over).
    lost: int = 0


_COUNTERS: Final = (
    ("sj300_sparkplug_connects", "Connections to the broker made.", "connects"),
    ("sj300_sparkplug_losses", "Connections to the broker lost.", "losses"),
    ("sj300_sparkplug_samples", "Drive samples handed to the edge node.", "samples"),
    (
        "sj300_sparkplug_samples_replaced",
        "Samples replaced by a newer one of the same drive before they were published.",
        "replaced",
    ),
    ("sj300_sparkplug_commands", "NCMD and DCMD messages received.", "commands"),
    ("sj300_sparkplug_rebirths", "Rebirths done on a host's request.", "rebirths"),
    ("sj300_sparkplug_host_offline", "Times the primary host went offline.", "host_offline"),
    ("sj300_sparkplug_lost", "Messages being sent when the connection broke.", "lost"),
    (
        "sj300_sparkplug_puback_timeouts",
        "Connections ended because a QoS 1 publish waited keepalive_s for its PUBACK.",
        "puback_timeouts",
    ),
    (
        "sj300_sparkplug_suback_timeouts",
        "Connections ended because a SUBSCRIBE waited keepalive_s for its SUBACK.",
        "suback_timeouts",
    ),
)


def sparkplug_families(
    stats: SparkplugStats, *, born: bool, host_online: bool | None
) -> Iterator[Metric]:
    """The edge node's metric families, built now (prometheus-client imported here)."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    for name, help_text, attribute in _COUNTERS:
        family = CounterMetricFamily(name, help_text)
        family.add_metric([], getattr(stats, attribute))
        yield family
    published = CounterMetricFamily(
        "sj300_sparkplug_published", "Sparkplug messages published, by type.", labels=["type"]
    )
    for kind in ("NBIRTH", "NDATA", "NDEATH", "DBIRTH", "DDATA", "DDEATH"):
        published.add_metric([kind], stats.published[kind])
    yield published
    writes = CounterMetricFamily(
        "sj300_sparkplug_writes", "Metric writes of DCMDs, by result.", labels=["result"]
    )
    writes.add_metric(["done"], stats.writes)
    writes.add_metric(["refused"], stats.refused)
    yield writes
    bad = CounterMetricFamily(
        "sj300_sparkplug_bad_input",
        "Received input that changed nothing, by reason.",
        labels=["reason"],
    )
    for reason in BAD_INPUTS:
        bad.add_metric([reason], stats.bad_input[reason])
    yield bad
    yield refused_subscriptions("sj300_sparkplug_subscriptions_refused", stats)
    state = GaugeMetricFamily(
        "sj300_sparkplug_born", "1 while the edge node's birth stands on a connection."
    )
    state.add_metric([], 1.0 if born else 0.0)
    yield state
    if host_online is not None:
        host = GaugeMetricFamily(
            "sj300_sparkplug_primary_host_online", "1 while the primary host says it is online."
        )
        host.add_metric([], 1.0 if host_online else 0.0)
        yield host
