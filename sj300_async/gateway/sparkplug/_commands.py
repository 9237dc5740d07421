"""DCMD metrics -> the gateway's neutral writes (sans-IO).

A DCMD names its metrics by alias (the specification's rule) or by name
(some hosts send both; the alias wins). Each metric is judged alone:

- a metric the device's birth did not have: ``unknown_metric``
  (:attr:`~sj300_async.gateway.Refusal.UNKNOWN_TARGET`);
- a read-only one: not allowed;
- a null, no value, a datatype other than the metric's, or a value of the
  wrong kind: ``wrong_type`` (malformed). Numbers may come in any numeric
  member (a host may send a Float for a Double); an integer member is read
  as unsigned, as the specification encodes it, so a negative number must
  come as a Float or Double;
- then the value: a frequency or a parameter becomes the gateway's neutral
  request, judged by its controller as from every door (the range, the
  0.01 Hz step, a parameter's setting increment); a direction is one of
  ``stop``, ``forward``, ``reverse``; ``Control/Lease`` and
  ``Control/Stop`` take ``true`` only.
"""

from __future__ import annotations

from typing import Final

from ...wire import Direction
from .. import (
    DIRECTION_WORDS,
    Heartbeat,
    ParameterValue,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
    excerpt,
)
from ._device import Device, DeviceMetric, Writes
from ._payload import BOOLEAN, DOUBLE, STRING, ReceivedMetric

__all__ = ["Judged", "judge"]

_NUMBERS: Final = frozenset({"int_value", "long_value", "float_value", "double_value"})
_MEMBERS: Final = {
    DOUBLE: _NUMBERS,
    BOOLEAN: frozenset({"boolean_value"}),
    STRING: frozenset({"string_value"}),
}
#: Direction's words as written: the gateway's, the ones it is read in.
_DIRECTIONS: Final = {word: direction for direction, word in DIRECTION_WORDS.items()}

#: What became of one metric of a DCMD: the device's metric it names (None: none), the
#: write it asks for or why not, and the bad-input reason to count (None: not bad input).
Judged = tuple[DeviceMetric | None, WriteRequest | WriteResult, str | None]


def _shown(value: object) -> str:
    return excerpt(repr(value))


def judge(device: Device, received: ReceivedMetric) -> Judged:
    """The write *received* asks of *device* (see the module docstring)."""
    metric = None
    if received.alias is not None:
        metric = device.by_alias(received.alias)
    elif received.name is not None:
        metric = device.by_name(received.name)
    if metric is None:
        what = excerpt(received.label)
        return (
            None,
            WriteResult(Refusal.UNKNOWN_TARGET, f"{what} is no metric of {device.id}"),
            "unknown_metric",
        )
    definition = metric.definition
    if metric.write is None:
        return (
            metric,
            WriteResult(Refusal.NOT_ALLOWED, f"{definition.name} is read-only here"),
            None,
        )
    expected = _MEMBERS[definition.datatype]
    if (
        received.is_null
        or received.member not in expected
        or (received.datatype is not None and received.datatype != definition.datatype)
    ):
        got = "null" if received.is_null or received.member is None else received.member
        return (
            metric,
            WriteResult(
                Refusal.MALFORMED,
                f"{definition.name} takes a {_type_name(definition.datatype)}, got {got}",
            ),
            "wrong_type",
        )
    return metric, _request(device, metric, received.value), None


def _type_name(datatype: int) -> str:
    return {DOUBLE: "number", BOOLEAN: "Boolean", STRING: "String"}[datatype]


def _request(device: Device, metric: DeviceMetric, value: object) -> WriteRequest | WriteResult:
    name = metric.definition.name
    if metric.write in (Writes.FREQUENCY, Writes.PARAMETER):
        assert isinstance(value, int | float)
        number = float(value)
        if metric.write == Writes.FREQUENCY:  # judged by the gateway, as from every door
            return SetFrequency(number)
        assert metric.code is not None
        return ParameterValue(metric.code, number, repr(value))  # judged by the gateway too
    if metric.write == Writes.DIRECTION:
        direction = _DIRECTIONS.get(str(value).strip().lower())
        if direction is None:
            return WriteResult(
                Refusal.MALFORMED, f"Direction takes stop, forward or reverse, got {_shown(value)}"
            )
        return RunCommand(direction)
    if value is not True:
        return WriteResult(Refusal.MALFORMED, f"{name} takes true only")
    return Heartbeat() if metric.write == Writes.LEASE else RunCommand(Direction.STOP)
