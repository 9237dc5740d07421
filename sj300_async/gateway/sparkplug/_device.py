"""A drive as a Sparkplug device: its metrics, their aliases, and its values in a sample.

Sans-IO. Each drive of the gateway is one device of the edge node, with
device id ``<line>-<node>``. Its metrics (docs/GATEWAY.md, "Sparkplug B"):

==========================  ========  =====  =========================================
metric                      type      unit   written by a DCMD (where the line grants it)
==========================  ========  =====  =========================================
Output Frequency            Double    Hz
Frequency Command           Double    Hz     yes: the set frequency (control)
Output Current              Double    A
Output Voltage              Double    V
Output Power                Double    kW     (where the protocol measures it)
Output Torque               Double    %      (where the protocol measures it)
Direction                   String           yes: stop, forward, reverse (control)
Running, Tripped            Boolean
State, Trip, Trip Meaning   String
Lapse Pending               Boolean
Parameters/<code>           Double    its    yes, where granted
Control/Lease               Boolean          yes: true takes or renews the lease (control)
Control/Stop                Boolean          yes: true stops (control; no lease needed)
Control/Last Refusal        String           (where something is writable: the latest
Control/Refusals            UInt64            refusal in words, and how many so far)
Trip Record/Code            String           (where the gateway keeps trip records: the
Trip Record/Id              String            latest record's trip code and id, sent in a
                                              DDATA when it is kept; null before one)
Info/Protocol, Info/Line    String
Info/Node                   UInt32
==========================  ========  =====  =========================================

A value the gateway does not serve (stale, never read, not given by the
drive: the gateway's served view decides) is null. The values are read
from the drive as served (:class:`~sj300_async.gateway.ServedValues`, built
once per sample for every northbound), not from another door's wire format. Aliases are unique
across the edge node: device *k* (1-based, the gateway's drive order)
numbers its metrics from ``k << 16``; the node's own metrics are below
65536. The order of metrics and their aliases are fixed for a
configuration, so they are the same at every birth.
"""

from __future__ import annotations

import functools
import operator
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from ...profiles import ParameterSpec
from .. import DIRECTION_WORDS as SERVED_DIRECTION_WORDS
from .. import GatewayDrive, ServedValues
from ._payload import BOOLEAN, DOUBLE, STRING, UINT32, UINT64, MetricDef, Property

__all__ = [
    "DIRECTION_WORDS",
    "LAST_REFUSAL",
    "TRIP_RECORD",
    "Device",
    "DeviceFlags",
    "DeviceMetric",
    "Writes",
    "device_id",
]

#: Direction's words, as read and as written: the gateway's own (stop, forward, reverse).
DIRECTION_WORDS: Final = tuple(SERVED_DIRECTION_WORDS.values())
LAST_REFUSAL: Final = "Control/Last Refusal"
#: The first of the two trip record metrics (its code, then its id).
TRIP_RECORD: Final = "Trip Record/Code"


@dataclass(frozen=True, slots=True)
class DeviceFlags:
    """What a device's metrics read beside the served values, when its message goes out."""

    #: The Sparkplug client holds the drive's lease.
    lease: bool = False
    #: A lapsed lease's stop is not confirmed yet (the drive as served says so).
    lapse_pending: bool = False


#: Reads a metric's value from a sample's served values (and the device's flags),
#: None when unknown.
Reader = Callable[[ServedValues, DeviceFlags], object]


class Writes:
    """What a written metric asks for."""

    FREQUENCY: Final = "frequency"
    DIRECTION: Final = "direction"
    LEASE: Final = "lease"
    STOP: Final = "stop"
    PARAMETER: Final = "parameter"


@dataclass(frozen=True, slots=True)
class DeviceMetric:
    """One metric of a device: its definition, how it is read, and what writing it does."""

    definition: MetricDef
    #: How its value is read. A constant metric's reader is the layout's shared marker:
    #: its value is the device's own (``Device.values``), not this reader's.
    read: Reader
    #: What a DCMD writing it asks for (a :class:`Writes` word), None: read-only.
    write: str | None = None
    #: The parameter code of a ``Parameters/<code>`` metric.
    code: str | None = None


def device_id(line: str, node: int) -> str:
    """The device id of drive *node* of line *line*: ``line1-3``."""
    return f"{line}-{node}"


# The readers and properties below are made once for every device (functools.cache):
# each device's own came to some 2 KiB a drive at 2,048 (issue 44).


@functools.cache
def _unit(unit: str) -> tuple[Property, ...]:
    return (Property("engUnit", STRING, unit),) if unit else ()


@dataclass(frozen=True, slots=True)
class _Field:
    """Reads a field of the state (Device.values reads them all in one call)."""

    name: str

    def __call__(self, values: ServedValues, flags: DeviceFlags) -> object:
        return getattr(values, self.name)


@dataclass(frozen=True, slots=True)
class _Constant:
    """The same value at every sample (Device.values starts from them)."""

    value: object

    def __call__(self, values: ServedValues, flags: DeviceFlags) -> object:
        return self.value


@functools.cache
def _field(name: str) -> Reader:
    return _Field(name)


@functools.cache
def _parameter(code: str) -> Reader:
    def read(values: ServedValues, flags: DeviceFlags) -> object:
        reading = values.parameters.get(code)
        return None if reading is None else reading.value

    return read


def _constant(value: object) -> Reader:
    return _Constant(value)


def _lease(values: ServedValues, flags: DeviceFlags) -> object:
    return flags.lease


def _lapse_pending(values: ServedValues, flags: DeviceFlags) -> object:
    return flags.lapse_pending


def _trip_code(values: ServedValues, flags: DeviceFlags) -> object:
    return None if values.trip is None else values.trip.code


def _trip_meaning(values: ServedValues, flags: DeviceFlags) -> object:
    return None if values.trip is None else values.trip.meaning


def _never(values: ServedValues, flags: DeviceFlags) -> object:
    return False


def _parameter_properties(spec: ParameterSpec) -> tuple[Property, ...]:
    return _properties(spec.unit, float(spec.minimum), float(spec.maximum), spec.name)


@functools.cache
def _properties(unit: str, low: float, high: float, name: str) -> tuple[Property, ...]:
    return (
        *_unit(unit),
        Property("engLow", DOUBLE, low),
        Property("engHigh", DOUBLE, high),
        Property("Documentation", STRING, name),
    )


#: A metric as a device is built of it: name, datatype, properties, reader, write, code.
_Row = tuple[str, int, tuple[Property, ...], Reader, str | None, str | None]
#: The reader of every constant metric in a layout (each device keeps its own values).
_CONSTANT: Final = _Constant(None)
#: Layouts kept: one per distinct set of metrics (a profile, its grants and parameters);
#: a plant has a handful, a reload may add some.
_LAYOUTS: Final = 64


@dataclass(frozen=True, slots=True)
class _Layout:
    """The metrics of every device built of the same rows, made once and shared."""

    #: Aliases counted from 0: a device adds its own base.
    metrics: tuple[DeviceMetric, ...]
    definitions: tuple[MetricDef, ...]
    #: values() reads the served fields in one call (the attrgetter of their names, each
    #: value kept with its metric's index), the constants are the device's template, and
    #: only the rest is called one by one.
    field_index: tuple[int, ...]
    pick: Callable[[ServedValues], tuple[object, ...]]
    called: tuple[tuple[int, Reader], ...]
    indices: Mapping[str, int]
    refusal_index: int | None
    record_index: int | None


@functools.lru_cache(maxsize=_LAYOUTS)
def _layout(rows: tuple[_Row, ...]) -> _Layout:
    metrics = tuple(
        DeviceMetric(MetricDef(name, i, datatype, properties), read, write, code)
        for i, (name, datatype, properties, read, write, code) in enumerate(rows)
    )
    fields = [(i, m.read) for i, m in enumerate(metrics) if isinstance(m.read, _Field)]
    names = [m.definition.name for m in metrics]
    return _Layout(
        metrics=metrics,
        definitions=tuple(m.definition for m in metrics),
        field_index=tuple(i for i, _ in fields),
        pick=operator.attrgetter(*(f.name for _, f in fields), "online"),  # 2 at least
        called=tuple(
            (i, m.read)
            for i, m in enumerate(metrics)
            if not isinstance(m.read, (_Field, _Constant))
        ),
        indices=MappingProxyType({name: index for index, name in enumerate(names)}),
        refusal_index=names.index(LAST_REFUSAL) if LAST_REFUSAL in names else None,
        record_index=names.index(TRIP_RECORD) if TRIP_RECORD in names else None,
    )


class Device:
    """One drive as a device (see the module docstring)."""

    def __init__(self, drive: GatewayDrive, ordinal: int, *, trips: bool = False) -> None:
        self.drive = drive
        self.id = device_id(*drive.key)
        line, node, profile = drive.line, drive.node, drive.profile
        control = line.control_allowed(node)
        granted = line.writable_parameters(node)
        measures = profile.capabilities.measures
        rows: list[_Row] = [
            ("Output Frequency", DOUBLE, _unit("Hz"), _field("output_frequency_hz"), None, None),
            (
                "Frequency Command",
                DOUBLE,
                _unit("Hz"),
                _field("set_frequency_hz"),
                Writes.FREQUENCY if control else None,
                None,
            ),
            ("Output Current", DOUBLE, _unit("A"), _field("output_current_a"), None, None),
            ("Output Voltage", DOUBLE, _unit("V"), _field("output_voltage_v"), None, None),
        ]
        if "power_kw" in measures:
            rows.append(("Output Power", DOUBLE, _unit("kW"), _field("power_kw"), None, None))
        if "output_torque_percent" in measures:
            rows.append(
                ("Output Torque", DOUBLE, _unit("%"), _field("output_torque_percent"), None, None)
            )
        rows += [
            (
                "Direction",
                STRING,
                (),
                _field("direction"),
                Writes.DIRECTION if control else None,
                None,
            ),
            ("Running", BOOLEAN, (), _field("running"), None, None),
            ("Tripped", BOOLEAN, (), _field("tripped"), None, None),
            ("State", STRING, (), _field("state"), None, None),
            ("Trip", STRING, (), _trip_code, None, None),
            ("Trip Meaning", STRING, (), _trip_meaning, None, None),
            ("Lapse Pending", BOOLEAN, (), _lapse_pending, None, None),
        ]
        for code in dict.fromkeys((*line.parameters, *sorted(granted))):
            spec = profile.parameters.spec(code)
            rows.append(
                (
                    sys.intern(f"Parameters/{code}"),
                    DOUBLE,
                    _parameter_properties(spec),
                    _parameter(code),
                    Writes.PARAMETER if code in granted else None,
                    code,
                )
            )
        if control:
            rows.append(("Control/Lease", BOOLEAN, (), _lease, Writes.LEASE, None))
            rows.append(("Control/Stop", BOOLEAN, (), _never, Writes.STOP, None))
        #: Something can be written: a refusal has a metric to be told on.
        self.writable = control or bool(granted)
        if self.writable:
            rows.append((LAST_REFUSAL, STRING, (), _constant(None), None, None))
            rows.append(("Control/Refusals", UINT64, (), _constant(0), None, None))
        if trips:  # the gateway keeps trip records: the latest one's, when one is kept
            rows.append((TRIP_RECORD, STRING, (), _constant(None), None, None))
            rows.append(("Trip Record/Id", STRING, (), _constant(None), None, None))
        rows += [
            ("Info/Protocol", STRING, (), _constant(drive.profile.name), None, None),
            ("Info/Line", STRING, (), _constant(line.name), None, None),
            ("Info/Node", UINT32, (), _constant(node), None, None),
        ]
        self._base = ordinal << 16
        # The metrics themselves are the layout's, shared by every device built alike: a
        # device keeps its alias base and its constants' values (issue 44: a device's own
        # 18 metrics, their definitions and aliases took 2.8 KiB a drive).
        self._layout = _layout(tuple(
            (name, datatype, properties, _CONSTANT if isinstance(read, _Constant) else read,
             write, code)
            for name, datatype, properties, read, write, code in rows
        ))  # fmt: skip
        self._template: list[object] = [
            read.value if isinstance(read, _Constant) else None for _, _, _, read, _, _ in rows
        ]

    @property
    def metrics(self) -> Sequence[DeviceMetric]:
        """Its metrics, in alias order (a definition's alias is from :attr:`alias_base`)."""
        return self._layout.metrics

    @property
    def definitions(self) -> Sequence[MetricDef]:
        """What its births say of its metrics (aliases from :attr:`alias_base`)."""
        return self._layout.definitions

    @property
    def alias_base(self) -> int:
        """What its metrics' aliases count from: ``ordinal << 16``."""
        return self._base

    def by_alias(self, alias: int) -> DeviceMetric | None:
        """The metric of alias *alias*, None: none of this device's."""
        index = alias - self._base
        metrics = self._layout.metrics
        return metrics[index] if 0 <= index < len(metrics) else None

    def by_name(self, name: str) -> DeviceMetric | None:
        """The metric named *name*, None: none of this device's."""
        index = self._layout.indices.get(name)
        return None if index is None else self._layout.metrics[index]

    def values(
        self,
        values: ServedValues,
        flags: DeviceFlags,
        refusal: tuple[str, int] | None,
        record: tuple[str | None, str] | None = None,
    ) -> list[object]:
        """Every metric's value in the served *values*, in the metrics' order.

        *flags*: the lease and a pending lapse; *refusal*: the latest refusal in
        words and the count so far (None: none yet); *record*: the latest trip
        record's code and id (None: none yet).
        """
        layout = self._layout
        out = self._template.copy()
        for i, value in zip(layout.field_index, layout.pick(values), strict=False):  # not online
            out[i] = value
        for i, read in layout.called:
            out[i] = read(values, flags)
        if layout.refusal_index is not None and refusal is not None:
            out[layout.refusal_index], out[layout.refusal_index + 1] = refusal
        if layout.record_index is not None and record is not None:
            out[layout.record_index], out[layout.record_index + 1] = record
        return out
