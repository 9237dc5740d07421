"""Sparkplug B 3.0: the gateway as an edge node, each drive a device (docs/GATEWAY.md).

A northbound of its own, ``[sparkplug]`` (:mod:`._config`: the broker's
keys, ``group_id``, an optional ``primary_host_id``), riding the MQTT
transport (:mod:`sj300_async.gateway.mqttlink`) on a connection of its
own: an MQTT connection has one last will, and the edge node's must be its
NDEATH (docs/GATEWAY.md, "One connection each"). It imports no other
northbound. ``[mqtt] sparkplug = true`` is its deprecated alias for one
release, read here through the registry's ``borrows`` hook.

- :mod:`._schema`: the specification's protobuf schema, built at import;
  :mod:`._payload`: payloads encoded and decoded, typed.
- :mod:`._device`: a drive's metrics and aliases; :mod:`._commands`: DCMD
  metrics judged into the gateway's writes.
- :mod:`._node`: the edge node's session (births, data by exception,
  deaths); :mod:`._node_metrics`: its own metrics (each line's health);
  :mod:`._host`: the primary host's STATE; :mod:`._workers`: each drive's
  commands carried out in order, refusals told; :mod:`._stats`: its
  counters; :mod:`._config`: its section.

The protobuf runtime is imported with the edge node, when Sparkplug is
configured and starts: this face stays light, for the command line loads
every spec to build its flags.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

from .. import ConfigTable, Endpoint, Northbound, SectionContext
from ._config import SPARKPLUG_KEYS, SparkplugConfig, parse_mqtt_alias, parse_sparkplug_section
from ._stats import BAD_INPUTS, SparkplugStats

if TYPE_CHECKING:
    from ._device import DIRECTION_WORDS, LAST_REFUSAL, Device, DeviceFlags, DeviceMetric, device_id
    from ._node import NAMESPACE, EdgeNode
    from ._node_metrics import NODE_METRICS
    from ._payload import (
        Decoded,
        MalformedPayload,
        MetricDef,
        Property,
        ReceivedMetric,
        decode_payload,
        encode_payload,
    )
    from ._schema import DATA_TYPES
    from ._workers import CLIENT

__all__ = [
    "BAD_INPUTS",
    "CLIENT",
    "DATA_TYPES",
    "DIRECTION_WORDS",
    "LAST_REFUSAL",
    "NAMESPACE",
    "NODE_METRICS",
    "NORTHBOUND",
    "SPARKPLUG_KEYS",
    "Decoded",
    "Device",
    "DeviceFlags",
    "DeviceMetric",
    "EdgeNode",
    "MalformedPayload",
    "MetricDef",
    "Property",
    "ReceivedMetric",
    "SparkplugConfig",
    "SparkplugStats",
    "decode_payload",
    "device_id",
    "encode_payload",
]

#: The names that need protobuf, by the module that holds them: imported on first use.
_LAZY: Final = {
    **dict.fromkeys(
        ("DIRECTION_WORDS", "LAST_REFUSAL", "Device", "DeviceFlags", "DeviceMetric", "device_id"),
        "_device",
    ),
    **dict.fromkeys(("NAMESPACE", "EdgeNode"), "_node"),
    "NODE_METRICS": "_node_metrics",
    "CLIENT": "_workers",
    **dict.fromkeys(
        ("Decoded", "MalformedPayload", "MetricDef", "Property", "ReceivedMetric"), "_payload"
    ),
    **dict.fromkeys(("decode_payload", "encode_payload"), "_payload"),
    "DATA_TYPES": "_schema",
}


def __getattr__(name: str) -> object:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # once
    return value


class _Spec:
    section = "sparkplug"
    keys = SPARKPLUG_KEYS
    flag = None  # a URL alone is not enough: it needs its group_id
    requires = ("google.protobuf",)
    #: ``[mqtt] sparkplug = true`` (deprecated: goes in the next release).
    borrows = "mqtt"

    def parse(self, table: ConfigTable, context: SectionContext) -> SparkplugConfig:
        return parse_sparkplug_section(table, context)

    def parse_borrowed(self, table: ConfigTable, context: SectionContext) -> SparkplugConfig | None:
        return parse_mqtt_alias(table, context)

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        return ()  # a client: it listens on nothing

    def check(self, config: object) -> Sequence[str]:
        """``--check-config``'s words for it (the broker is not contacted)."""
        assert isinstance(config, SparkplugConfig)
        return (
            f"group {config.group_id} on {config.url} as {config.client_id}, "
            "not contacted by the check",
        )

    def create(self, config: object) -> Northbound:
        from ._node import EdgeNode

        assert isinstance(config, SparkplugConfig)
        return EdgeNode(config)


#: The registry's entry (``sj300_async.gateway.sparkplug:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
