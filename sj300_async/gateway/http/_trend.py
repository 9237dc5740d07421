"""Each drive's recent trend: its last monitor samples, for the workbench's graph.

Sans-IO. One :class:`Trend` per drive holds the last ``capacity`` monitor
samples (output frequency, current and voltage, with the Unix time each
was read), packed: the newest in plain typed arrays, the older ones in
sealed blocks of :data:`BLOCK` samples. No object is allocated per sample.

Decisions:

- The capacity is the configured window (``trend_s``, 15 min by default)
  over the line's poll interval, plus one sample in ten: a poll cycle
  runs a little longer than its interval when the line is busy, and the
  window must still be covered. So a 0.5 s line keeps 1,980 samples.
- **Integers of what the drive reports.** Times to the millisecond, as the
  CSV download and the event streams give them (:func:`millisecond`);
  values in thousandths (a drive reports 0.01 Hz, 0.01 or 0.1 A, 0.1 V:
  every value comes back as the decimal it was). A value the drive did
  not report (or past 2 million) is :data:`NOT_REPORTED`, served as null.
- **Sealed blocks.** Each :data:`BLOCK` samples are sealed: each column as
  steps from the sample before (a poll's interval, a ramp's slope: small
  numbers, mostly repeated), in one zlib stream at level 6 (a block is
  1,280 bytes: a seventh smaller than at level 1, for microseconds). A 15-minute
  trend at 1 s took 15.5 KiB a drive held plainly (16 bytes a sample); a
  ramping drive's takes a third of that or less, a noisy one's more, never
  more than its steps as they are (a block that does not shrink is kept
  unpacked) (issue 44, CHANGELOG). Sealing costs tens of microseconds, once
  a minute a drive at 1 s; reading the trend unpacks its blocks, which only
  a request does.
- Whole blocks expire: the trend holds the last ``capacity`` samples and
  at most one block more, and serves the last ``capacity``.
- A sample is kept only when the monitor was read again since the last one
  (its time advanced, to the millisecond): a snapshot made by a write's
  read-back or a trip history read repeats the monitor values it had.
"""

from __future__ import annotations

import collections
import itertools
import math
import operator
import zlib
from array import array
from typing import Final

__all__ = ["BLOCK", "NOT_REPORTED", "SAMPLE_BYTES", "Trend", "millisecond", "trend_capacity"]

#: Bytes a sample takes held plainly (a 32-bit time and three 32-bit values): what the
#: trend's memory is measured against.
SAMPLE_BYTES: Final = 4 + 3 * 4
#: Samples per sealed block.
BLOCK: Final = 64
#: A value not reported (or beyond what 32 bits of thousandths hold), served as null.
NOT_REPORTED: Final = -(2**31)
_LARGEST: Final = 2**31 - 1
#: The value columns, in the order a block holds them after the time.
VALUES: Final = ("output_frequency_hz", "output_current_a", "output_voltage_v")

_Columns = tuple["array[int]", "array[int]", "array[int]", "array[int]"]


def trend_capacity(window_s: float, interval_s: float) -> int:
    """Samples needed to cover *window_s* at one sample per *interval_s* (at least 2)."""
    # window * 11 / (10 * interval): one rounding, so 900 s at 0.5 s is 1980, not 1981.
    return max(2, math.ceil(window_s * 11 / (10 * max(interval_s, 0.001))))


def millisecond(unix: float) -> float:
    """*unix* to the millisecond: a time as the trend keeps and serves it."""
    return round(unix * 1000) / 1000


def _thousandths(value: float | None) -> int:
    if value is None or not math.isfinite(value):
        return NOT_REPORTED
    milli = round(value * 1000)
    return milli if -_LARGEST <= milli <= _LARGEST else NOT_REPORTED


def _value(milli: int) -> float | None:
    return None if milli == NOT_REPORTED else milli / 1000


def _steps(values: array[int]) -> array[int]:
    """Each value less the one before (the first as it is), as signed 64-bit."""
    return array("q", itertools.chain(values[:1], map(operator.sub, values[1:], values)))


class _Block:
    """Samples sealed: each column's steps, zlib-packed (or as they are, if not smaller)."""

    __slots__ = ("count", "data", "packed")

    def __init__(self, columns: _Columns) -> None:
        self.count = len(columns[0])
        raw = b"".join(_steps(column).tobytes() for column in columns)
        packed = zlib.compress(raw, 6)
        self.packed = len(packed) < len(raw)
        self.data = packed if self.packed else raw

    def columns(self) -> list[array[int]]:
        raw = zlib.decompress(self.data) if self.packed else self.data
        width = self.count * 8
        out = []
        for at in range(0, len(raw), width):
            steps = array("q")
            steps.frombytes(raw[at : at + width])
            out.append(array("q", itertools.accumulate(steps)))
        return out


def _columns() -> _Columns:
    """The newest samples' columns as they fill: the time in ms, the values in thousandths."""
    return array("q"), array("i"), array("i"), array("i")


class Trend:
    """The last *capacity* samples of one drive (see the module docstring)."""

    __slots__ = ("_blocks", "_in_blocks", "_last_ms", "_live", "capacity")

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"a trend holds at least one sample, got {capacity}")
        self.capacity = capacity
        self._blocks: collections.deque[_Block] = collections.deque()
        self._in_blocks = 0
        self._live = _columns()
        self._last_ms: int | None = None

    def __len__(self) -> int:
        return min(self.capacity, self._in_blocks + len(self._live[0]))

    @property
    def nbytes(self) -> int:
        """The bytes its samples take: the sealed blocks' and the newest arrays' buffers."""
        live = sum(a.buffer_info()[1] * a.itemsize for a in self._live)
        return live + sum(len(block.data) for block in self._blocks)

    @property
    def last_time(self) -> float | None:
        """The time of the newest sample, None when empty."""
        return None if self._last_ms is None else self._last_ms / 1000

    def add(
        self,
        time: float,
        frequency_hz: float | None,
        current_a: float | None,
        voltage_v: float | None,
    ) -> bool:
        """Keep a sample read at Unix *time* (kept to the millisecond); False (nothing
        kept) unless newer than the last."""
        stamp = round(time * 1000)
        if self._last_ms is not None and stamp <= self._last_ms:
            return False
        self._last_ms = stamp
        times, frequency, current, voltage = self._live
        times.append(stamp)
        frequency.append(_thousandths(frequency_hz))
        current.append(_thousandths(current_a))
        voltage.append(_thousandths(voltage_v))
        if len(times) >= BLOCK:
            self._seal()
        return True

    def _seal(self) -> None:
        block = _Block(self._live)
        self._live = _columns()
        self._blocks.append(block)
        self._in_blocks += block.count
        # Whole blocks go once the rest still holds the capacity.
        while self._blocks and self._in_blocks - self._blocks[0].count >= self.capacity:
            self._in_blocks -= self._blocks.popleft().count

    def columns(self, since: float | None = None) -> dict[str, list[float | None]]:
        """The samples newer than *since* (all when None), oldest first, as columns.

        ``{"time": [...], "output_frequency_hz": [...], "output_current_a": [...],
        "output_voltage_v": [...]}``: the shape a chart takes, and JSON's (null: a value
        not reported).
        """
        held: list[list[int]] = [[], [], [], []]
        for block in self._blocks:
            for column, values in zip(held, block.columns(), strict=True):
                column += values
        for column, values in zip(held, self._live, strict=True):
            column += values
        times = held[0]
        first = max(0, len(times) - self.capacity)
        if since is not None:  # compared as served: a client gives back a time it was given
            while first < len(times) and times[first] / 1000 <= since:
                first += 1
        out: dict[str, list[float | None]] = {"time": [t / 1000 for t in times[first:]]}
        for name, column in zip(VALUES, held[1:], strict=True):
            out[name] = [_value(v) for v in column[first:]]
        return out
