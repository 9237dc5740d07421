"""Decoders from reply data to typed results (frozen, slotted, units in field names)."""

from __future__ import annotations

import enum
import struct
from binascii import a2b_hex
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final, TypeVar

from ..wire import Direction, RemoteProtocolError, slot_setters, unfrozen_twin
from ._codes import StatusA, StatusB, StatusC, TripCode, TripStatusB, TripStatusC
from ._constants import MONITOR_DATA_LEN, STATUS_DATA_LEN, TRIP_HISTORY_DATA_LEN
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


def _malformed(what: str, data: bytes) -> RemoteProtocolError:
    return RemoteProtocolError(f"malformed {what} data: {data!r}")


# Splitting into 8-character fields with one struct call (in C) is faster than
# slicing in a loop (the codec benchmark times the decoders).
# (The monitor's items 5-6 are hex, read apart; item 11 is reserved.)
_MONITOR_FIELDS: Final = struct.Struct("8s" * 4 + "16x" + "8s" * 4 + "8x" + "8s" * 2)
_TRIP_FIELDS: Final = struct.Struct("8s" * 55)
# Monitor items 5 and 6 after a2b_hex: two big-endian 32-bit words.
_TERMINAL_WORDS: Final = struct.Struct(">II")

# How the decoders check their data: bytes.isdigit() (ASCII digits only) on the
# decimal fields, and the full pattern only when that fails (a negative value
# has a minus sign). a2b_hex() refuses anything but hex digits in the monitor's
# two hex items. Once the characters are known to be good, int() and float()
# read exactly the values the pattern allows. float() is the cheaper of the
# two, and it gives the same result for a scaled field as int() would: an
# 8-digit integer is exact in a float, so x / 100 rounds the same either way,
# and `or 0.0` turns the -0.0 that "-0000000" gives into int()'s 0.0.
_MONITOR_PATTERN: Final = DATA_PATTERNS[MONITOR_DATA_LEN]
_TRIP_HISTORY_PATTERN: Final = DATA_PATTERNS[TRIP_HISTORY_DATA_LEN]

_E = TypeVar("_E", bound=enum.Enum)


def _lookup(cls: type[_E]) -> Callable[[int], _E]:
    """A fast int -> member function: a dict for known codes, the enum for the rest."""
    members: dict[int, _E] = {m.value: m for m in cls}

    def lookup(value: int) -> _E:
        member = members.get(value)
        return member if member is not None else cls(value)

    return lookup


_F = TypeVar("_F", bound=enum.IntFlag)


def _flag_lookup(cls: type[_F], cached_below: int) -> tuple[dict[int, _F], Callable[[int], _F]]:
    """A memoizing int -> flag function (IntFlag's own constructor is slow), and its memo.

    Values with bits the manual does not assign are kept (never dropped) but
    built without the enum's constructor: enum.Flag caches every pseudo-member
    it makes, so a line delivering ever new stray bits would grow memory
    without bound. Known-bit combinations are at most ``cached_below``. The
    decoders look in the memo themselves first (a call less).
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

    return cache, lookup


def _two_digit_table(lookup: Callable[[int], _E]) -> dict[bytes, _E]:
    """Each two-digit field b"00".."99" -> its member (an unknown code as the enum keeps it)."""
    return {b"%02d" % value: lookup(value) for value in range(100)}


_INPUT_MONITOR, _input_monitor = _flag_lookup(InputMonitor, 1 << 9)
_OUTPUT_TERMINAL, _output_terminal = _flag_lookup(OutputTerminal, 1 << 6)
_, _trip_status_b = _flag_lookup(TripStatusB, 1 << 8)
_status_a = _lookup(StatusA)
_status_b = _lookup(StatusB)
_status_c = _lookup(StatusC)
_trip_status_c = _lookup(TripStatusC)
_direction = _lookup(Direction)
# Fields as they arrive (8 characters) -> member, for the codes the manual
# lists; any other value goes through int() and the lookups above.
_DIRECTION_FIELDS: Final = {b"%08d" % m.value: m for m in Direction}
_STATUS_A_FIELDS: Final = {b"%08d" % m.value: m for m in StatusA}
_TRIP_STATUS_C_FIELDS: Final = {b"%08d" % m.value: m for m in TripStatusC}
_STATUS_A_CHARS: Final = _two_digit_table(_status_a)
_STATUS_B_CHARS: Final = _two_digit_table(_status_b)
_STATUS_C_CHARS: Final = _two_digit_table(_status_c)

# The decoders build their results without the generated __init__ (every value
# is made by the decoder itself): through the slots' setters for a few fields,
# through an unfrozen twin for many (see slot_setters and unfrozen_twin).
_new = object.__new__


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
    if type(data) is not bytes:
        data = bytes(data)
    if len(data) != STATUS_DATA_LEN or not data.isdigit():  # bytes.isdigit() is ASCII-only
        raise _malformed("status", data)
    return _decode_status(data)


def _decode_status(data: bytes) -> InverterStatus:
    # A drive's status is one of a few dozen combinations and a poll reads it over
    # and over: each is decoded once and the frozen object shared (bounded: the
    # table starts over when full, as a line of ever-new statuses would fill it).
    status = _STATUSES.get(data)
    if status is None:
        if len(_STATUSES) >= _STATUSES_KEPT:
            _STATUSES.clear()
        status = _new(InverterStatus)
        _set_status_a(status, _STATUS_A_CHARS[data[0:2]])
        _set_status_b(status, _STATUS_B_CHARS[data[2:4]])
        _set_status_c(status, _STATUS_C_CHARS[data[4:6]])
        _STATUSES[data] = status  # only once whole
    return status


#: Decoded statuses by their 8 characters (see _decode_status), and how many are kept.
_STATUSES: Final[dict[bytes, InverterStatus]] = {}
_STATUSES_KEPT: Final = 512


_set_status_a, _set_status_b, _set_status_c = slot_setters(InverterStatus)


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
    if type(data) is not bytes:
        data = bytes(data)
    if len(data) != MONITOR_DATA_LEN or (
        not (data[:32].isdigit() and data[48:].isdigit()) and not _MONITOR_PATTERN.fullmatch(data)
    ):
        raise _malformed("monitor", data)
    try:
        inputs, outputs = _TERMINAL_WORDS.unpack(a2b_hex(data[32:48]))
    except ValueError:  # binascii.Error: not hex
        raise _malformed("monitor", data) from None
    freq, current, direction, pid, conv, torque, voltage, power, run_h, on_h = (
        _MONITOR_FIELDS.unpack(data)
    )
    m = _UnfrozenMonitorData()
    m.output_frequency_hz = float(freq) / 100 or 0.0
    m.output_current_a = float(current) / 10 or 0.0
    member = _DIRECTION_FIELDS.get(direction)
    m.direction = member if member is not None else _direction(int(direction))
    m.pid_feedback_percent = float(pid) / 100 or 0.0
    input_flags = _INPUT_MONITOR.get(inputs)
    m.input_terminals = input_flags if input_flags is not None else _input_monitor(inputs)
    output_flags = _OUTPUT_TERMINAL.get(outputs)
    m.output_terminals = output_flags if output_flags is not None else _output_terminal(outputs)
    m.frequency_conversion = float(conv) / 100 or 0.0
    m.output_torque_percent = int(torque)
    m.output_voltage_v = float(voltage) / 10 or 0.0
    m.power_kw = float(power) / 10 or 0.0
    m.run_time_h = int(run_h)
    m.power_on_time_h = int(on_h)
    m.__class__ = MonitorData
    return m  # type: ignore[no-any-return]  # (a cast() would cost a call)


# The checks are cheap next to the decode: the path after the parser (which
# has checked every character) shares them rather than skipping them.
_decode_monitor = decode_monitor
_UnfrozenMonitorData: Final[Any] = unfrozen_twin(MonitorData)


@dataclass(frozen=True, slots=True)
class TripRecord:
    """One trip-history record: the cause and the drive's state at the moment of the trip."""

    #: The E-code number (7 = E07), as it came; :attr:`trip_code` gives its meaning.
    trip_factor: int
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

    @property
    def trip_code(self) -> TripCode:
        """The trip factor as a :class:`TripCode` (``.description`` is its meaning).

        A number the codec does not list is kept (``UNKNOWN_<n>``).
        """
        return TripCode(self.trip_factor)


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
    if type(data) is not bytes:
        data = bytes(data)
    if len(data) != TRIP_HISTORY_DATA_LEN or (
        not data.isdigit() and not _TRIP_HISTORY_PATTERN.fullmatch(data)
    ):
        raise _malformed("trip history", data)
    fields = iter(_TRIP_FIELDS.unpack(data))
    total_count = int(next(fields))
    records = []
    # zip() of one iterator nine times: the fields nine by nine, one record each.
    for factor, status_a, status_b, status_c, hz, run_h, amps, volts, on_h in zip(
        *[fields] * _TRIP_RECORD_FIELDS, strict=True
    ):
        bits = int(status_b)
        if bits < 0:
            raise RemoteProtocolError(f"negative status B bit field in trip history: {data!r}")
        record = _UnfrozenTripRecord()
        record.trip_factor = int(factor)
        member_a = _STATUS_A_FIELDS.get(status_a)
        record.status_a = member_a if member_a is not None else _status_a(int(status_a))
        record.status_b = _trip_status_b(bits)
        member_c = _TRIP_STATUS_C_FIELDS.get(status_c)
        record.status_c = member_c if member_c is not None else _trip_status_c(int(status_c))
        record.output_frequency_hz = float(hz) / 10 or 0.0
        record.run_time_h = int(run_h)
        record.output_current_a = float(amps) / 10 or 0.0
        record.output_voltage_v = float(volts) / 10 or 0.0
        record.power_on_time_h = int(on_h)
        record.__class__ = TripRecord
        records.append(record)
    history = _new(TripHistory)
    _set_total_count(history, total_count)
    _set_records(history, tuple(records))
    return history


_decode_trip_history = decode_trip_history  # (see _decode_monitor)
_UnfrozenTripRecord: Final[Any] = unfrozen_twin(TripRecord)
_set_total_count, _set_records = slot_setters(TripHistory)


def decode_parameter_value(data: bytes) -> int:
    """Decode the 8 characters after ACK of a command 06 reply to the raw integer.

    Raises:
        RemoteProtocolError: the data is not an 8-character decimal field.
    """
    if type(data) is not bytes:
        data = bytes(data)
    if len(data) == 8 and data.isdigit():  # the usual case; a negative value needs the pattern
        return int(data)
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
