"""What the MQTT bridge counts, and the metric families it contributes to /metrics."""

from __future__ import annotations

import collections
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from ..mqttlink import SessionStats, refused_subscriptions

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["BridgeStats", "mqtt_families"]

Key = tuple[str, int]


@dataclass
class BridgeStats(SessionStats):
    """What the bridge did (see the module docstring: nothing is dropped silently)."""

    #: Messages the broker took (QoS 1: acknowledged).
    published: int = 0
    #: Messages not confirmed: being sent when the connection broke or the
    #: bridge stopped (some may have reached the broker), or still waiting at
    #: the stop. States and availability are republished on reconnect; error
    #: replies are not.
    lost: int = 0
    #: Snapshots handed to the bridge (each poll, each write's read-back), per drive.
    samples: collections.Counter[Key] = field(default_factory=collections.Counter)
    #: State messages published, per drive.
    states: collections.Counter[Key] = field(default_factory=collections.Counter)
    #: State messages replaced by a newer one before they were sent, per drive.
    replaced: collections.Counter[Key] = field(default_factory=collections.Counter)
    #: Error replies not published: past the replies' budget (:mod:`._intake`), or
    #: more than MAX_ERRORS were waiting.
    errors_dropped: int = 0
    #: Command messages received, refused, and discarded (received but not
    #: started before the connection they came on was lost).
    commands: int = 0
    refused: int = 0
    discarded: int = 0
    #: Messages on the command topics that name no drive of this gateway.
    ignored: int = 0
    #: Commands refused unread: longer than MAX_PAYLOAD_BYTES (also in ``refused``).
    oversized: int = 0
    #: Commands dropped unread: past the intake budget (:mod:`._intake`); not in
    #: ``refused`` (no reply, no audit).
    throttled: int = 0
    #: Commands a bug stopped (logged with its traceback; also in ``refused``): the
    #: drive's command worker goes on with the next.
    failed: int = 0
    #: Re-discoveries for Home Assistant's births, and the births that added nothing
    #: (one was scheduled already: :mod:`._births`).
    rediscoveries: int = 0
    births_coalesced: int = 0
    #: Retained topics cleared at the start: left by drives or entities the
    #: configuration no longer has (:mod:`._sweep`).
    swept: int = 0


#: The bridge's counters: (name, HELP, BridgeStats attribute).
_COUNTERS: Final = (
    ("sj300_mqtt_connects", "Connections to the broker made.", "connects"),
    ("sj300_mqtt_losses", "Connections to the broker lost.", "losses"),
    ("sj300_mqtt_published", "Messages the broker took.", "published"),
    ("sj300_mqtt_lost", "Messages being sent when the connection broke.", "lost"),
    (
        "sj300_mqtt_errors_dropped",
        "Error replies not published (past their budget, or too many waiting).",
        "errors_dropped",
    ),
    (
        "sj300_mqtt_rediscoveries",
        "Discovery republished for Home Assistant's births (at most one per 10 s).",
        "rediscoveries",
    ),
    (
        "sj300_mqtt_births_coalesced",
        "Home Assistant births that added nothing: a re-discovery was scheduled already.",
        "births_coalesced",
    ),
    (
        "sj300_mqtt_swept",
        "Retained topics cleared at the start: drives and entities no longer configured.",
        "swept",
    ),
    (
        "sj300_mqtt_puback_timeouts",
        "Connections ended because a QoS 1 publish waited keepalive_s for its PUBACK.",
        "puback_timeouts",
    ),
    (
        "sj300_mqtt_suback_timeouts",
        "Connections ended because a SUBSCRIBE waited keepalive_s for its SUBACK.",
        "suback_timeouts",
    ),
)
#: Command messages by what became of them: (label, BridgeStats attribute).
_COMMAND_RESULTS: Final = (
    ("received", "commands"),
    ("refused", "refused"),
    ("discarded", "discarded"),
    ("ignored", "ignored"),
    ("oversized", "oversized"),
    ("failed", "failed"),
    ("throttled", "throttled"),
)


def mqtt_families(stats: BridgeStats) -> Iterator[Metric]:
    """The bridge's metric families, built now (prometheus-client imported here)."""
    from prometheus_client.core import CounterMetricFamily

    for name, help_text, attribute in _COUNTERS:
        family = CounterMetricFamily(name, help_text)
        family.add_metric([], getattr(stats, attribute))
        yield family
    commands = CounterMetricFamily(
        "sj300_mqtt_commands",
        "Command messages: received, refused (answered on the error topic), discarded "
        "(the connection was lost first), ignored (no drive of this gateway), oversized "
        "(refused unread: too long; also counted as refused), throttled (dropped unread, past "
        "the intake budget: no reply, no audit).",
        labels=["result"],
    )
    for label, attribute in _COMMAND_RESULTS:
        commands.add_metric([label], getattr(stats, attribute))
    yield commands
    replaced = CounterMetricFamily(
        "sj300_mqtt_states_replaced",
        "State messages replaced by a newer one before the broker took them (coalesced).",
    )
    replaced.add_metric([], sum(stats.replaced.values()))
    yield replaced
    yield refused_subscriptions("sj300_mqtt_subscriptions_refused", stats)
