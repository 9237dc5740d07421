"""The MQTT northbound, and the fleet subscriber that reads what gateways publish.

- The northbound (``[mqtt] url = "mqtt://HOST[:PORT]"`` or ``--mqtt URL``):
  each drive's state and availability, Home Assistant discovery, and
  commands (:mod:`._bridge`, :mod:`._messages`, :mod:`._discovery`,
  :mod:`._commands`), on one connection of its own, kept up and its
  subscriptions checked by the MQTT transport
  (:mod:`sj300_async.gateway.mqttlink`, which Sparkplug rides too).
- The contract both sides share: topics and the state message
  (:mod:`._topics`).
- The fleet (:mod:`._fleet`): every drive of every gateway on a broker,
  read-only; ``sj300 monitor --url mqtt://…`` renders it.

The MQTT client is the transport's (``mqttlink.client``), the gateway's
own on the standard library: this package's face stays light, for the
command line builds its flags from it. It imports no other northbound:
Sparkplug B is ``[sparkplug]`` (``gateway.sparkplug``), which reads this
section's deprecated ``sparkplug = true`` itself.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from .. import ConfigTable, Endpoint, Flag, Northbound, SectionContext

# What follow() raises for a broker it cannot reach: the transport's, part of the fleet's face.
from ..mqttlink import BrokerUnreachable
from ._commands import COMMAND_DIRECTIONS, error_text, parse_command
from ._config import MQTT_KEYS, SPARKPLUG_ALIAS_KEYS, MqttConfig, parse_mqtt_section
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
from ._stats import BridgeStats, mqtt_families
from ._sweep import SweepRefused, Swept, sweep
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
    "FLEET_SCHEMES",
    "NORTHBOUND",
    "SPARKPLUG_ALIAS_KEYS",
    "UNAVAILABLE",
    "BridgeStats",
    "BrokerUnreachable",
    "Fleet",
    "FleetUrl",
    "Malformed",
    "MqttConfig",
    "StateMessage",
    "SubscriptionRefused",
    "SweepRefused",
    "Swept",
    "Topics",
    "discovery",
    "error_text",
    "follow",
    "is_fleet_url",
    "mqtt_families",
    "node_id",
    "parse_command",
    "parse_fleet_url",
    "parse_state_topic",
    "state_message",
    "sweep",
]


class _Spec:
    section = "mqtt"
    keys = MQTT_KEYS
    flag = Flag(
        "--mqtt",
        "url",
        "URL",
        "publish to this MQTT broker (mqtt://HOST[:PORT] or mqtts://): state, "
        "availability, Home Assistant discovery (Sparkplug B: a [sparkplug] section)",
    )
    requires = ("orjson",)

    def parse(self, table: ConfigTable, context: SectionContext) -> MqttConfig | None:
        return parse_mqtt_section(table, context)

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        return ()  # a client: it listens on nothing

    def check(self, config: object) -> Sequence[str]:
        """``--check-config``'s words for it (the broker is not contacted)."""
        assert isinstance(config, MqttConfig)
        return (f"to {config.url} as {config.client_id}, not contacted by the check",)

    def create(self, config: object) -> Northbound:
        from ._bridge import MqttBridge

        assert isinstance(config, MqttConfig)
        return MqttBridge(config)


#: The registry's entry (``sj300_async.gateway.mqtt:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
