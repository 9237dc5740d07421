"""How each drive variable of the address space is read from a snapshot: its sources.

A source is a variable's reader (its value and read time from a
:class:`~sj300_async.profiles.DriveSnapshot`), its group's stamp (what
changes when the group was read again: the server pushes a group only then)
and the read group whose served quality is its own (None: a parameter's, or
the verdict's own rule). :mod:`._model` binds one to each variable; every
drive's variables share these functions, made once here, not per drive (a
closure and a lambda each was 2.4 KiB a drive, 5 MiB at 2,048).

Split from :mod:`._model` (which builds the address space) to keep each
module to one job.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Final

from asyncua import ua

from ...profiles import DriveSnapshot, ReadGroup, Trip

__all__ = [
    "ACTIVE_TRIP",
    "CURRENT",
    "DIRECTION",
    "FREQUENCY",
    "ONLINE",
    "POWER",
    "RUNNING",
    "SETPOINT",
    "STATE",
    "TORQUE",
    "TRIPPED",
    "TRIP_COUNT",
    "TRIP_SOURCES",
    "VOLTAGE",
    "Reader",
    "Source",
    "Stamp",
    "parameter_source",
]

Reader = Callable[[DriveSnapshot], tuple[object, float]]
#: What changes when a group's values were read again (a read time, or a pair of them).
Stamp = Callable[[DriveSnapshot], object]
#: How a variable is read: its reader, its group's stamp, and the read group whose
#: served quality is its own (None: a parameter's, or the verdict's own rule).
Source = tuple[Reader, Stamp, ReadGroup | None]


def _status_at(s: DriveSnapshot) -> object:
    return s.status_at


def _status_or_trips_at(s: DriveSnapshot) -> object:
    # The state in words and the active trip name the trip the history read found.
    return s.status_at, s.trips_at


def _monitor_at(s: DriveSnapshot) -> object:
    return s.monitor_at


def _trips_at(s: DriveSnapshot) -> object:
    return s.trips_at


def _sample_at(s: DriveSnapshot) -> object:
    return s.taken_at


def status_source(get: Callable[[DriveSnapshot], object]) -> Source:
    return (lambda s: (get(s), s.status_at)), _status_at, "status"


def monitor_source(get: Callable[[DriveSnapshot], object]) -> Source:
    return (lambda s: (get(s), s.monitor_at)), _monitor_at, "monitor"


def trip_field_source(get: Callable[[Trip], object]) -> Source:
    """One field of every trip record, newest first (None until the history is read)."""

    def read(s: DriveSnapshot) -> tuple[object, float]:
        if s.trips is None:
            return None, s.trips_at
        return [get(record) for record in s.trips.records], s.trips_at

    return read, _trips_at, "trips"


@functools.cache  # one per code, for every drive (see FREQUENCY)
def parameter_source(code: str) -> Source:
    def read(s: DriveSnapshot) -> tuple[object, float]:
        reading = s.parameters.get(code)
        if reading is not None:
            return reading.value, reading.at
        if code in s.unavailable_parameters:
            return None, s.taken_at
        return None, -math.inf

    # Its group is the parameter itself (the binding says which).
    return read, lambda s: read(s)[1], None


def _read_direction(s: DriveSnapshot) -> tuple[object, float]:
    direction: int | None = None if s.direction is None else int(s.direction)
    return direction, s.direction_at


def _read_active_trip(s: DriveSnapshot) -> tuple[object, float]:
    if s.tripped is None:
        return None, s.status_at
    return (str(s.trip) if s.tripped and s.trip is not None else ""), s.status_at


#: The trip history's arrays: name, element type, a record's value, unit, description.
TRIP_FIELDS: Final[
    tuple[tuple[str, ua.VariantType, Callable[[Trip], object], str, str], ...]
] = (
    ("TripCodes", ua.VariantType.String, lambda t: t.code, "",
     "each trip's code, newest first"),
    ("TripMeanings", ua.VariantType.String, lambda t: t.meaning, "",
     "what each trip means, newest first (null: a code the manual does not list)"),
    ("TripOutputFrequencies", ua.VariantType.Double, lambda t: t.output_frequency_hz, "Hz",
     "the output frequency at each trip, newest first (NaN: not recorded)"),
    ("TripOutputCurrents", ua.VariantType.Double, lambda t: t.output_current_a, "A",
     "the output current at each trip, newest first (NaN: not recorded)"),
    ("TripOutputVoltages", ua.VariantType.Double, lambda t: t.output_voltage_v, "V",
     "the output voltage at each trip, newest first (NaN: not recorded)"),
)  # fmt: skip
DIRECTION: Final[Source] = (_read_direction, lambda s: s.direction_at, "direction")
# The state in words and the active trip: read with the status, judged by it.
ACTIVE_TRIP: Final[Source] = (_read_active_trip, _status_or_trips_at, "status")
STATE: Final[Source] = (
    (lambda s: (s.state_text(), s.status_at)),
    _status_or_trips_at,
    "status",
)
ONLINE: Final[Source] = ((lambda s: (s.online, s.taken_at)), _sample_at, None)
SETPOINT: Final[Source] = (
    (lambda s: (s.set_frequency_hz, s.set_frequency_at)),
    lambda s: s.set_frequency_at,
    "set_frequency",
)
# Every drive's variables read through the same functions: made once, not per drive
# (a closure each, and a lambda each, was 2.4 KiB a drive, 5 MiB at 2,048).
FREQUENCY: Final = monitor_source(lambda s: s.output_frequency_hz)
CURRENT: Final = monitor_source(lambda s: s.output_current_a)
VOLTAGE: Final = monitor_source(lambda s: s.output_voltage_v)
POWER: Final = monitor_source(lambda s: s.power_kw)
TORQUE: Final = monitor_source(lambda s: s.output_torque_percent)
RUNNING: Final = status_source(lambda s: s.running)
TRIPPED: Final = status_source(lambda s: s.tripped)
TRIP_SOURCES: Final = tuple(
    (name, vtype, trip_field_source(get), unit, description)
    for name, vtype, get, unit, description in TRIP_FIELDS
)
TRIP_COUNT: Final[Source] = (
    (lambda s: (s.trips.total_count if s.trips else None, s.trips_at)),
    _trips_at,
    "trips",
)
