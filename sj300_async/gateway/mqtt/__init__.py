"""The MQTT northbound, and the fleet subscriber that reads what gateways publish.

- The northbound (``[mqtt] url = "mqtt://HOST[:PORT]"`` or ``--mqtt URL``):
  each drive's state and availability, Home Assistant discovery, and
  commands (:mod:`._bridge`, :mod:`._messages`, :mod:`._discovery`,
  :mod:`._commands`), on one connection kept up by :mod:`._session`, its
  subscriptions checked by :mod:`._subscriptions` (shared with Sparkplug).
- The contract both sides share: topics and the state message
  (:mod:`._topics`).
- The fleet (:mod:`._fleet`): every drive of every gateway on a broker,
  read-only; ``sj300 monitor --url mqtt://…`` renders it.

The MQTT client (:mod:`.client`) is the gateway's own, on the standard
library: this package's face stays light, for the command line builds its
flags from it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from .. import ConfigTable, Endpoint, Flag, Northbound, SectionContext
from ._commands import (
    COMMAND_DIRECTIONS,
    DROPPED_BY_STOP,
    error_text,
    frequency_request,
    parameter_request,
    parse_command,
)
from ._config import MQTT_KEYS, MqttConfig, SparkplugConfig, parse_mqtt_section
from ._discovery import discovery, node_id
from ._fleet import (
    FLEET_SCHEMES,
    Fleet,
    FleetUrl,
    Malformed,
    SubscriptionRefused,
    follow,
    is_fleet_url,
    parse_fleet_url,
)
from ._messages import state_message
from ._session import (
    BrokerUnreachable,
    SessionStats,
    backoff,
    cancel_and_wait,
    keep_connected,
    new_client,
    reader,
)
from ._stats import BridgeStats, mqtt_families, refused_subscriptions
from ._subscriptions import Subscriptions
from ._topics import (
    AVAILABLE,
    COMMANDS,
    DEFAULT_PREFIX,
    DISCOVERY_PREFIX,
    UNAVAILABLE,
    StateMessage,
    Topics,
    parse_state_topic,
)

__all__ = [
    "AVAILABLE",
    "COMMANDS",
    "COMMAND_DIRECTIONS",
    "DEFAULT_PREFIX",
    "DISCOVERY_PREFIX",
    "DROPPED_BY_STOP",
    "FLEET_SCHEMES",
    "NORTHBOUND",
    "UNAVAILABLE",
    "BridgeStats",
    "BrokerUnreachable",
    "Fleet",
    "FleetUrl",
    "Malformed",
    "MqttConfig",
    "SessionStats",
    "SparkplugConfig",
    "StateMessage",
    "SubscriptionRefused",
    "Subscriptions",
    "Topics",
    "backoff",
    "cancel_and_wait",
    "discovery",
    "error_text",
    "follow",
    "frequency_request",
    "is_fleet_url",
    "keep_connected",
    "mqtt_families",
    "new_client",
    "node_id",
    "parameter_request",
    "parse_command",
    "parse_fleet_url",
    "parse_state_topic",
    "reader",
    "refused_subscriptions",
    "state_message",
]


class _Spec:
    section = "mqtt"
    keys = MQTT_KEYS
    flag = Flag(
        "--mqtt",
        "url",
        "URL",
        "publish to this MQTT broker (mqtt://HOST[:PORT] or mqtts://): state, "
        "availability, Home Assistant discovery (Sparkplug B: [mqtt] sparkplug = true)",
    )
    requires = ("google.protobuf", "orjson")

    def parse(self, table: ConfigTable, context: SectionContext) -> MqttConfig:
        return parse_mqtt_section(table, context)

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        return ()  # a client: it listens on nothing

    def create(self, config: object) -> Northbound:
        from ._pair import Clients, StatePublisher

        assert isinstance(config, MqttConfig)
        parts: list[StatePublisher] = []
        if config.state_topics:
            from ._bridge import MqttBridge

            parts.append(MqttBridge(config))
        if config.sparkplug is not None:
            from ..sparkplug import EdgeNode

            parts.append(EdgeNode(config))
        if len(parts) == 1:
            return parts[0]
        return Clients(parts)


#: The registry's entry (``sj300_async.gateway.mqtt:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
