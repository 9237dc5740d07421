"""The Modbus register map: what each holding register of a drive's unit holds.

Sans-IO: :class:`RegisterMap` turns a read of ``count`` registers at
``address`` into register values from a drive as served (its latest
snapshot and the gateway's judgement of it), or a Modbus exception code,
and a write into a neutral :data:`~sj300_async.gateway.WriteRequest` for
the gateway to judge and carry out. docs/GATEWAY.md prints the map;
:func:`describe` generates it, so the two cannot drift.

The map is one common block (identity, state, output, the lease and
commands), the drive's protocol's own block and parameter bases (its
profile's :class:`~sj300_async.profiles.RegisterLayout`: a third
protocol brings its own), and a block per polled parameter.

Decisions:

- One map, read with function 3 (holding registers) or 4 (input registers),
  written with 6 or 16; addresses are the PDU's, 0-based.
- Every value is an integer count of a documented step (0.01 Hz, 0.1 A...).
  Two-register values are 32-bit, high word first (big-endian word order,
  "ABCD"); signed values are two's complement; a value too large for its
  registers saturates (never wraps into a plausible wrong number).
- A read succeeds whole or not at all: any register of it unknown (0x02),
  any data in it the drive as served does not hold fresh, or never read
  (0x0B, "gateway target device failed to respond"). Freshness is the
  gateway's judgement, not the map's: each field names its deadline on the
  :class:`~sj300_async.gateway.ServedDrive` (its group's ``*_until``, a
  parameter's :meth:`~sj300_async.gateway.ServedDrive.parameter_until`), the
  one every northbound serves by. The identity block (online, sample age)
  is always served, so a SCADA can see why.
- A parameter is served at ``base(group) + 2 * number`` (A004 at 12008,
  Pr.7 at 30014) when the line polls it; it is counted in its own setting
  increment (F002 = 30.00 s reads 3000), 32-bit. A parameter is written
  whole: both registers in one function-16 request.
- One write request changes one thing (a heartbeat, a command, the set
  frequency, or one parameter); a write spanning several is refused (0x03).
- A neutral refusal becomes the exception its meaning is closest to
  (:data:`REFUSAL_CODES`).
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from math import isfinite
from typing import Final, get_args

from ...profiles import DriveSnapshot, Profile, ReadGroup, RegisterField
from ...wire import Direction
from .. import (
    Heartbeat,
    ParameterWrite,
    Refusal,
    RunCommand,
    ServedDrive,
    SetFrequency,
    WriteRequest,
    WriteResult,
)
from ._framing import Exc

__all__ = [
    "REFUSAL_CODES",
    "Exc",
    "Field",
    "RegisterMap",
    "describe",
    "parameter_address",
]


#: The exception each neutral refusal is answered with.
REFUSAL_CODES: Final = {
    Refusal.NOT_ALLOWED: Exc.ILLEGAL_FUNCTION,
    Refusal.NO_LEASE: Exc.ILLEGAL_FUNCTION,
    Refusal.LEASE_HELD: Exc.DEVICE_BUSY,
    Refusal.INVALID_VALUE: Exc.ILLEGAL_VALUE,
    Refusal.MALFORMED: Exc.ILLEGAL_VALUE,
    Refusal.UNKNOWN_TARGET: Exc.ILLEGAL_ADDRESS,
    Refusal.BUSY: Exc.DEVICE_BUSY,
    Refusal.DRIVE_REFUSED: Exc.DEVICE_FAILURE,
    Refusal.NOT_CONFIRMED: Exc.DEVICE_FAILURE,
    Refusal.NO_ANSWER: Exc.TARGET_FAILED,
}

HEARTBEAT: Final = 1000
LEASE_LEFT: Final = 1001
COMMAND: Final = 1002
SET_FREQUENCY: Final = 1003


def parameter_address(profile: Profile, code: str) -> int | None:
    """The first register of parameter *code* (normalised), or None if it has none."""
    for prefix, base in profile.registers.parameter_bases.items():
        if code.startswith(prefix) and code[len(prefix) :].isdigit():
            number = int(code[len(prefix) :])
            return base + 2 * number if number < 1000 else None
    return None


# -- the fields -------------------------------------------------------------------

#: A field's value in counts from a drive as served at a loop time (None: not known).
Getter = Callable[[ServedDrive, float], "int | None"]
#: The loop time until which a field's data is fresh, by the drive as served.
Until = Callable[[ServedDrive], float]

#: Each read group's deadline (``ServedDrive.status_until``...): one object per group,
#: so a read's fields of one group are judged once (:attr:`_Plan.deadlines`).
_UNTIL: Final[Mapping[ReadGroup, Until]] = {
    group: operator.attrgetter(f"{group}_until") for group in get_args(ReadGroup)
}


@dataclass(frozen=True, slots=True)
class Field:
    """One value of the map: where, how wide, in what step, and from what."""

    address: int
    name: str
    #: The step one count stands for, for the documentation ("0.01 Hz", "bit field").
    unit: str
    value: Getter
    #: When its data turns stale (None: live, never stale).
    until: Until | None = None
    width: int = 1
    signed: bool = False
    #: True for the registers a write may target (the gateway judges the writes).
    writable: bool = False

    def words(self, served: ServedDrive, now: float) -> list[int] | None:
        """The field's registers, or None when its value is unknown."""
        value = self.value(served, now)
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


def _snapshot(name: str, per_unit: float = 1) -> Getter:
    """The snapshot's field *name* in counts of ``1 / per_unit`` (:func:`in_counts`, inlined:
    a SCADA's reads run these at every request)."""
    get: Callable[[DriveSnapshot], float | None] = operator.attrgetter(name)

    def read(served: ServedDrive, now: float) -> int | None:
        value = get(served.snapshot)
        if value is None or not isfinite(value):
            return None
        return round(value * per_unit)

    return read


def _flag(get: Callable[[DriveSnapshot], bool | None]) -> Getter:
    def read(served: ServedDrive, now: float) -> int | None:
        value = get(served.snapshot)
        return None if value is None else int(value)

    return read


def _direction(served: ServedDrive, now: float) -> int | None:
    direction = served.snapshot.direction
    return None if direction is None else int(direction)


def _age(served: ServedDrive, now: float) -> int:
    age = served.snapshot.sample_age_s(now)
    return 65535 if age is None else math.floor(age)


def _leased(served: ServedDrive, now: float) -> int:
    return int(served.lease_holder(now) is not None)


def _lease_left(served: ServedDrive, now: float) -> int:
    return round(served.lease_seconds_left(now) * 10)


def _common(protocol_id: int) -> list[Field]:
    m, s, d = _UNTIL["monitor"], _UNTIL["status"], _UNTIL["direction"]
    return [
        Field(0, "drive online (poller's verdict)", "0/1", lambda x, now: int(x.snapshot.online)),
        Field(1, "seconds since the last good sample (65535: never)", "1 s", _age),
        Field(2, "protocol (1 SJ300, 2 FR-700)", "code", lambda x, now: protocol_id),
        Field(3, "node (FR-700: station)", "address", lambda x, now: x.snapshot.node),
        Field(200, "running", "0/1", _flag(lambda x: x.running), s),
        Field(201, "tripped", "0/1", _flag(lambda x: x.tripped), s),
        Field(100, "output frequency", "0.01 Hz", _snapshot("output_frequency_hz", 100),
              m),
        Field(101, "output current", "0.1 A", _snapshot("output_current_a", 10), m),
        Field(102, "output voltage", "0.1 V", _snapshot("output_voltage_v", 10), m),
        Field(103, "direction (0 stop, 1 forward, 2 reverse)", "code", _direction, d),
        Field(
            HEARTBEAT,
            "control lease: write any value to take or renew it; reads 1 while held",
            "0/1",
            _leased,
            writable=True,
        ),
        Field(LEASE_LEFT, "control lease: time left", "0.1 s", _lease_left),
        Field(
            COMMAND,
            "run command: write 0 stop, 1 forward, 2 reverse; reads the direction",
            "code",
            _direction,
            d,
            writable=True,
        ),
        Field(
            SET_FREQUENCY,
            "set frequency (as last read back)",
            "0.01 Hz",
            _snapshot("set_frequency_hz", 100),
            _UNTIL["set_frequency"],
            writable=True,
        ),
    ]  # fmt: skip


#: A snapshot every read group's time can be set on, to tell a profile's stamp's group.
def _protocol_field(field: RegisterField) -> Field:
    """A profile's own register, read from the drive's snapshot, fresh as its group is."""
    get = field.value

    def read(served: ServedDrive, now: float) -> int | None:
        return get(served.snapshot)

    until = None if field.group is None else _UNTIL[field.group]
    return Field(field.address, field.name, field.step, read, until, field.width, field.signed)


def _parameter_field(code: str, address: int) -> Field:
    def read(served: ServedDrive, now: float) -> int | None:
        reading = served.snapshot.parameters.get(code)
        return None if reading is None else reading.raw

    # A methodcaller, not a closure around the method: one Python call per check.
    until: Until = operator.methodcaller("parameter_until", code)
    return Field(
        address,
        f"parameter {code}",
        "its setting increment",
        read,
        until,
        width=2,
        signed=True,
        writable=True,
    )


#: A unit's answered reads: (address, count) -> the drive as served it was read from,
#: the soonest deadline of its values, and the registers (see RegisterMap.read).
ReadCache = dict[tuple[int, int], tuple[ServedDrive, float, "list[int]"]]
#: Reads whose plan a map keeps (a SCADA reads the same few blocks over and over; what a
#: client could ask is 65,536 x 125 reads, so past this many a plan is made every time).
MAX_PLANS: Final = 1024
#: Reads a unit's cache keeps answers of (a SCADA reads a unit in a few blocks); past
#: it, the one kept longest makes room, so a client that once scanned the map leaves
#: no entry the SCADA's own blocks cannot take over.
MAX_CACHED_READS: Final = 16


@dataclass(frozen=True, slots=True)
class _Plan:
    """A read's fields, each with the words of it the read takes (first, stop)."""

    segments: tuple[tuple[Field, int, int], ...]
    #: A field of it is computed at every read (the lease, the sample's age): not cached.
    live: bool
    #: The distinct deadlines of its fields (a block's fields mostly share one: it is
    #: asked once per read, not once per field).
    deadlines: tuple[Until, ...]


class RegisterMap:
    """The registers of every drive of one line (its protocol's profile and polled parameters)."""

    def __init__(self, profile: Profile, parameters: Iterable[str] = ()) -> None:
        layout = profile.registers
        fields = _common(layout.protocol_id) + [_protocol_field(f) for f in layout.fields]
        self.parameters: dict[int, str] = {}
        for code in parameters:
            address = parameter_address(profile, code)
            if address is not None:
                fields.append(_parameter_field(code, address))
                self.parameters[address] = code
        self.profile = profile
        self.fields = sorted(fields, key=lambda f: f.address)
        #: address -> (field, index of the word within the field)
        self._at: dict[int, tuple[Field, int]] = {}
        for f in self.fields:
            for word in range(f.width):
                if f.address + word in self._at:
                    raise AssertionError(f"register {f.address + word} defined twice")
                self._at[f.address + word] = (f, word)
        #: (address, count) -> the read's plan, or the exception refusing it (see read)
        self._plans: dict[tuple[int, int], _Plan | Exc] = {}

    def __iter__(self) -> Iterator[Field]:
        return iter(self.fields)

    def read(
        self,
        served: ServedDrive,
        address: int,
        count: int,
        now: float,
        cache: ReadCache | None = None,
    ) -> list[int] | Exc:
        """*count* registers from *address* of the drive *served* (its latest served view),
        or the exception that refuses the whole read.

        *cache*, kept per drive by the caller, holds each read's answer with
        the served view it came from: a SCADA may read far more often than
        the line polls, and the same read of the same snapshot is answered
        again until the soonest of its values' deadlines. One entry per read,
        not per field: an entry per field, replaced at every sample, was two
        objects per register for the cyclic collector to scan (70,000 at plant
        scale).
        The list returned may be the cache's: the caller must not change it.
        """
        key = (address, count)
        plan = self._plans.get(key)
        if plan is None:
            plan = self._plan(address, count)
            if len(self._plans) < MAX_PLANS:
                self._plans[key] = plan
        if isinstance(plan, Exc):
            return plan
        cached = None if cache is None or plan.live else cache.get(key)
        if cached is not None and cached[0] is served and now <= cached[1]:
            return cached[2]
        soonest = math.inf
        for until in plan.deadlines:
            deadline = until(served)
            if now > deadline:  # stale, or never read: the served view's judgement
                return Exc.TARGET_FAILED
            if deadline < soonest:
                soonest = deadline
        out: list[int] = []
        for f, first, stop in plan.segments:
            if f.width == 1 and not f.signed:  # most fields: one unsigned register, inline
                value = f.value(served, now)
                if value is None:
                    return Exc.TARGET_FAILED
                out.append(0 if value < 0 else 0xFFFF if value > 0xFFFF else value)
                continue
            words = f.words(served, now)
            if words is None:
                return Exc.TARGET_FAILED
            out += words if stop - first == f.width else words[first:stop]
        if cache is not None and not plan.live:
            if key not in cache and len(cache) >= MAX_CACHED_READS:
                del cache[next(iter(cache))]  # the one kept longest (see MAX_CACHED_READS)
            cache[key] = (served, soonest, out)
        return out

    def _plan(self, address: int, count: int) -> _Plan | Exc:
        """The fields a read of *count* registers at *address* covers, each with the part
        of its words it takes; ILLEGAL_ADDRESS when a register of it is in no field."""
        segments: list[tuple[Field, int, int]] = []
        at, end = address, address + count
        while at < end:
            found = self._at.get(at)
            if found is None:
                return Exc.ILLEGAL_ADDRESS
            f, word = found
            stop = min(f.width, word + end - at)
            segments.append((f, word, stop))
            at += stop - word
        deadlines = dict.fromkeys(f.until for f, _, _ in segments if f.until is not None)
        return _Plan(
            tuple(segments),
            live=any(f.until is None for f, _, _ in segments),
            deadlines=tuple(deadlines),
        )

    def decode_write(self, address: int, values: list[int]) -> WriteRequest | WriteResult:
        """What a write of *values* at *address* asks for (not yet judged), or why it is none.

        The refusals are neutral, as the gateway's are: the server answers
        each with its exception (:data:`REFUSAL_CODES`) and audits it.
        """
        found = self._at.get(address)
        missing = next(
            (a for a in range(address, address + len(values)) if a not in self._at), None
        )
        if found is None or missing is not None:
            where = address if found is None else missing
            return WriteResult(Refusal.UNKNOWN_TARGET, f"no register {where} for this unit")
        f, word = found
        if not f.writable:
            return WriteResult(Refusal.NOT_ALLOWED, f"register {address} ({f.name}) is read-only")
        if word != 0 or len(values) != f.width:  # part of a value, or more than one target
            return WriteResult(
                Refusal.MALFORMED,
                f"a write covers one value whole: {f.name} is registers {f.address}.."
                f"{f.address + f.width - 1}",
            )
        if address == HEARTBEAT:
            return Heartbeat()
        if address == COMMAND:
            if values[0] not in (0, 1, 2):
                return WriteResult(
                    Refusal.INVALID_VALUE,
                    f"a run command is 0 stop, 1 forward or 2 reverse, got {values[0]}",
                )
            return RunCommand(Direction(values[0]))
        if address == SET_FREQUENCY:
            return SetFrequency(values[0] / 100)
        raw = (values[0] << 16) | values[1]
        if raw >= 1 << 31:
            raw -= 1 << 32
        return ParameterWrite(self.parameters[address], raw)


def describe(profile: Profile) -> list[tuple[int, int, str, str, bool]]:
    """(address, registers, name, unit, writable) of every fixed field, for the documentation."""
    return [(f.address, f.width, f.name, f.unit, f.writable) for f in RegisterMap(profile)]
