"""Each drive's recent trend: its last samples, for the workbench's graph and trip records.

Sans-IO. One :class:`Trend` per drive holds the last ``capacity`` samples
(the Unix time each was read and a fixed set of named values: the
workbench's output frequency, current and voltage by default, every
polled field in the gateway's, :mod:`._trend_columns`), packed: the
newest as varints, the older ones in sealed blocks of :data:`BLOCK`
samples. No object is allocated per sample.

Decisions:

- The capacity is a window over the line's poll interval, plus one
  sample in ten: a poll cycle runs a little longer than its interval when
  the line is busy, and the window must still be covered. So 15 minutes
  of a 0.5 s line keep 1,980 samples.
- **Integers of what the drive reports.** Times to the millisecond, as the
  CSV download and the event streams give them (:func:`millisecond`);
  values in thousandths (a drive reports 0.01 Hz, 0.01 or 0.1 A, 0.1 V:
  every value comes back as the decimal it was). A value the drive did
  not report (or past 2 million) is :data:`NOT_REPORTED`, served as null.
- **Steps, as varints, sealed in blocks.** Each sample is written as it
  comes: each column as its step from the sample before (a poll's
  interval, a ramp's slope, a flag that did not change: small numbers,
  mostly repeated or zero), zigzagged
  and in LEB128 varints (two bytes for a 1 s interval, one for most value
  steps), into one ``bytearray``. Each :data:`BLOCK` samples are sealed:
  zlib level 6 of them (kept as they are if that is not smaller),
  appended to the drive's one buffer of sealed blocks, whose sizes one
  array keeps. A block's first sample is its step from zero, so a block
  reads on its own and the oldest is dropped by cutting its bytes off the
  buffer's front. A 15-minute trend at 0.5 s is 31 KiB a drive held
  plainly (16 bytes a sample); a ramping drive's now takes 2.7 KiB with
  its objects, where a deque of block objects and four typed
  arrays took 7.2 KiB (issue 44, CHANGELOG). Writing a sample costs about
  a tenth of a microsecond more than four array appends did; reading the
  trend decodes its varints in Python (about 1 ms for 1,000 samples),
  which only a request does.
- Whole blocks expire: the trend holds the last ``capacity`` samples and
  at most one block more, and serves the last ``capacity``.
- A sample is kept only when the monitor was read again since the last one
  (its time advanced, to the millisecond): a snapshot made by a write's
  read-back or a trip history read repeats the monitor values it had.
"""

from __future__ import annotations

import itertools
import math
import zlib
from array import array
from typing import Final

__all__ = ["BLOCK", "NOT_REPORTED", "SAMPLE_BYTES", "Trend", "millisecond", "trend_capacity"]

#: Bytes a sample of the workbench's three values takes held plainly (a 32-bit time and
#: three 32-bit values): what the trend's memory is measured against.
SAMPLE_BYTES: Final = 4 + 3 * 4
#: Samples per sealed block.
BLOCK: Final = 64
#: A value not reported (or beyond what 32 bits of thousandths hold), served as null.
NOT_REPORTED: Final = -(2**31)
_LARGEST: Final = 2**31 - 1
# Beyond any value whose thousandths fit, and finite (Trend.add's first test).
_BOUND: Final = float(2**31)
#: The workbench's value columns (a trend's default), in the order a block holds them.
VALUES: Final = ("output_frequency_hz", "output_current_a", "output_voltage_v")


def trend_capacity(window_s: float, interval_s: float) -> int:
    """Samples needed to cover *window_s* at one sample per *interval_s* (at least 2)."""
    # window * 11 / (10 * interval): one rounding, so 900 s at 0.5 s is 1980, not 1981.
    return max(2, math.ceil(window_s * 11 / (10 * max(interval_s, 0.001))))


def millisecond(unix: float) -> float:
    """*unix* to the millisecond: a time as the trend keeps and serves it."""
    return round(unix * 1000) / 1000


def _value(milli: int) -> float | None:
    return None if milli == NOT_REPORTED else milli / 1000


def _samples(data: bytes | bytearray | memoryview, width: int) -> list[list[int]]:
    """A block's samples (its varints, *width* to a sample, each a step from the one
    before, the first from zero), as its *width* columns of values."""
    steps: list[int] = []
    wide = shift = 0
    for byte in data:
        wide |= (byte & 0x7F) << shift
        if byte & 0x80:
            shift += 7
        else:
            steps.append(wide >> 1 ^ -(wide & 1))
            wide = shift = 0
    return [list(itertools.accumulate(steps[column::width])) for column in range(width)]


class Trend:
    """The last *capacity* samples of one drive (see the module docstring)."""

    __slots__ = ("_count", "_in_blocks", "_last", "_last_ms", "_live", "_origin", "_sealed",
                 "_sizes", "capacity", "names")  # fmt: skip

    def __init__(self, capacity: int, names: tuple[str, ...] = VALUES) -> None:
        if capacity < 1:
            raise ValueError(f"a trend holds at least one sample, got {capacity}")
        self.capacity = capacity
        #: The value columns' names, in the order :meth:`add` takes them.
        self.names = names
        #: The sealed blocks, oldest first, one after the other.
        self._sealed = bytearray()
        #: Each sealed block's size in bytes << 1, | 1 when zlib-packed.
        self._sizes = array("I")
        self._in_blocks = 0
        #: The newest samples' varints, and how many samples they are.
        self._live = bytearray()
        self._count = 0
        #: The newest sample's integers (the zeros at a block's start).
        self._origin = [0] * (1 + len(names))
        self._last: list[int] = self._origin
        self._last_ms: int | None = None

    def __len__(self) -> int:
        return min(self.capacity, self._in_blocks + self._count)

    @property
    def nbytes(self) -> int:
        """The bytes its samples take: the sealed blocks, their sizes, the newest varints."""
        return len(self._sealed) + 4 * len(self._sizes) + len(self._live)

    @property
    def last_time(self) -> float | None:
        """The time of the newest sample, None when empty."""
        return None if self._last_ms is None else self._last_ms / 1000

    def add(self, time: float, *values: float | None) -> bool:
        """Keep a sample read at Unix *time* (kept to the millisecond), one value per
        name; False (nothing kept) unless newer than the last."""
        stamp = round(time * 1000)
        if self._last_ms is not None and stamp <= self._last_ms:
            return False
        if len(values) != len(self.names):
            raise ValueError(f"a sample of {self.names} takes {len(self.names)} values")
        self._last_ms = stamp
        # Every drive's every sample comes through here (10 columns at least): each value
        # to thousandths and each step to a zigzag LEB128 varint, written out in plain
        # loops (helper calls were a third of its time; Python 3.11's comprehensions cost
        # more than they save at this size). A value within _BOUND is finite (NaN fails
        # the comparison) and its thousandths are judged against 32 bits.
        sample = [stamp]
        for value in values:
            if value is None or not -_BOUND <= value <= _BOUND:
                sample.append(NOT_REPORTED)
            else:
                milli = round(value * 1000)
                sample.append(milli if -_LARGEST <= milli <= _LARGEST else NOT_REPORTED)
        live = self._live
        for value, last in zip(sample, self._last, strict=True):
            step = value - last
            wide = step << 1 if step >= 0 else ~step << 1 | 1
            while wide > 0x7F:
                live.append(wide & 0x7F | 0x80)
                wide >>= 7
            live.append(wide)
        self._last = sample
        self._count += 1
        if self._count >= BLOCK:
            self._seal()
        return True

    def _seal(self) -> None:
        raw = bytes(self._live)
        packed = zlib.compress(raw, 6)
        if len(packed) < len(raw):
            self._sealed += packed
            self._sizes.append(len(packed) << 1 | 1)
        else:
            self._sealed += raw
            self._sizes.append(len(raw) << 1)
        self._in_blocks += self._count
        self._live = bytearray()
        self._count = 0
        self._last = self._origin
        # Whole blocks go once the rest still holds the capacity.
        while self._sizes and self._in_blocks - BLOCK >= self.capacity:
            del self._sealed[: self._sizes[0] >> 1]
            del self._sizes[0]
            self._in_blocks -= BLOCK

    def columns(
        self, since: float | None = None, *, until: float | None = None, last: int | None = None
    ) -> dict[str, list[float | None]]:
        """The samples newer than *since* and not newer than *until* (all when None) of
        the *last* held (all when None), oldest first, as columns.

        ``{"time": [...], "output_frequency_hz": [...], ...}``, a list per name: the
        shape a chart takes, and JSON's (null: a value not reported).
        """
        width = 1 + len(self.names)
        held: list[list[int]] = [[] for _ in range(width)]
        at = 0
        with memoryview(self._sealed) as sealed:
            for size in self._sizes:
                block = sealed[at : at + (size >> 1)]
                at += size >> 1
                unpacked = zlib.decompress(block) if size & 1 else block
                for column, values in zip(held, _samples(unpacked, width), strict=True):
                    column += values
        for column, values in zip(held, _samples(self._live, width), strict=True):
            column += values
        times = held[0]
        first = max(0, len(times) - min(self.capacity, self.capacity if last is None else last))
        end = len(times)
        if since is not None:  # compared as served: a client gives back a time it was given
            while first < end and times[first] / 1000 <= since:
                first += 1
        if until is not None:
            while end > first and times[end - 1] / 1000 > until:
                end -= 1
        out: dict[str, list[float | None]] = {"time": [t / 1000 for t in times[first:end]]}
        for name, column in zip(self.names, held[1:], strict=True):
            out[name] = [_value(v) for v in column[first:end]]
        return out
