"""Each drive's recent trend: a bounded ring of monitor samples, for the workbench's graph.

Sans-IO. One :class:`Trend` per drive holds the last ``capacity`` monitor
samples (output frequency, current and voltage, with the Unix time each
was read), in preallocated typed arrays: its memory is fixed when it is
made, whatever the drive does, and no object is allocated per sample.

Decisions:

- The capacity is the configured window (``trend_s``, 15 min by default)
  over the line's poll interval, plus one sample in ten: a poll cycle
  runs a little longer than its interval when the line is busy, and the
  window must still be covered. So a 0.5 s line keeps 1,980 samples.
- Times to the millisecond, as the CSV download and the event streams give
  them (:func:`millisecond`): 32-bit offsets from a base in whole
  milliseconds, the first sample's. 49.7 days fit; past that the base moves
  to the oldest sample kept, or the trend starts again when the samples
  kept span more than that (a drive back after seven weeks). The values
  float32: seven significant digits are more than any drive reports
  (0.01 Hz, 0.1 A, 0.1 V). A sample is 16 bytes: 15.5 KiB a drive at the
  plant's 1 s, 20 with float64 times (issue 44).
- A sample is kept only when the monitor was read again since the last one
  (its time advanced): a snapshot made by a write's read-back or a trip
  history read repeats the monitor values it already had.
- A value the drive did not report is stored as NaN and served as null.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterator
from typing import Final

__all__ = ["SAMPLE_BYTES", "Trend", "millisecond", "trend_capacity"]

#: Bytes one sample takes: a 32-bit time and three float32 values.
SAMPLE_BYTES: Final = 4 + 3 * 4
#: The largest offset from the base, in milliseconds (49.7 days).
MAX_OFFSET_MS: Final = 2**32 - 1


def millisecond(unix: float) -> float:
    """*unix* to the millisecond: a time as the trend keeps and serves it."""
    return round(unix * 1000) / 1000


def trend_capacity(window_s: float, interval_s: float) -> int:
    """Samples needed to cover *window_s* at one sample per *interval_s* (at least 2)."""
    # window * 11 / (10 * interval): one rounding, so 900 s at 0.5 s is 1980, not 1981.
    return max(2, math.ceil(window_s * 11 / (10 * max(interval_s, 0.001))))


class Trend:
    """The last *capacity* samples of one drive (see the module docstring)."""

    __slots__ = (
        "_base_ms",
        "_current",
        "_frequency",
        "_next",
        "_size",
        "_times",
        "_voltage",
        "capacity",
    )

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"a trend holds at least one sample, got {capacity}")
        self.capacity = capacity
        # Repeated, not built from bytes: array(code, bytes(n)) reserves 1/16 more than it
        # holds (CPython's growth rule), 2.5 kB per drive at the default window.
        #: Each sample's milliseconds after _base_ms.
        self._times = array("I", [0]) * capacity
        self._base_ms = 0
        self._frequency = array("f", [0.0]) * capacity
        self._current = array("f", [0.0]) * capacity
        self._voltage = array("f", [0.0]) * capacity
        self._next = 0
        self._size = 0

    def __len__(self) -> int:
        return self._size

    @property
    def nbytes(self) -> int:
        """The memory its arrays hold (their buffers, not the Python objects around them)."""
        arrays = (self._times, self._frequency, self._current, self._voltage)
        return sum(a.buffer_info()[1] * a.itemsize for a in arrays)

    @property
    def last_time(self) -> float | None:
        """The time of the newest sample, None when empty."""
        if not self._size:
            return None
        return self._time((self._next - 1) % self.capacity)

    def _time(self, at: int) -> float:
        # An integer over 1000: the double nearest the millisecond, as millisecond() gives.
        return (self._base_ms + self._times[at]) / 1000

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
        if not self._size:
            self._base_ms = stamp
        elif stamp <= self._base_ms + self._times[(self._next - 1) % self.capacity]:
            return False
        offset = stamp - self._base_ms
        if offset > MAX_OFFSET_MS:
            offset = self._rebase(stamp)
        at = self._next
        self._times[at] = offset
        self._frequency[at] = math.nan if frequency_hz is None else frequency_hz
        self._current[at] = math.nan if current_a is None else current_a
        self._voltage[at] = math.nan if voltage_v is None else voltage_v
        self._next = (at + 1) % self.capacity
        self._size = min(self._size + 1, self.capacity)
        return True

    def _rebase(self, stamp: int) -> int:
        """The base moved to the oldest sample this one will not replace (the trend
        emptied if that is not enough); *stamp*'s offset from the new one."""
        keeps = self._size - (self._size == self.capacity)
        if keeps == 0:
            shift = stamp - self._base_ms
        else:
            shift = self._times[(self._next - keeps) % self.capacity]
        if stamp - (self._base_ms + shift) > MAX_OFFSET_MS:
            self._size = 0
            self._base_ms = stamp
            return 0
        for at in self._indices(None):
            self._times[at] = max(0, self._times[at] - shift)  # the one replaced: any
        self._base_ms += shift
        return stamp - self._base_ms

    def _indices(self, since: float | None) -> Iterator[int]:
        start = (self._next - self._size) % self.capacity
        for offset in range(self._size):
            at = (start + offset) % self.capacity
            if since is None or self._time(at) > since:
                yield at

    def columns(self, since: float | None = None) -> dict[str, list[float | None]]:
        """The samples newer than *since* (all when None), oldest first, as columns.

        ``{"time": [...], "output_frequency_hz": [...], "output_current_a": [...],
        "output_voltage_v": [...]}``: the shape a chart takes, and JSON's (NaN -> None).
        """
        rows = list(self._indices(since))
        return {
            "time": [self._time(at) for at in rows],
            "output_frequency_hz": [_value(self._frequency[at]) for at in rows],
            "output_current_a": [_value(self._current[at]) for at in rows],
            "output_voltage_v": [_value(self._voltage[at]) for at in rows],
        }


def _value(number: float) -> float | None:
    # float32 -> shortest decimal that reads back as the same float32 (no 49.990001).
    return None if math.isnan(number) else float(f"{number:.7g}")
