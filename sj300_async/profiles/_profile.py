"""What the gateway and the command line need to know of a protocol: its profile.

A dialect tells the async stack how to talk to a protocol's drives; a
profile tells everything above the poller what the drives' answers mean
and what the drives can do, so that no consumer branches on a protocol's
name or checks for one protocol's types:

- its readings in neutral terms: a status and a monitor read as
  :class:`~._snapshot.StatusView` / :class:`~._snapshot.MonitorView`, a
  trip history as a :class:`~._snapshot.TripLog`, a trip code named
  (:meth:`Profile.trip`), the protocol's own extras for its register block;
- its parameters (:class:`ParameterCatalogue`): code parsing and
  completion, units, raw integer <-> value in the unit, ranges, the codes
  a backup reads; which of them a restore leaves alone or writes last;
- the parameter holding the maximum frequency, and how the set frequency
  is read back;
- where it sits in the gateway's register map: the unit-id offset, its
  own register block and the bases of its parameter blocks
  (:class:`RegisterLayout`, a plain description: the Modbus northbound
  does the encoding);
- the noun and range of its node numbers, and its capabilities.

A protocol's dialect names its profile (``Dialect.profile``, a
``"module:attribute"`` string imported on first use, as it names its
simulator); :func:`~._registry.get_profile` finds it. A protocol without
one is refused by the gateway's configuration and the commands that need
one, with a message naming it.

Profiles are stateless and shared: every method is a pure function of its
arguments, but for the two async reads, which only await drive methods.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Protocol

from ._snapshot import DriveSnapshot, MonitorView, ReadGroup, StatusView, Trip, TripLog

__all__ = [
    "Capabilities",
    "ParameterCatalogue",
    "ParameterSpec",
    "Profile",
    "RegisterField",
    "RegisterLayout",
    "in_counts",
]


@dataclass(frozen=True, slots=True)
class Capabilities:
    """What a protocol's drives can do beyond status, monitor, run, stop and frequency."""

    #: The trip history can be read (:meth:`Profile.read_trips`).
    trip_history: bool = False
    #: Intelligent input terminals can be set over the line.
    terminals: bool = False
    #: One frame stops every drive of the line (``bus.broadcast.stop()``).
    broadcast_stop: bool = False
    #: Settings written over the line can be stored to non-volatile memory
    #: apart (``drive.store()``).
    store: bool = False
    #: A whole parameter set can be backed up and restored (``sj300 params``):
    #: every parameter a drive can have is addressable
    #: (:meth:`ParameterCatalogue.addressable`), and absent ones are told apart
    #: (:meth:`Profile.absent`).
    parameter_backup: bool = False
    #: The optional snapshot values its monitor read fills
    #: (``"output_torque_percent"``, ``"power_kw"``).
    measures: frozenset[str] = frozenset()
    #: Every word the profile's state gives for a status it knows (``"stopped"``,
    #: ``"accelerating"``...): Home Assistant's status sensor offers them as its
    #: options. Empty: not listed (the sensor is plain text). A status the drive
    #: reports that the profile does not know may give another word.
    states: tuple[str, ...] = ()


class ParameterSpec(Protocol):
    """One parameter as the catalogue knows it."""

    @property
    def code(self) -> str:
        """The protocol's own name: ``"F002"``, ``"Pr.7"``."""

    @property
    def name(self) -> str: ...

    @property
    def unit(self) -> str:
        """The value's unit ("" for selections and counts)."""

    @property
    def scale(self) -> int:
        """Raw counts per unit."""

    @property
    def minimum(self) -> float: ...

    @property
    def maximum(self) -> float: ...

    @property
    def default(self) -> float | None:
        """The factory setting in the unit; None where the manual gives none or it depends
        on the drive (rated current, capacity, country)."""

    def to_raw(self, value: float) -> int:
        """The integer the drive holds for *value*.

        Raises:
            LocalProtocolError: outside the range or finer than the setting increment.
        """

    def from_raw(self, raw: int) -> float:
        """The value in the unit of the integer *raw*."""


class ParameterCatalogue(Protocol):
    """A protocol's parameters: names, units and ranges."""

    def code(self, text: str) -> str | None:
        """The protocol's own code for *text* (``"f002"`` -> ``"F002"``), None if not one."""

    def spec(self, code: str) -> ParameterSpec:
        """The catalogue entry of *code*.

        Raises:
            LocalProtocolError: not a parameter code, or one whose unit is unknown.
        """

    def codes(self) -> Sequence[str]:
        """Every catalogued code, in the catalogue's order (completion)."""

    def addressable(self) -> Sequence[str]:
        """Every code a drive of the protocol can have, in order: what a backup reads.

        The catalogued codes where the catalogue names every parameter; where
        it does not, every code the protocol can address (a drive refuses the
        ones it lacks, :meth:`Profile.absent`), catalogued or not. An
        uncatalogued code has no :meth:`spec`: its value is a raw integer.
        """

    @property
    def raw_range(self) -> tuple[int, int]:
        """The lowest and highest integer a parameter's data can carry on the wire."""


@dataclass(frozen=True, slots=True)
class RegisterField:
    """One value of a protocol's own register block, described (the Modbus map encodes it)."""

    #: The first register (PDU address, 0-based).
    address: int
    name: str
    #: The step one count stands for, for the documentation (``"0.1 kW"``, ``"bit field"``).
    step: str
    #: The value in counts from a snapshot, None when unknown.
    value: Callable[[DriveSnapshot], int | None]
    #: The read group the value comes with (its freshness is the group's, judged by the
    #: served view), None for a live value.
    group: ReadGroup | None = None
    width: int = 1
    signed: bool = False


_NO_BASES: Mapping[str, int] = MappingProxyType({})


@dataclass(frozen=True, slots=True)
class RegisterLayout:
    """Where a protocol's drives sit in the gateway's register map (docs/GATEWAY.md)."""

    #: What the identity register "protocol" reads for its drives.
    protocol_id: int
    #: The protocol's own register block, besides the common one.
    fields: tuple[RegisterField, ...] = ()
    #: The first register of each parameter group, by the code's prefix
    #: (``{"A": 12000}``: A004 is at 12000 + 2 x 4).
    parameter_bases: Mapping[str, int] = field(default_factory=lambda: _NO_BASES)


class Profile(Protocol):
    """A protocol as the gateway and the command line see it (see the module docstring)."""

    #: The registered protocol name (its dialect's).
    name: str
    #: The drives' model and maker, for people and for Home Assistant's device registry.
    model: str
    manufacturer: str
    #: What the protocol calls an address (``"node"``, ``"station"``), and their range.
    node_noun: str
    node_range: tuple[int, int]
    capabilities: Capabilities
    #: A drive's gateway unit id is its address plus this (unless its line says otherwise).
    unit_offset: int
    #: The highest output frequency any of its drives can be set to.
    max_frequency_hz: float
    #: The parameter holding a drive's own maximum frequency (None: none).
    max_frequency_parameter: str | None
    #: A parameter that holds the set frequency, so that polling it reads the
    #: setpoint (None: the set frequency has a read of its own).
    setpoint_parameter: str | None
    parameters: ParameterCatalogue
    registers: RegisterLayout
    #: The acceleration and deceleration time parameters.
    ramp_parameters: tuple[str, str]
    #: The parameter holding a drive's address on the line (a restore never writes it).
    address_parameter: str | None
    #: The line's settings (speed, framing...): a restore writes them only when asked,
    #: since a new value cuts the drive off the line being used.
    line_parameters: tuple[str, ...]
    #: Parameters a restore never writes besides the address: another address
    #: of the drive, a read-only count, the drive's own calibration.
    kept_parameters: tuple[str, ...]
    #: Parameters a restore writes after every other, in this order: each one
    #: changes whether the drive takes the writes after it (a write lock).
    last_parameters: tuple[str, ...]

    def status_view(self, status: Any) -> StatusView:
        """What the drive class's status read result says."""

    def monitor_view(self, monitor: Any) -> MonitorView:
        """What the drive class's monitor read result says."""

    def trip_log(self, history: Any) -> TripLog:
        """The trip history read (:meth:`read_trips`) in neutral terms."""

    def trip(self, number: int) -> Trip:
        """A trip code named as the drive's display and manual name it."""

    def extras(self, status: Any, monitor: Any, trips: Any) -> object | None:
        """The protocol's own typed extras of a snapshot (each argument may be None)."""

    async def read_set_frequency(self, drive: Any) -> float:
        """Read the set frequency back from *drive* (its drive class), in Hz."""

    async def read_trips(self, drive: Any) -> Any:
        """Read *drive*'s trip history (only when ``capabilities.trip_history``)."""

    async def read_latest_trip(self, drive: Any) -> Trip | None:
        """The trip *drive* is in or was last in, None when it keeps none (its newest record)."""

    async def reset(self, drive: Any) -> None:
        """Send *drive* what clears a trip (the drive's status tells whether it did)."""

    def status_rows(self, status: Any, monitor: Any) -> list[tuple[str, str]]:
        """A status and a monitor read as ``(label, value with its unit)`` rows for people."""

    def trip_codes(self) -> Sequence[Trip]:
        """Every trip code the reference names, with its meaning."""

    def nak_hint(self, code: int, command: str) -> str | None:
        """What a refusal (NAK *code*) of *command* (``"run"``, ``"frequency"``) usually means."""

    def absent(self, code: int) -> bool:
        """True when NAK *code* to a parameter read means the drive does not have it."""

    def request_describer(self, dialect: Any) -> Callable[[bytes], str] | None:
        """What reads a frame the host wrote back in words, for traces (None: none)."""


def in_counts(value: float | None, per_unit: float = 1) -> int | None:
    """*value* counted in steps of ``1 / per_unit`` (a register's integer), None if unknown."""
    if value is None or not math.isfinite(value):
        return None
    return round(value * per_unit)
