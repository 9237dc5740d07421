"""Sparkplug B 3.0: the gateway as an edge node, each drive a device (docs/GATEWAY.md).

Configured in ``[mqtt]`` (``sparkplug = true``, ``group_id``, optional
``primary_host_id``) and created by the MQTT northbound beside its JSON
topics; it connects to the same broker on a connection of its own.

- :mod:`._schema`: the specification's protobuf schema, built at import;
  :mod:`._payload`: payloads encoded and decoded, typed.
- :mod:`._device`: a drive's metrics and aliases; :mod:`._commands`: DCMD
  metrics judged into the gateway's writes.
- :mod:`._node`: the edge node's session (births, data by exception,
  deaths, the primary host, commands); :mod:`._stats`: its counters.

The protobuf runtime is imported with this package, which the MQTT
northbound imports only when Sparkplug is configured.
"""

from __future__ import annotations

from ._device import DIRECTION_WORDS, LAST_REFUSAL, Device, DeviceMetric, device_id
from ._node import CLIENT, NAMESPACE, NODE_METRICS, EdgeNode
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
from ._stats import BAD_INPUTS, SparkplugStats

__all__ = [
    "BAD_INPUTS",
    "CLIENT",
    "DATA_TYPES",
    "DIRECTION_WORDS",
    "LAST_REFUSAL",
    "NAMESPACE",
    "NODE_METRICS",
    "Decoded",
    "Device",
    "DeviceMetric",
    "EdgeNode",
    "MalformedPayload",
    "MetricDef",
    "Property",
    "ReceivedMetric",
    "SparkplugStats",
    "decode_payload",
    "device_id",
    "encode_payload",
]
