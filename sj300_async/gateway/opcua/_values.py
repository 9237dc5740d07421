"""The DataValues the OPC UA server serves: a drive variable's, and each line's counters.

A drive variable's value and status come from its :class:`~._model.Binding`
(the drive as served); this module only makes the DataValue. A line's
counters are the core's health of the line (``ServedLine.health``), read
when a client reads them, and pushed by the server's tick only while a
monitored item watches them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from typing import Any, Final, cast

from asyncua import ua

from .. import ServedLine
from ._model import LINE_COUNTERS, Binding, LineNodes
from ._quality import BAD_WAITING, GOOD, utc
from ._speedups import ServedDataValue

__all__ = ["LineCounters", "drive_datavalue"]

_LINE_TYPES: Final = {name: vtype for name, vtype, _, _ in LINE_COUNTERS}
_CONVERT: Final = {
    ua.VariantType.Double: float,
    ua.VariantType.Boolean: bool,
    ua.VariantType.String: str,
    ua.VariantType.UInt16: int,
    ua.VariantType.UInt32: int,
    ua.VariantType.UInt64: int,
    ua.VariantType.Int32: int,
}


def drive_datavalue(binding: Binding, status: int) -> ua.DataValue:
    """*binding*'s value with *status*, stamped with its sample's wall time."""
    if status & 0x80000000:  # Bad: no value (Part 4, 7.7.1)
        variant = ua.Variant(None, ua.VariantType.Null)
    else:
        convert = _CONVERT[binding.vtype]
        if binding.array:  # a missing element: a null string, a NaN number
            empty = math.nan if binding.vtype == ua.VariantType.Double else None
            items = cast("list[object]", binding.value)
            value: object = [empty if v is None else convert(v) for v in items]
        else:
            value = convert(binding.value)
        variant = ua.Variant(value, binding.vtype)
    return ServedDataValue(
        Value=variant,
        StatusCode=ua.StatusCode(status),
        SourceTimestamp=utc(binding.wall),
        ServerTimestamp=utc(time.time()),
    )


class LineCounters:
    """The lines' counters: read on demand, pushed by the tick while watched."""

    def __init__(self) -> None:
        #: The monitored items on each counter's node.
        self._watched: dict[ua.NodeId, int] = {}

    def watch(self, node: ua.NodeId, change: int) -> None:
        """A monitored item added to (+1) or deleted from (-1) a counter's node."""
        count = self._watched.get(node, 0) + change
        if count > 0:
            self._watched[node] = count
        else:  # no count kept for a node nobody watches (a drive's property, too)
            self._watched.pop(node, None)

    def forget(self, nodes: Iterable[ua.NodeId]) -> None:
        """*nodes* are deleted (a reload removed their line): their watch counts go."""
        for node in nodes:
            self._watched.pop(node, None)

    def reader(self, nodes: LineNodes, name: str) -> Any:
        """The read callback of the line's counter *name*."""

        def read(node: ua.NodeId, attribute: ua.AttributeIds) -> ua.DataValue:
            return _datavalue(name, _values(nodes.line).get(name))

        return read

    def tick(self, nodes: LineNodes, now: float, outbox: dict[ua.NodeId, ua.DataValue]) -> bool:
        """The watched counters that changed since the last tick, into *outbox*. True when
        one did."""
        changed = False
        for key, value in _values(nodes.line, now).items():
            if not self._watched.get(nodes.counters[key]):  # reads ask the line
                nodes.shown.pop(key, None)
                continue
            if value is None or nodes.shown.get(key) == value:
                continue
            nodes.shown[key] = value
            outbox[nodes.counters[key]] = _datavalue(key, value)
            changed = True
        return changed


def _datavalue(name: str, value: object) -> ua.DataValue:
    vtype = _LINE_TYPES[name]
    stamp = utc(time.time())
    if value is None:
        return ServedDataValue(
            Value=ua.Variant(None, ua.VariantType.Null),
            StatusCode=ua.StatusCode(BAD_WAITING),
            SourceTimestamp=stamp,
            ServerTimestamp=stamp,
        )
    return ServedDataValue(
        Value=ua.Variant(_CONVERT[vtype](value), vtype),
        StatusCode=ua.StatusCode(GOOD),
        SourceTimestamp=stamp,
        ServerTimestamp=stamp,
    )


def _values(line: ServedLine, now: float | None = None) -> dict[str, object]:
    """A line's counters as the OPC UA model names them (the core's health of the line)."""
    health = line.health(now)
    return {
        "Connected": health.connected,
        "DrivesOnline": health.drives_online,
        "Utilisation": health.utilisation,
        "Requests": health.requests,
        "Replies": health.replies,
        "Timeouts": health.timeouts,
        "Retries": health.retries,
        "Naks": health.naks,
        "TransportErrors": health.transport_errors,
        "ProtocolErrors": health.protocol_errors,
        "BadFrames": health.bad_frames,
        "EarlyFrames": health.early_frames,
        "StrayFrames": health.stray_frames,
        "DiscardedBytes": health.discarded_bytes,
        "Connects": health.connects,
        "Disconnects": health.disconnects,
        "LatencyMean": health.latency_mean_s,
    }
