"""``[mqtt]``: the broker the gateway publishes its JSON topics to, and how.

The broker keys (``url``, ``client_id``, ``username``, ``password``,
``tls_ca``, ``tls_cert``, ``tls_key``, ``keepalive_s``) are the MQTT
transport's (:mod:`sj300_async.gateway.mqttlink`, parsed there for this
section and ``[sparkplug]`` alike); the client id defaults to
``sj300-<gateway id>``. This section adds the topics' ``prefix``, the
``qos``, Home Assistant's ``discovery`` and ``discovery_prefix``,
``state_topics``, ``home_assistant_lease`` (:mod:`._presence`), and the
command intake's budget (:mod:`._intake`):
``command_burst`` and ``commands_per_s`` per drive, ``all_command_burst``
and ``all_commands_per_s`` for every drive together. The defaults (20, 10,
200, 100) are far above what a person, Home Assistant or a heartbeating
SCADA sends; a controller that streams setpoints faster raises them. Each
is a whole number from 1 to :data:`MAX_BUDGET`: a budget of 0 would drop
every command, and one past a million is no budget.

Sparkplug B has its own section, ``[sparkplug]``. For one release
``[mqtt]`` still takes ``sparkplug = true`` with ``group_id`` and
``primary_host_id`` (:data:`SPARKPLUG_ALIAS_KEYS`): the Sparkplug
northbound reads them from this table (it logs the deprecation); this
package only accepts them. ``state_topics = false`` leaves the JSON topics
and discovery out, for a plant that reads only Sparkplug under the alias:
then ``[mqtt]`` configures nothing of this northbound.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from .. import ConfigTable, SectionContext, valid_name
from ..mqttlink import BROKER_KEYS, BrokerConfig, broker_fields, parse_broker
from ._intake import COMMAND_BUDGET, Budget
from ._topics import DEFAULT_PREFIX, DISCOVERY_PREFIX

__all__ = ["MAX_BUDGET", "MQTT_KEYS", "SPARKPLUG_ALIAS_KEYS", "MqttConfig", "parse_mqtt_section"]

#: Sparkplug B's keys of old, read by the Sparkplug northbound (deprecated alias).
SPARKPLUG_ALIAS_KEYS: Final = ("sparkplug", "group_id", "primary_host_id")
#: The largest command budget a key takes (see the module docstring).
MAX_BUDGET: Final = 1_000_000
MQTT_KEYS: Final = (
    *BROKER_KEYS,
    *("prefix", "qos", "discovery", "discovery_prefix", "state_topics"),
    *("command_burst", "commands_per_s", "all_command_burst", "all_commands_per_s"),
    "home_assistant_lease",
    *SPARKPLUG_ALIAS_KEYS,
)


@dataclass(frozen=True, slots=True)
class MqttConfig(BrokerConfig):
    """The JSON topics' broker and topics (docs/GATEWAY.md, "MQTT")."""

    #: The first topic level(s): ``<prefix>/<gateway id>/...``.
    prefix: str = DEFAULT_PREFIX
    #: The QoS of everything published and subscribed (0 or 1).
    qos: int = 1
    #: Home Assistant's MQTT discovery: configs published, and republished on its birth.
    discovery: bool = True
    discovery_prefix: str = DISCOVERY_PREFIX
    #: Commands taken per drive and in all (stops: the same again, apart).
    commands: Budget = COMMAND_BUDGET
    #: The control lease kept while Home Assistant is present (:mod:`._presence`).
    home_assistant_lease: bool = True


_DEFAULT: Final = MqttConfig(host="localhost", port=1883)


def parse_mqtt_section(table: ConfigTable, context: SectionContext) -> MqttConfig | None:
    """``[mqtt]`` (see the module docstring); None: ``state_topics = false``.

    Raises:
        GatewayConfigError: through *table*.
    """
    broker = parse_broker(table, context, client_id=f"sj300-{context.gateway_id}")
    qos = table.integer("qos")
    if qos is not None and qos not in (0, 1):
        raise table.error("qos", f"must be 0 or 1, got {qos}")
    discovery = table.boolean("discovery")
    home_assistant_lease = table.boolean("home_assistant_lease")
    prefix = _topic_prefix(table, "prefix", DEFAULT_PREFIX)
    discovery_prefix = _topic_prefix(table, "discovery_prefix", DISCOVERY_PREFIX)
    if table.boolean("state_topics") is False:
        if not table.boolean("sparkplug"):
            raise table.error(
                "state_topics",
                "with state_topics = false, [mqtt] publishes nothing: leave the section out",
            )
        return None  # only Sparkplug's deprecated keys: its northbound reads them
    return MqttConfig(
        **broker_fields(broker),
        prefix=prefix,
        qos=_DEFAULT.qos if qos is None else qos,
        discovery=_DEFAULT.discovery if discovery is None else discovery,
        discovery_prefix=discovery_prefix,
        home_assistant_lease=home_assistant_lease is not False,
        commands=Budget(
            burst=_budget(table, "command_burst", COMMAND_BUDGET.burst),
            per_s=_budget(table, "commands_per_s", COMMAND_BUDGET.per_s),
            all_burst=_budget(table, "all_command_burst", COMMAND_BUDGET.all_burst),
            all_per_s=_budget(table, "all_commands_per_s", COMMAND_BUDGET.all_per_s),
        ),
    )


def _budget(table: ConfigTable, name: str, default: int) -> int:
    value = table.integer(name)
    if value is None:
        return default
    if not 1 <= value <= MAX_BUDGET:
        raise table.error(name, f"expected a whole number from 1 to {MAX_BUDGET:,}, got {value}")
    return value


def _topic_prefix(table: ConfigTable, name: str, default: str) -> str:
    """Topic levels (``sj300``, ``plant/sj300``): each a valid name, no wildcards."""
    prefix = table.string(name)
    if prefix is None:
        return default
    if not all(valid_name(level) for level in prefix.split("/")):
        raise table.error(
            name,
            "expected topic levels of letters, digits, '_', '.' and '-' separated by '/', "
            f"got {prefix!r}",
        )
    return prefix
