"""MQTT as the gateway's transport: what its MQTT northbounds share, knowing none of them.

The JSON / Home Assistant northbound (``gateway.mqtt``) and the Sparkplug
B northbound (``gateway.sparkplug``) each ride it, on a connection of
their own (docs/GATEWAY.md, "One connection each"):

- :mod:`.client`: the gateway's own MQTT 3.1.1 client, on the standard
  library (a sans-IO codec under an asyncio protocol);
- :mod:`._broker`: the broker keys both sections take (URL, identity,
  credentials, TLS with an optional client certificate, keepalive),
  parsed once;
- :mod:`._session`: one connection kept up, its back-off and outages,
  :class:`SessionStats`;
- :mod:`._subscriptions`: every SUBACK checked; a refusal said, counted
  and shown on /healthz.

Nothing here imports a northbound: import-linter holds it to that.
"""

from __future__ import annotations

from ._broker import BROKER_KEYS, BrokerConfig, broker_fields, parse_broker
from ._session import (
    BACKOFF_FIRST_S,
    BrokerUnreachable,
    SessionStats,
    backoff,
    cancel_and_wait,
    keep_connected,
    new_client,
    reader,
)
from ._subscriptions import REFUSED, Subscriptions, refused_subscriptions

__all__ = [
    "BACKOFF_FIRST_S",
    "BROKER_KEYS",
    "REFUSED",
    "BrokerConfig",
    "BrokerUnreachable",
    "SessionStats",
    "Subscriptions",
    "backoff",
    "broker_fields",
    "cancel_and_wait",
    "keep_connected",
    "new_client",
    "parse_broker",
    "reader",
    "refused_subscriptions",
]
