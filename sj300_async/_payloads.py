"""Decoders from reply data to typed results (frozen, slotted, units in field names)."""

from __future__ import annotations

import enum
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, TypeVar

from ._codes import Direction, StatusA, StatusB, StatusC, TripStatusB, TripStatusC
from ._constants import MONITOR_DATA_LEN, STATUS_DATA_LEN, TRIP_HISTORY_DATA_LEN
from ._errors import RemoteProtocolError
from ._parser import DATA_PATTERNS, DECIMAL_FIELD
from ._terminals import InputMonitor, OutputTerminal

__all__ = [
    "InverterStatus",
    "MonitorData",
    "TripHistory",
    "TripRecord",
    "decode_can_store",
    "decode_monitor",
    "decode_parameter_value",
    "decode_status",
    "decode_trip_history",
]

_TRIP_RECORDS: Final = 6
_TRIP_RECORD_FIELDS: Final = 9


def _check(data: bytes, length: int, what: str) -> None:
    if len(data) != length or not DATA_PATTERNS[length].fullmatch(data):
        raise RemoteProtocolError(f"malformed {what} data: {data!r}")


# Splitting into 8-character fields with one struct call is about three times
# faster than slicing in a loop. The callers have checked every field against
# its pattern, so int() cannot see whitespace, '+' or '_' (which it accepts).
_MONITOR_FIELDS: Final = struct.Struct("8s" * 4 + "16x" + "8s" * 7)
_TRIP_FIELDS: Final = struct.Struct("8s" * 55)

_E = TypeVar("_E", bound=enum.Enum)


def _lookup(cls: type[_E]) -> Callable[[int], _E]:
    """A fast int -> member function: a dict for known codes, the enum for the rest."""
    members: dict[int, _E] = {m.value: m for m in cls}

    def lookup(value: int) -> _E:
        member = members.get(value)
        return member if member is not None else cls(value)

    return lookup


_F = TypeVar("_F", bound=enum.IntFlag)


def _flag_lookup(cls: type[_F], cached_below: int) -> Callable[[int], _F]:
    """A memoizing int -> flag function (IntFlag's own constructor is slow).

    Values with bits the manual does not assign are kept (never dropped) but
    built without the enum's constructor: enum.Flag caches every pseudo-member
    it makes, so a line delivering ever new stray bits would grow memory
    without bound. Known-bit combinations are at most ``cached_below``.
    """
    cache: dict[int, _F] = {}

    def lookup(value: int) -> _F:
        flag = cache.get(value)
        if flag is not None:
            return flag
        if 0 <= value < cached_below:
            flag = cache[value] = cls(value)
            return flag
        stray = int.__new__(cls, value)
        stray._value_ = value
        stray._name_ = None
        return stray

    return lookup


_input_monitor = _flag_lookup(InputMonitor, 1 << 9)
_output_terminal = _flag_lookup(OutputTerminal, 1 << 6)
_trip_status_b = _flag_lookup(TripStatusB, 1 << 8)
_status_a = _lookup(StatusA)
_status_b = _lookup(StatusB)
_status_c = _lookup(StatusC)
_trip_status_c = _lookup(TripStatusC)
_direction = _lookup(Direction)


@dataclass(frozen=True, slots=True)
class InverterStatus:
    """Command 04: status A, B and C."""

    a: StatusA  #: operating state
    b: StatusB  #: stopped / running / tripped
    c: StatusC  #: what the output is doing

    @property
    def tripped(self) -> bool:
        """True when the drive is in a trip."""
        return self.a == StatusA.TRIP or self.b == StatusB.TRIPPED


def decode_status(data: bytes) -> InverterStatus:
    """Decode the 8 characters of command 04.

    Raises:
        RemoteProtocolError: the data is not 8 decimal digits.
    """
    _check(data, STATUS_DATA_LEN, "status")
    return _decode_status(data)


def _decode_status(data: bytes) -> InverterStatus:
    return InverterStatus(
        _status_a(int(data[0:2])), _status_b(int(data[2:4])), _status_c(int(data[4:6]))
    )


@dataclass(frozen=True, slots=True)
class MonitorData:
    """Command 03: the monitor block (13 items)."""

    output_frequency_hz: float  #: item 1
    output_current_a: float  #: item 2
    direction: Direction  #: item 3
    pid_feedback_percent: float  #: item 4
    input_terminals: InputMonitor  #: item 5, physical input terminal states
    output_terminals: OutputTerminal  #: item 6, output terminal states
    frequency_conversion: float  #: item 7, output frequency x conversion factor (B086)
    output_torque_percent: int  #: item 8
    output_voltage_v: float  #: item 9
    power_kw: float  #: item 10
    run_time_h: int  #: item 12, accumulated RUN time
    power_on_time_h: int  #: item 13, accumulated power-ON time


def decode_monitor(data: bytes) -> MonitorData:
    """Decode the 104 characters of command 03.

    Raises:
        RemoteProtocolError: the data is not 104 characters of the right kinds.
    """
    _check(data, MONITOR_DATA_LEN, "monitor")
    return _decode_monitor(data)


def _decode_monitor(data: bytes) -> MonitorData:
    freq, current, direction, pid, conv, torque, voltage, power, _reserved, run_h, on_h = map(
        int, _MONITOR_FIELDS.unpack(data)
    )
    return MonitorData(
        output_frequency_hz=freq / 100,
        output_current_a=current / 10,
        direction=_direction(direction),
        pid_feedback_percent=pid / 100,
        input_terminals=_input_monitor(int(data[32:40], 16)),
        output_terminals=_output_terminal(int(data[40:48], 16)),
        frequency_conversion=conv / 100,
        output_torque_percent=torque,
        output_voltage_v=voltage / 10,
        power_kw=power / 10,
        run_time_h=run_h,
        power_on_time_h=on_h,
    )


@dataclass(frozen=True, slots=True)
class TripRecord:
    """One trip-history record: the cause and the drive's state at the moment of the trip."""

    trip_factor: int  #: the E-code number (7 = E07); unknown codes kept as numbers
    status_a: StatusA  #: operating state at trip
    status_b: TripStatusB  #: hardware causes (bit field)
    status_c: TripStatusC  #: what the output was doing
    output_frequency_hz: float
    run_time_h: int
    output_current_a: float
    output_voltage_v: float
    power_on_time_h: int

    @property
    def is_empty(self) -> bool:
        """True for an unused slot (no trip recorded there)."""
        return self.trip_factor == 0

    @property
    def error_code(self) -> str:
        """The trip as the drive's display shows it, e.g. ``"E07"``."""
        return f"E{self.trip_factor:02d}"


@dataclass(frozen=True, slots=True)
class TripHistory:
    """Command 05: total trip count and the six most recent records, newest first."""

    total_count: int
    records: tuple[TripRecord, ...]

    @property
    def trips(self) -> tuple[TripRecord, ...]:
        """The records that hold a trip (empty slots left out)."""
        return tuple(r for r in self.records if not r.is_empty)


def decode_trip_history(data: bytes) -> TripHistory:
    """Decode the 440 characters of command 05.

    Raises:
        RemoteProtocolError: the data is not 440 characters of decimal fields.
    """
    _check(data, TRIP_HISTORY_DATA_LEN, "trip history")
    return _decode_trip_history(data)


def _decode_trip_history(data: bytes) -> TripHistory:
    values = list(map(int, _TRIP_FIELDS.unpack(data)))
    if any(values[3 + i * _TRIP_RECORD_FIELDS] < 0 for i in range(_TRIP_RECORDS)):
        raise RemoteProtocolError(f"negative status B bit field in trip history: {data!r}")
    records = []
    for i in range(_TRIP_RECORDS):
        f = values[1 + i * _TRIP_RECORD_FIELDS : 1 + (i + 1) * _TRIP_RECORD_FIELDS]
        records.append(
            TripRecord(
                trip_factor=f[0],
                status_a=_status_a(f[1]),
                status_b=_trip_status_b(f[2]),
                status_c=_trip_status_c(f[3]),
                output_frequency_hz=f[4] / 10,
                run_time_h=f[5],
                output_current_a=f[6] / 10,
                output_voltage_v=f[7] / 10,
                power_on_time_h=f[8],
            )
        )
    return TripHistory(values[0], tuple(records))


def decode_parameter_value(data: bytes) -> int:
    """Decode the 8 characters after ACK of a command 06 reply to the raw integer.

    Raises:
        RemoteProtocolError: the data is not an 8-character decimal field.
    """
    if not DECIMAL_FIELD.fullmatch(data):
        raise RemoteProtocolError(f"malformed parameter value: {data!r}")
    return int(data)


def decode_can_store(data: bytes) -> bool:
    """Decode the 2 characters after ACK of a command 09 reply.

    Raises:
        RemoteProtocolError: the data is neither ``00`` nor ``01``.
    """
    if data == b"01":
        return True
    if data == b"00":
        return False
    raise RemoteProtocolError(f"command 09 reply must be 00 or 01, got {data!r}")
