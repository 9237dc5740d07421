"""Unit 255 of a listener: a record of every drive it serves, side by side.

Sans-IO. A SCADA that reads each drive's unit makes two requests a drive
per scan: 4,096 a second for a plant of 2,048 drives, each a round trip
and a wake-up of the gateway. The summary gives it the values a plant
overview needs for 15 drives in one read of 120 registers (a
listener of 224 drives in 15 reads).

Decisions:

- **Unit 255**, on every listener, read-only. Modbus TCP addresses a
  server itself with unit id 0xFF; drives have 1..247, so it can never be
  a drive's. Writes are refused with 0x01, like a write to any read-only
  register; the drives' own units are where commands go.
- **Drive u's record is registers 8u..8u+7** (:data:`SUMMARY_RECORD`), so a SCADA
  finds a drive by the unit id it already knows. Registers 0..7 are the
  listener's own (drives served, drives online); 8 x 248 = 1,984
  registers in all, past them 0x02. "Online" is the poller's verdict and an
  answer heard at least once (register 0 of a drive's unit may read 1
  before its first answer).
- **A read never fails for one drive's sake** (the drives' own units
  answer 0x0B for stale data; here one stale drive would hide fifteen).
  Each record's first register says which of its values are current, a
  bit per group (:class:`SummaryBits`); a value not current reads 0 with its
  bit clear. Current is the gateway's judgement, not the summary's: a
  group's deadline on the drive as served (``served.status_until``...,
  :class:`~sj300_async.gateway.ServedDrive`), the one the drive's own unit
  answers 0x0B by; the lease holder is the served view's too. A value the
  drive's protocol does not give reads 0 with its group's bit set (the
  drive's own unit answers 0x0B for it; the SJ300 and FR-700 give every
  one). A unit id with no drive has an all-zero record.
- **Not cached.** Every read computes its records from the drives' latest
  served views (about 0.3 us a register here): a read covers fifteen drives,
  each with a sample of its own, so an answer would rarely be served twice.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from typing import Final

from ...profiles import DriveSnapshot
from .. import GatewayDrive, ServedDrive
from ._framing import Exc

__all__ = [
    "SUMMARY_RECORD",
    "SUMMARY_SLOTS",
    "SUMMARY_UNIT",
    "Summary",
    "SummaryBits",
    "SummaryField",
    "record",
]

#: The unit id of a listener's summary.
SUMMARY_UNIT: Final = 255
#: Registers per drive's record.
SUMMARY_RECORD: Final = 8
#: Record slots: slot 0 is the listener's, slots 1..247 the drives'.
SUMMARY_SLOTS: Final = 248


class SummaryBits(enum.IntFlag):
    """A record's first register: what the drive's values in it are worth."""

    #: A drive of this listener has this unit id.
    PRESENT = 1 << 0
    #: The poller's verdict is online, and the drive has answered at least once.
    ONLINE = 1 << 1
    #: The status is current: RUNNING and TRIPPED below say so.
    STATUS = 1 << 2
    RUNNING = 1 << 3
    TRIPPED = 1 << 4
    #: The monitor is current: output frequency, current and voltage.
    MONITOR = 1 << 5
    #: The direction is current.
    DIRECTION = 1 << 6
    #: The set frequency, as last read back, is current.
    SET_FREQUENCY = 1 << 7
    #: Some client holds the drive's control lease.
    LEASED = 1 << 8


class SummaryField(enum.IntEnum):
    """The registers of a drive's record, by offset."""

    BITS = 0  #: :class:`SummaryBits`
    AGE_S = 1  #: seconds since the last good sample (65535: never)
    OUTPUT_FREQUENCY = 2  #: 0.01 Hz
    OUTPUT_CURRENT = 3  #: 0.1 A
    OUTPUT_VOLTAGE = 4  #: 0.1 V
    DIRECTION = 5  #: 0 stop, 1 forward, 2 reverse
    SET_FREQUENCY = 6  #: 0.01 Hz
    TRIP = 7  #: the trip the drive is in: its number (0: none, or its history not read yet)


_EMPTY: Final = (0,) * SUMMARY_RECORD
# The bits as plain ints: an IntFlag's | makes a flag object each time (2 us a record).
_PRESENT: Final = int(SummaryBits.PRESENT)
_ONLINE: Final = int(SummaryBits.ONLINE)
_STATUS: Final = int(SummaryBits.STATUS)
_RUNNING: Final = int(SummaryBits.RUNNING)
_TRIPPED: Final = int(SummaryBits.TRIPPED)
_MONITOR: Final = int(SummaryBits.MONITOR)
_DIRECTION: Final = int(SummaryBits.DIRECTION)
_SET_FREQUENCY: Final = int(SummaryBits.SET_FREQUENCY)
_LEASED: Final = int(SummaryBits.LEASED)


def _word(value: float | None, per_unit: float) -> int:
    """*value* in counts of ``1 / per_unit``, saturated to a register; 0 when unknown."""
    if value is None or not math.isfinite(value):
        return 0
    counts = round(value * per_unit)
    return 0 if counts < 0 else 0xFFFF if counts > 0xFFFF else counts


def record(served: ServedDrive, now: float) -> list[int]:
    """The record of the drive *served* (its latest served view) at loop time *now*.

    Each group's bit is a compare of *now* with its served deadline (see the
    module docstring): a plant's read of 247 records makes no call per group.
    """
    s: DriveSnapshot = served.snapshot
    bits = _PRESENT
    if s.available:
        bits |= _ONLINE
    tripped = False
    if now <= served.status_until:
        bits |= _STATUS
        tripped = bool(s.tripped)
        if s.running:
            bits |= _RUNNING
        if tripped:
            bits |= _TRIPPED
    frequency = current = voltage = 0
    if now <= served.monitor_until:
        bits |= _MONITOR
        frequency = _word(s.output_frequency_hz, 100)
        current = _word(s.output_current_a, 10)
        voltage = _word(s.output_voltage_v, 10)
    direction = 0
    if s.direction is not None and now <= served.direction_until:
        bits |= _DIRECTION
        direction = int(s.direction)
    set_frequency = 0
    if now <= served.set_frequency_until:
        bits |= _SET_FREQUENCY
        set_frequency = _word(s.set_frequency_hz, 100)
    if served.lease_holder(now) is not None:
        bits |= _LEASED
    age = s.sample_age_s(now)
    trip = s.trip.number if tripped and s.trip is not None else 0
    return [
        bits,
        65535 if age is None else min(65535, math.floor(age)),
        frequency,
        current,
        voltage,
        direction,
        set_frequency,
        min(trip, 0xFFFF),
    ]


class Summary:
    """The summary of one listener's drives (see the module docstring)."""

    def __init__(self, drives: Mapping[int, GatewayDrive]) -> None:
        """*drives* by unit id, each 1..247 (the configuration's rule: 255 is this one's).

        Raises:
            ValueError: a unit id outside 1..247.
        """
        wrong = sorted(unit for unit in drives if not 1 <= unit < SUMMARY_SLOTS)
        if wrong:
            raise ValueError(f"unit ids outside 1..{SUMMARY_SLOTS - 1}: {wrong}")
        self.drives = dict(drives)

    def read(self, address: int, count: int, now: float) -> list[int] | Exc:
        """*count* registers from *address*, or 0x02 when any is past the last record."""
        end = address + count
        if end > SUMMARY_RECORD * SUMMARY_SLOTS:
            return Exc.ILLEGAL_ADDRESS
        first, last = address // SUMMARY_RECORD, (end - 1) // SUMMARY_RECORD
        words: list[int] = []
        for slot in range(first, last + 1):
            if slot == 0:
                words += self._header()
                continue
            drive = self.drives.get(slot)
            words += _EMPTY if drive is None else record(drive.served, now)
        offset = address - first * SUMMARY_RECORD
        return words[offset : offset + count]

    def _header(self) -> list[int]:
        online = sum(drive.served.snapshot.available for drive in self.drives.values())
        return [len(self.drives), online, 0, 0, 0, 0, 0, 0]
