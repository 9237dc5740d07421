"""The Modbus register map: what each holding register of a drive's unit holds.

Sans-IO: :class:`RegisterMap` turns a read of ``count`` registers at
``address`` into register values from a :class:`~._state.DriveState` (or a
Modbus exception code), and a write into a :class:`WriteRequest` for
:mod:`._control` to judge and carry out. docs/GATEWAY.md prints the map;
:func:`describe` generates it, so the two cannot drift.

Decisions:

- One map, read with function 3 (holding registers) or 4 (input registers),
  written with 6 or 16; addresses are the PDU's, 0-based.
- Every value is an integer count of a documented step (0.01 Hz, 0.1 A...).
  Two-register values are 32-bit, high word first (big-endian word order,
  "ABCD"); signed values are two's complement; a value too large for its
  registers saturates (never wraps into a plausible wrong number).
- A read succeeds whole or not at all: any register of it unknown (0x02),
  any data in it older than the staleness limit or never read (0x0B,
  "gateway target device failed to respond"). The identity block
  (online, sample age) is always served, so a SCADA can see why.
- A parameter is served at ``base(group) + 2 * number`` (A004 at 12008,
  Pr.7 at 30014) when the line polls it; it is counted in its own setting
  increment (F002 = 30.00 s reads 3000), 32-bit. A parameter is written
  whole: both registers in one function-16 request.
- One write request changes one thing (a heartbeat, a command, the set
  frequency, or one parameter); a write spanning several is refused (0x03).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Final

from ..fr700 import Fr700Monitor, Fr700Status, Fr700StatusBits
from ..sj300 import InverterStatus, MonitorData, TripHistory
from ._state import DriveState

__all__ = [
    "PARAMETER_BASES",
    "Command",
    "Exc",
    "Field",
    "Heartbeat",
    "ParameterWrite",
    "RegisterMap",
    "SetFrequency",
    "WriteRequest",
    "describe",
    "parameter_address",
]


class Exc(enum.IntEnum):
    """The Modbus exception codes the gateway answers with."""

    ILLEGAL_FUNCTION = 0x01  #: not allowed: read-only, not allow-listed, no lease
    ILLEGAL_ADDRESS = 0x02  #: no such register for this unit
    ILLEGAL_VALUE = 0x03  #: a value the drive must not get, or a malformed write
    DEVICE_FAILURE = 0x04  #: the drive refused (NAK) or read back something else
    DEVICE_BUSY = 0x06  #: another client holds the control lease
    PATH_UNAVAILABLE = 0x0A  #: no drive behind this unit id
    TARGET_FAILED = 0x0B  #: stale or missing data, or the drive did not answer


#: Where each protocol's parameter groups start (two registers per number).
PARAMETER_BASES: Final = {
    "sj300": {"F": 10000, "A": 12000, "B": 14000, "C": 16000, "H": 18000, "P": 20000},
    "fr700": {"Pr.": 30000},
}
PROTOCOL_IDS: Final = {"sj300": 1, "fr700": 2}

HEARTBEAT: Final = 1000
LEASE_LEFT: Final = 1001
COMMAND: Final = 1002
SET_FREQUENCY: Final = 1003


def parameter_address(protocol: str, code: str) -> int | None:
    """The first register of parameter *code* (normalised), or None if it has none."""
    for prefix, base in PARAMETER_BASES.get(protocol, {}).items():
        if code.startswith(prefix) and code[len(prefix) :].isdigit():
            number = int(code[len(prefix) :])
            return base + 2 * number if number < 1000 else None
    return None


# -- write requests ---------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """Take or renew the control lease."""


@dataclass(frozen=True, slots=True)
class Command:
    """Run or stop: 0 stop, 1 forward, 2 reverse."""

    direction: int


@dataclass(frozen=True, slots=True)
class SetFrequency:
    hz: float


@dataclass(frozen=True, slots=True)
class ParameterWrite:
    code: str
    raw: int


WriteRequest = Heartbeat | Command | SetFrequency | ParameterWrite

# -- the fields -------------------------------------------------------------------

#: A field's value in counts from a drive's state at a time (None: not known).
Getter = Callable[[DriveState, float], "int | None"]
#: When a field's data was read (None: live, never stale).
Stamp = Callable[[DriveState], float]


@dataclass(frozen=True, slots=True)
class Field:
    """One value of the map: where, how wide, in what step, and from what."""

    address: int
    name: str
    #: The step one count stands for, for the documentation ("0.01 Hz", "bit field").
    unit: str
    value: Getter
    stamp: Stamp | None = None
    width: int = 1
    signed: bool = False
    #: True for the registers a write may target (their writes are judged by _control).
    writable: bool = False

    def words(self, state: DriveState, now: float) -> list[int] | None:
        """The field's registers, or None when its value is unknown."""
        value = self.value(state, now)
        if value is None:
            return None
        if self.width == 1 and not self.signed:  # most fields: one unsigned register
            return [0 if value < 0 else 0xFFFF if value > 0xFFFF else value]
        bits = 16 * self.width
        if self.signed:
            low, high = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        else:
            low, high = 0, (1 << bits) - 1
        value = min(max(value, low), high) & ((1 << bits) - 1)  # saturate, then two's complement
        return [(value >> (16 * (self.width - 1 - i))) & 0xFFFF for i in range(self.width)]


def _counts(value: float | None, per_unit: float) -> int | None:
    return None if value is None or not math.isfinite(value) else round(value * per_unit)


def _sj300_monitor(get: Callable[[MonitorData], float], per_unit: float = 1) -> Getter:
    def read(state: DriveState, now: float) -> int | None:
        m = state.monitor
        return _counts(get(m), per_unit) if isinstance(m, MonitorData) else None

    return read


def _any_monitor(name: str, per_unit: float) -> Getter:
    def read(state: DriveState, now: float) -> int | None:
        m = state.monitor
        if isinstance(m, MonitorData | Fr700Monitor):
            return _counts(getattr(m, name), per_unit)
        return None

    return read


def _sj300_status(get: Callable[[InverterStatus], int]) -> Getter:
    def read(state: DriveState, now: float) -> int | None:
        s = state.status
        return get(s) if isinstance(s, InverterStatus) else None

    return read


def _flag(get: Callable[[DriveState], bool | None]) -> Getter:
    def read(state: DriveState, now: float) -> int | None:
        value = get(state)
        return None if value is None else int(value)

    return read


def _direction(state: DriveState, now: float) -> int | None:
    m, s = state.monitor, state.status
    if isinstance(m, MonitorData):
        return int(m.direction)
    if isinstance(s, Fr700Status):
        if Fr700StatusBits.RUN not in s.bits:
            return 0
        return 2 if s.reverse else 1
    return None


def _direction_stamp(state: DriveState) -> float:
    return state.monitor_at if state.protocol == "sj300" else state.status_at


def _trip_record(index: int, get: Callable[[TripHistory, int], float], per: float) -> Getter:
    def read(state: DriveState, now: float) -> int | None:
        trips = state.trips
        if trips is None or index >= len(trips.records):
            return None
        return _counts(get(trips, index), per)

    return read


def _common() -> list[Field]:
    return [
        Field(0, "drive online (poller's verdict)", "0/1", lambda s, now: int(s.online)),
        Field(
            1,
            "seconds since the last good sample (65535: never)",
            "1 s",
            lambda s, now: 65535 if (age := s.sample_age_s(now)) is None else math.floor(age),
        ),
        Field(2, "protocol (1 SJ300, 2 FR-700)", "code", lambda s, now: PROTOCOL_IDS[s.protocol]),
        Field(3, "node (FR-700: station)", "address", lambda s, now: s.node),
        Field(200, "running", "0/1", _flag(lambda s: s.running), lambda s: s.status_at),
        Field(201, "tripped", "0/1", _flag(lambda s: s.tripped), lambda s: s.status_at),
        Field(
            100,
            "output frequency",
            "0.01 Hz",
            _any_monitor("output_frequency_hz", 100),
            _monitor_stamp,
        ),
        Field(101, "output current", "0.1 A", _any_monitor("output_current_a", 10), _monitor_stamp),
        Field(102, "output voltage", "0.1 V", _any_monitor("output_voltage_v", 10), _monitor_stamp),
        Field(
            103, "direction (0 stop, 1 forward, 2 reverse)", "code", _direction, _direction_stamp
        ),
        Field(
            HEARTBEAT,
            "control lease: write any value to take or renew it; reads 1 while held",
            "0/1",
            lambda s, now: int(s.lease.held(now)),
            writable=True,
        ),
        Field(
            LEASE_LEFT,
            "control lease: time left",
            "0.1 s",
            lambda s, now: round(s.lease.seconds_left(now) * 10),
        ),
        Field(
            COMMAND,
            "run command: write 0 stop, 1 forward, 2 reverse; reads the direction",
            "code",
            _direction,
            _direction_stamp,
            writable=True,
        ),
        Field(
            SET_FREQUENCY,
            "set frequency (as last read back)",
            "0.01 Hz",
            lambda s, now: _counts(s.set_frequency_hz, 100),
            lambda s: s.set_frequency_at,
            writable=True,
        ),
    ]


def _monitor_stamp(state: DriveState) -> float:
    return state.monitor_at


def _sj300() -> list[Field]:
    m = _monitor_stamp
    fields = [
        Field(104, "output torque", "1 %", _sj300_monitor(lambda x: x.output_torque_percent), m,
              signed=True),
        Field(105, "power", "0.1 kW", _sj300_monitor(lambda x: x.power_kw, 10), m),
        Field(106, "PID feedback", "0.01 %", _sj300_monitor(lambda x: x.pid_feedback_percent, 100),
              m),
        Field(107, "input terminals", "bit field", _sj300_monitor(lambda x: int(x.input_terminals)),
              m),
        Field(108, "output terminals", "bit field",
              _sj300_monitor(lambda x: int(x.output_terminals)), m),
        Field(109, "frequency x conversion factor (B086)", "0.01",
              _sj300_monitor(lambda x: x.frequency_conversion, 100), m),
        Field(110, "run time", "1 h", _sj300_monitor(lambda x: x.run_time_h), m, width=2),
        Field(112, "power-on time", "1 h", _sj300_monitor(lambda x: x.power_on_time_h), m,
              width=2),
        Field(202, "status A (operating state)", "code", _sj300_status(lambda s: int(s.a)),
              lambda s: s.status_at),
        Field(203, "status B (0 stopped, 1 running, 2 tripped)", "code",
              _sj300_status(lambda s: int(s.b)), lambda s: s.status_at),
        Field(204, "status C (what the output does)", "code", _sj300_status(lambda s: int(s.c)),
              lambda s: s.status_at),
        Field(300, "trip count", "1", lambda s, now: None if s.trips is None else
              s.trips.total_count, lambda s: s.trips_at, width=2),
    ]  # fmt: skip
    for i in range(6):
        base = 302 + 10 * i
        t = lambda s: s.trips_at  # noqa: E731
        rec = f"trip {i + 1} (newest first):"
        fields += [
            Field(base, f"{rec} E-code number (0: empty)", "code",
                  _trip_record(i, lambda h, j: h.records[j].trip_factor, 1), t),
            Field(base + 1, f"{rec} status A", "code",
                  _trip_record(i, lambda h, j: int(h.records[j].status_a), 1), t),
            Field(base + 2, f"{rec} output frequency", "0.01 Hz",
                  _trip_record(i, lambda h, j: h.records[j].output_frequency_hz, 100), t),
            Field(base + 3, f"{rec} output current", "0.1 A",
                  _trip_record(i, lambda h, j: h.records[j].output_current_a, 10), t),
            Field(base + 4, f"{rec} output voltage", "0.1 V",
                  _trip_record(i, lambda h, j: h.records[j].output_voltage_v, 10), t),
            Field(base + 5, f"{rec} run time", "1 h",
                  _trip_record(i, lambda h, j: h.records[j].run_time_h, 1), t, width=2),
            Field(base + 7, f"{rec} power-on time", "1 h",
                  _trip_record(i, lambda h, j: h.records[j].power_on_time_h, 1), t, width=2),
            Field(base + 9, f"{rec} status C", "code",
                  _trip_record(i, lambda h, j: int(h.records[j].status_c), 1), t),
        ]  # fmt: skip
    return fields


def _fr700() -> list[Field]:
    def bits(state: DriveState, now: float) -> int | None:
        s = state.status
        return int(s.bits) if isinstance(s, Fr700Status) else None

    return [Field(202, "status bits (H7A/H79)", "bit field", bits, lambda s: s.status_at)]


def _parameter_field(protocol: str, code: str, address: int) -> Field:
    def read(state: DriveState, now: float) -> int | None:
        return state.parameters.get(code)

    return Field(
        address,
        f"parameter {code}",
        "its setting increment",
        read,
        lambda s: s.parameters_at.get(code, -math.inf),
        width=2,
        signed=True,
        writable=True,
    )


class RegisterMap:
    """The registers of every drive of one line (its protocol and polled parameters)."""

    def __init__(self, protocol: str, parameters: Iterable[str] = ()) -> None:
        fields = _common() + (_sj300() if protocol == "sj300" else _fr700())
        self.parameters: dict[int, str] = {}
        for code in parameters:
            address = parameter_address(protocol, code)
            if address is not None:
                fields.append(_parameter_field(protocol, code, address))
                self.parameters[address] = code
        self.protocol = protocol
        self.fields = sorted(fields, key=lambda f: f.address)
        #: address -> (field, index of the word within the field)
        self._at: dict[int, tuple[Field, int]] = {}
        for f in self.fields:
            for word in range(f.width):
                if f.address + word in self._at:
                    raise AssertionError(f"register {f.address + word} defined twice")
                self._at[f.address + word] = (f, word)

    def __iter__(self) -> Iterator[Field]:
        return iter(self.fields)

    def read(
        self, state: DriveState, address: int, count: int, now: float, stale_after_s: float
    ) -> list[int] | Exc:
        """*count* registers from *address*, or the exception that refuses the whole read."""
        out: list[int] = []
        at, end = address, address + count
        while at < end:  # field by field (a two-register field is read once)
            found = self._at.get(at)
            if found is None:
                return Exc.ILLEGAL_ADDRESS
            f, word = found
            stamp = f.stamp
            if stamp is None:  # live: computed every time
                words = f.words(state, now)
            else:
                read_at = stamp(state)
                if now - read_at > stale_after_s:
                    return Exc.TARGET_FAILED
                # Encoded once per sample: a SCADA reads far more often than the line polls.
                cached = state.encoded.get(f.address)
                if cached is not None and cached[0] == read_at:
                    words = cached[1]
                else:
                    words = f.words(state, now)
                    state.encoded[f.address] = (read_at, words)
            if words is None:
                return Exc.TARGET_FAILED
            taken = words[word : word + end - at]
            out += taken
            at += len(taken)
        return out

    def decode_write(self, address: int, values: list[int]) -> WriteRequest | Exc:
        """What a write of *values* at *address* asks for (not yet judged)."""
        found = self._at.get(address)
        if found is None or any(a not in self._at for a in range(address, address + len(values))):
            return Exc.ILLEGAL_ADDRESS
        f, word = found
        if not f.writable:
            return Exc.ILLEGAL_FUNCTION
        if word != 0 or len(values) != f.width:
            return Exc.ILLEGAL_VALUE  # part of a value, or more than one target
        if address == HEARTBEAT:
            return Heartbeat()
        if address == COMMAND:
            return Command(values[0]) if values[0] in (0, 1, 2) else Exc.ILLEGAL_VALUE
        if address == SET_FREQUENCY:
            return SetFrequency(values[0] / 100)
        raw = (values[0] << 16) | values[1]
        if raw >= 1 << 31:
            raw -= 1 << 32
        return ParameterWrite(self.parameters[address], raw)


def describe(protocol: str) -> list[tuple[int, int, str, str, bool]]:
    """(address, registers, name, unit, writable) of every fixed field, for the documentation."""
    return [(f.address, f.width, f.name, f.unit, f.writable) for f in RegisterMap(protocol)]
