"""The protocol-neutral drive model: one frozen :class:`DriveSnapshot` per sample.

Every consumer above the poller reads a drive through this model: the
gateway's northbounds (Modbus registers, MQTT state, metrics), the command
line's monitor and the fleet view. None of them looks at a protocol's status
codes to work out whether a drive runs, which way, or what its state is in
words: the drive's profile (:mod:`._profile`) did that once, when the
snapshot was built (:mod:`._build`).

Decisions:

- Values keep the time they were read (event-loop time, ``*_at``; ``-inf``
  for never), not only the time of the snapshot: a snapshot can hold values
  of older reads (a poll that failed half-way keeps the last good monitor
  block), and each consumer applies its own staleness rule to each group
  (:func:`is_fresh`). Nothing is nulled here.
- Units are in the field names (``output_frequency_hz``); a value the drive
  did not give, or that was never read, is None, never a made-up 0.
- What only one protocol has travels in :attr:`DriveSnapshot.extras`, an
  object of the protocol's own typed class (its profile defines it): the
  protocol's own register block reads it, nothing neutral does.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Final, Literal

from ..wire import Direction

__all__ = [
    "NEVER",
    "DriveSnapshot",
    "MonitorView",
    "ParameterReading",
    "StatusView",
    "Trip",
    "TripLog",
    "is_fresh",
    "read_time",
]

#: The read time of a value never read.
NEVER: Final = -math.inf

_NO_FIELDS: Final[Mapping[str, object]] = MappingProxyType({})


def is_fresh(at: float, now: float, stale_after_s: float) -> bool:
    """True when a value read at loop time *at* is no older than *stale_after_s* at *now*."""
    return now - at <= stale_after_s


@dataclass(frozen=True, slots=True)
class Trip:
    """One trip (a fault that stopped the drive), as the drive and its manual name it."""

    #: As the drive's display shows it: ``"E07"`` (SJ300), ``"E.OC1"`` (FR-700;
    #: ``"H9A"`` for a fault byte its table lacks).
    code: str
    #: The trip factor / fault code as a number.
    number: int
    #: The codec's name (``"OVER_VOLTAGE"``); None where the reference names none.
    name: str | None
    #: What it means (``"over-voltage"``); None where the reference gives none.
    meaning: str | None
    #: The drive's values when it tripped, where its history records them.
    output_frequency_hz: float | None = None
    output_current_a: float | None = None
    output_voltage_v: float | None = None
    run_time_h: int | None = None
    power_on_time_h: int | None = None
    #: What else the protocol's record says, labelled, in words (``("state", "running")``).
    details: tuple[tuple[str, str], ...] = ()
    #: The protocol's own record, as its drive class read it (None: named from a code only).
    record: object = field(default=None, compare=False)

    def __str__(self) -> str:
        """``E07 over-voltage``; ``fault H9A`` when the meaning is unknown."""
        if self.meaning is None:
            return f"fault {self.code}"
        return f"{self.code} {self.meaning}"

    def as_json(self) -> dict[str, Any]:
        """``{"code": "E07", "number": 7, "name": "OVER_VOLTAGE", "meaning": "over-voltage"}``."""
        return {
            "code": self.code,
            "number": self.number,
            "name": self.name,
            "meaning": self.meaning,
        }


@dataclass(frozen=True, slots=True)
class TripLog:
    """A drive's trip history: how many trips in all, and the latest ones, newest first."""

    #: Trips since the counter was cleared (None: the drive does not count them).
    total_count: int | None
    #: The recorded trips, newest first (empty slots left out).
    records: tuple[Trip, ...] = ()


@dataclass(frozen=True, slots=True)
class ParameterReading:
    """A parameter as read: the drive's integer and the value in its unit."""

    code: str
    #: The integer the drive holds (its setting increment counted).
    raw: int
    value: float
    #: The value's unit ("" for selections and counts).
    unit: str
    #: Event-loop time of the read.
    at: float


_NO_READINGS: Final[Mapping[str, ParameterReading]] = MappingProxyType({})


@dataclass(frozen=True, slots=True)
class StatusView:
    """What a drive's status says, in neutral terms (a profile's reading of it)."""

    running: bool
    tripped: bool
    #: In a word or two: ``stopped``, ``accelerating``, ``running reverse``, ``tripped``.
    state: str
    #: The direction, when the status tells it (else the monitor does).
    direction: Direction | None = None
    #: The status as the protocol words it, for consumers that show it as is
    #: (MQTT's ``status``: ``{"a": "RUNNING", ...}``, ``{"bits": 11}``).
    fields: Mapping[str, object] = field(default_factory=lambda: _NO_FIELDS)


@dataclass(frozen=True, slots=True)
class MonitorView:
    """What a drive's monitor read says, in neutral terms (None: the protocol's read lacks it)."""

    output_frequency_hz: float | None = None
    output_current_a: float | None = None
    output_voltage_v: float | None = None
    direction: Direction | None = None
    output_torque_percent: float | None = None
    power_kw: float | None = None


@dataclass(frozen=True, slots=True)
class DriveSnapshot:
    """One drive at one sample (see the module docstring)."""

    # -- identity -----------------------------------------------------------------
    #: The line's name (a gateway's line; the bus description outside a gateway).
    line: str
    #: The drive's address on its line (a node, an FR-700 station).
    node: int
    #: The registered protocol name.
    protocol: str
    #: The gateway's unit id of the drive (Modbus unit), None outside a gateway.
    unit: int | None
    # -- the sample ------------------------------------------------------------------
    #: Event-loop time the snapshot was built at (the sample's end).
    taken_at: float
    #: The same instant as Unix time, for consumers in another process.
    time: float
    #: The poller's verdict (a drive is polled online until enough polls fail).
    online: bool
    #: Event-loop time of the last poll in which every read succeeded (None: never).
    last_ok: float | None = None
    # -- the status (read at status_at) -----------------------------------------------
    status_at: float = NEVER
    running: bool | None = None
    tripped: bool | None = None
    #: The state in words (:attr:`StatusView.state`), None when no status was read.
    state: str | None = None
    status_fields: Mapping[str, object] | None = None
    # -- the monitor (read at monitor_at) ------------------------------------------------
    monitor_at: float = NEVER
    output_frequency_hz: float | None = None
    output_current_a: float | None = None
    output_voltage_v: float | None = None
    output_torque_percent: float | None = None
    power_kw: float | None = None
    # -- direction: the monitor's when it tells it, else the status's -------------------
    direction: Direction | None = None
    direction_at: float = NEVER
    # -- the set frequency, as last read back ------------------------------------------
    set_frequency_hz: float | None = None
    set_frequency_at: float = NEVER
    # -- trips ----------------------------------------------------------------------------
    #: The trip the drive is in: set only while it is tripped and its history was
    #: read after the trip was seen (a history read before would name the previous one).
    trip: Trip | None = None
    trips: TripLog | None = None
    trips_at: float = NEVER
    # -- the rest -----------------------------------------------------------------------
    #: Polled parameters by code.
    parameters: Mapping[str, ParameterReading] = field(default_factory=lambda: _NO_READINGS)
    #: Polled parameters the drive refused at their latest read (a NAK): they
    #: have no value (not in ``parameters``), and the drive is not offline for it.
    unavailable_parameters: frozenset[str] = frozenset()
    #: The protocol's own typed extras (its profile's class), or None.
    extras: object | None = None

    @property
    def available(self) -> bool:
        """Online and heard from: a drive that has never answered is not available."""
        return self.online and self.last_ok is not None

    def sample_age_s(self, now: float) -> float | None:
        """Seconds since the last good sample at loop time *now*, None before the first."""
        return None if self.last_ok is None else max(0.0, now - self.last_ok)

    def state_text(self) -> str | None:
        """The state in words with the trip named: ``tripped E07 over-voltage``."""
        if self.state is None:
            return None
        if self.tripped and self.trip is not None:
            return f"{self.state} {self.trip}"
        return self.state


#: A group of a snapshot's values read together (each has its ``<group>_at`` time).
ReadGroup = Literal["status", "monitor", "direction", "set_frequency", "trips"]


def read_time(group: ReadGroup) -> Callable[[DriveSnapshot], float]:
    """The function giving when *group*'s values of a snapshot were read (a register's stamp)."""
    getter: Callable[[DriveSnapshot], float] = operator.attrgetter(f"{group}_at")
    return getter
