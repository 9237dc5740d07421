"""Sparkplug B payloads, typed: what the edge node sends, encoded; what it receives, decoded.

Sans-IO. The protobuf classes come from :mod:`._schema`; nothing else in the
package touches them.

- Encoding: a metric is a :class:`MetricDef` (name, alias, datatype, the
  properties of its birth) with a value. A birth carries name, alias,
  datatype, properties and value; a data message the alias and value only
  (Sparkplug 3.0, 6.4.6: "NDATA, DDATA, NCMD, and DCMD messages MUST only
  include an alias"). A value of None is sent as ``is_null`` with no value.
  Every metric carries the timestamp it is given.
- Decoding (commands): :func:`decode_payload` reads any valid payload into
  :class:`ReceivedMetric` values that keep which member of the value
  ``oneof`` was set, so the edge node can refuse a value of the wrong type;
  bytes that are no payload raise :class:`MalformedPayload`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Final

from google.protobuf.message import DecodeError

from ._schema import DATA_TYPES, Payload

__all__ = [
    "BOOLEAN",
    "DOUBLE",
    "INT64",
    "STRING",
    "UINT32",
    "UINT64",
    "Decoded",
    "MalformedPayload",
    "MetricDef",
    "Property",
    "ReceivedMetric",
    "decode_payload",
    "encode_payload",
]

INT64: Final = DATA_TYPES["Int64"]
UINT32: Final = DATA_TYPES["UInt32"]
UINT64: Final = DATA_TYPES["UInt64"]
DOUBLE: Final = DATA_TYPES["Double"]
BOOLEAN: Final = DATA_TYPES["Boolean"]
STRING: Final = DATA_TYPES["String"]

#: The member of a metric's (and a property value's) value oneof each datatype uses.
#: UInt32 goes in ``long_value``, as Eclipse Tahu (the reference implementation, under
#: Ignition's MQTT modules) puts it and reads it back: its JavaScript decoder reads a
#: UInt32 in ``int_value`` as null.
_MEMBER: Final = {
    **{DATA_TYPES[n]: "int_value" for n in ("Int8", "Int16", "Int32", "UInt8", "UInt16")},
    UINT32: "long_value",
    INT64: "long_value",
    UINT64: "long_value",
    DATA_TYPES["DateTime"]: "long_value",
    DATA_TYPES["Float"]: "float_value",
    DOUBLE: "double_value",
    BOOLEAN: "boolean_value",
    STRING: "string_value",
    DATA_TYPES["Text"]: "string_value",
    DATA_TYPES["UUID"]: "string_value",
}
_WIDTH: Final = {"int_value": 1 << 32, "long_value": 1 << 64}


class MalformedPayload(ValueError):
    """Bytes that are no Sparkplug B payload."""


@dataclass(frozen=True, slots=True)
class Property:
    """One entry of a metric's property set (``engUnit = "Hz"``)."""

    key: str
    datatype: int
    value: object


@dataclass(frozen=True, slots=True)
class MetricDef:
    """What a birth says of a metric; data messages name it by alias."""

    name: str
    #: None: no alias (the specification's ``bdSeq`` and ``Node Control/Rebirth``).
    alias: int | None
    datatype: int
    properties: tuple[Property, ...] = ()


def _set(target: Any, datatype: int, value: object) -> None:
    """Set *value* in *target*'s value oneof, as *datatype* says (signed: two's complement)."""
    member = _MEMBER[datatype]
    if member in _WIDTH and isinstance(value, int) and value < 0:
        value += _WIDTH[member]
    setattr(target, member, value)


def encode_payload(
    timestamp_ms: int,
    seq: int | None,
    metrics: Iterable[tuple[MetricDef, object]],
    *,
    birth: bool,
    metric_timestamp_ms: int | None = None,
    alias_base: int = 0,
) -> bytes:
    """A payload of *metrics* (each with its value, None for null).

    *seq* None leaves the sequence number out (NDEATH). Every metric's
    timestamp is *metric_timestamp_ms* (default: *timestamp_ms*). A metric's
    alias is its definition's plus *alias_base* (a device's metrics are shared
    by every device built alike, each numbering them from its own base).
    """
    payload = Payload()
    payload.timestamp = timestamp_ms
    if seq is not None:
        payload.seq = seq
    stamp = timestamp_ms if metric_timestamp_ms is None else metric_timestamp_ms
    for definition, value in metrics:
        metric = payload.metrics.add()
        if birth or definition.alias is None:
            metric.name = definition.name
        if definition.alias is not None:
            metric.alias = alias_base + definition.alias
        metric.timestamp = stamp
        if birth:
            metric.datatype = definition.datatype
            if definition.properties:
                properties = metric.properties
                for prop in definition.properties:
                    properties.keys.append(prop.key)
                    entry = properties.values.add()
                    entry.type = prop.datatype
                    _set(entry, prop.datatype, prop.value)
        if value is None:
            metric.is_null = True
        else:
            _set(metric, definition.datatype, value)
    data: bytes = payload.SerializeToString()
    return data


@dataclass(frozen=True, slots=True)
class ReceivedMetric:
    """A metric of a received command."""

    name: str | None
    alias: int | None
    #: The datatype it says it has, None when it says none (the usual in commands).
    datatype: int | None
    #: The member of the value oneof that was set (``"double_value"``), None for none.
    member: str | None
    #: Its value as sent (an unsigned member as the unsigned number), None for none.
    value: object
    is_null: bool

    @property
    def label(self) -> str:
        """How a log line names it: its name, else its alias."""
        return self.name if self.name is not None else f"alias {self.alias}"


@dataclass(frozen=True, slots=True)
class Decoded:
    """A received payload."""

    timestamp_ms: int | None
    seq: int | None
    metrics: Sequence[ReceivedMetric]


def decode_payload(data: bytes) -> Decoded:
    """*data* read as a Sparkplug B payload.

    Raises:
        MalformedPayload: it is not one.
    """
    try:
        payload = Payload.FromString(data)
    except (DecodeError, ValueError, RuntimeError) as exc:  # upb raises DecodeError
        raise MalformedPayload(str(exc) or "not a Sparkplug B payload") from None
    metrics = []
    for metric in payload.metrics:
        member = metric.WhichOneof("value")
        metrics.append(
            ReceivedMetric(
                name=metric.name if metric.HasField("name") else None,
                alias=metric.alias if metric.HasField("alias") else None,
                datatype=metric.datatype if metric.HasField("datatype") else None,
                member=member,
                value=None if member is None else getattr(metric, member),
                is_null=metric.is_null,
            )
        )
    return Decoded(
        timestamp_ms=payload.timestamp if payload.HasField("timestamp") else None,
        seq=payload.seq if payload.HasField("seq") else None,
        metrics=tuple(metrics),
    )
