"""``[sparkplug]``: the broker the edge node publishes to, and its Sparkplug ids.

The broker keys are the MQTT transport's (``url``, ``client_id``,
``username``, ``password``, ``tls_ca``, ``tls_cert``, ``tls_key``,
``keepalive_s``: :mod:`sj300_async.gateway.mqttlink`), parsed as
``[mqtt]`` parses them; the client id defaults to ``sj300-<gateway
id>-spb``. ``group_id`` (required) is the Sparkplug group; an optional
``primary_host_id`` names the host application the edge node waits for.
The edge node id is the gateway's id.

The deprecated alias (for one release): ``[mqtt] sparkplug = true`` with
its ``group_id`` and optional ``primary_host_id`` configures this
northbound from ``[mqtt]``'s broker keys (its client id, if given, with
``-spb``: the two connections need two ids), and logs one WARNING naming
``[sparkplug]``. Both at once is an error. ``[mqtt]`` only accepts the
keys (``mqtt.SPARKPLUG_ALIAS_KEYS``) and imports nothing of Sparkplug:
this spec reads its table through the registry's ``borrows`` hook
(:mod:`sj300_async.gateway`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Final

from .. import ConfigTable, SectionContext
from ..mqttlink import BROKER_KEYS, BrokerConfig, broker_fields, parse_broker

__all__ = [
    "SPARKPLUG_KEYS",
    "SparkplugConfig",
    "parse_mqtt_alias",
    "parse_sparkplug_section",
]

_log = logging.getLogger("sj300_async.gateway.sparkplug")

SPARKPLUG_KEYS: Final = (*BROKER_KEYS, "group_id", "primary_host_id")


@dataclass(frozen=True, slots=True)
class SparkplugConfig(BrokerConfig):
    """Sparkplug B's broker and ids (docs/GATEWAY.md, "Sparkplug B")."""

    #: The Sparkplug group the gateway's edge node belongs to.
    group_id: str = field(kw_only=True)
    #: The primary host application the edge node waits for (its STATE), or None.
    primary_host_id: str | None = field(default=None, kw_only=True)


def parse_sparkplug_section(table: ConfigTable, context: SectionContext) -> SparkplugConfig:
    """``[sparkplug]`` (see the module docstring).

    Raises:
        GatewayConfigError: through *table*.
    """
    broker = parse_broker(table, context, client_id=f"sj300-{context.gateway_id}-spb")
    group_id = _sparkplug_id(table, "group_id")
    if group_id is None:
        raise table.error("group_id", "missing required key 'group_id' (the Sparkplug group)")
    return SparkplugConfig(
        **broker_fields(broker),
        group_id=group_id,
        primary_host_id=_sparkplug_id(table, "primary_host_id"),
    )


def parse_mqtt_alias(table: ConfigTable, context: SectionContext) -> SparkplugConfig | None:
    """``[mqtt] sparkplug = true`` (deprecated), else None (see the module docstring).

    Raises:
        GatewayConfigError: through *table* (``[mqtt]``'s).
    """
    if not table.boolean("sparkplug"):
        for key in ("group_id", "primary_host_id"):
            if table.string(key) is not None:
                raise table.error(key, "needs sparkplug = true (better: a [sparkplug] section)")
        return None
    group_id = _sparkplug_id(table, "group_id")
    if group_id is None:
        raise table.error("group_id", "sparkplug = true needs a group_id (the Sparkplug group)")
    given_id = table.string("client_id")
    client_id = f"sj300-{context.gateway_id}" if given_id is None else given_id
    broker = parse_broker(table, context, client_id=f"{client_id}-spb")
    _log.warning(
        "%s: [mqtt] sparkplug = true is deprecated and goes in the next release: "
        'configure Sparkplug B in a [sparkplug] section (docs/GATEWAY.md, "Sparkplug B")',
        table.ctx.source,
    )
    return SparkplugConfig(
        **{**broker_fields(broker), "client_id": f"{client_id}-spb"},
        group_id=group_id,
        primary_host_id=_sparkplug_id(table, "primary_host_id"),
    )


def _sparkplug_id(table: ConfigTable, key: str) -> str | None:
    """A Sparkplug id: UTF-8 text without ``+``, ``/``, ``#`` or control characters."""
    text = table.string(key)
    if text is None:
        return None
    if not text or any(c in "+/#" or not c.isprintable() for c in text) or text != text.strip():
        raise table.error(
            key,
            f"expected a Sparkplug id: text without '+', '/', '#', control characters or "
            f"surrounding spaces, got {text!r}",
        )
    return text
