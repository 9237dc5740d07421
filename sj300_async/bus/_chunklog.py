"""A line's recent chunks, kept compactly: time, direction, bytes and the early flag.

Sans-IO. A bus with a recorder (:attr:`~._bus.Bus.recorder`) appends every
chunk it writes and receives here, without the trace hook's record: the
workbench keeps the last 300 seconds of every line's traffic this way (its
line page and pcapng download). At plant scale that is 64 lines, each 134
chunks a second (32 drives, two reads a sample, a request and a reply
each, 34 bytes on average): 2.6 million chunks, 40,000 a line. As a tuple
each (its float, its bytes object, its slot in a deque) a chunk took about
150 bytes; in plain arrays its bytes plus 16, 1.9 MB a line, 58 KiB a
drive; compressed as below 3 to 5 bytes (see CHANGELOG for the figures).

Decisions:

- **Times to the microsecond**, as integers: the resolution of the pcapng
  file the window is downloaded as (``bus/_capture.py``) and far finer than
  any response time the line page shows. A chunk reads back at
  ``round(at * 1e6) / 1e6``.
- **Segments of :data:`SEGMENT` chunks.** The newest is plain arrays, and
  an append is three container appends and a subtraction (every chunk of
  every line comes through it): a chunk's time as a step from the one
  before and its length with its flags in one word are small numbers, what
  zlib packs best. When the segment is full it is **sealed**: the three in
  one zlib stream at level 6, the steps and the marks **byte-shuffled**
  first (all their lowest bytes, then all their next ones...: a step's
  high bytes are zeros, and its low ones vary alike from chunk to chunk,
  so each plane packs far better than the words did). On the simulator's
  poll traffic that is 3.1 bytes a chunk, against 4.3 for the words as
  they are at level 3; level 9 saves nearly nothing more for three times
  the time. A polled line repeats itself, so a segment shrinks about
  tenfold; sealing one costs about 300 microseconds, once per
  :data:`SEGMENT` chunks of a line (every 8 s at the plant's rate), on the
  bus's path: no thread for it.
- **Whole segments expire, judged when a new one starts.** Then a segment
  is dropped if its newest chunk is older than the horizon, or if the
  chunks after it are *max_chunks* or more. The log holds at most
  *max_chunks* plus two segments, and chunks older than *keep_s* only in
  the oldest segment or since the last one started. :meth:`ChunkLog.since`
  is by time, so what is held longer is never shown as newer.
- A chunk is returned as the tuple the trace hook's readers use (time,
  ``"tx"`` or ``"rx"``, its bytes, early): built when read, which the line
  page and the download do (unsealing the segments they need), not when
  written, which every chunk of every line does.
"""

from __future__ import annotations

import collections
import zlib
from array import array
from collections.abc import Iterator
from typing import Final, Literal

__all__ = ["SEGMENT", "ChunkLog", "Kept"]

#: Chunks per segment: the unit of sealing, expiry and allocation.
SEGMENT: Final = 1024
#: A chunk as read back: loop time, direction, its bytes, found early by the bus.
Kept = tuple[float, Literal["tx", "rx"], bytes, bool]

# A chunk's mark: where its bytes end in the segment's data, shifted past two flags.
_RX: Final = 1
_EARLY: Final = 2
_SHIFT: Final = 2
# A mark is 32 bits: a segment holds at most this many bytes (a new one starts first).
_MAX_END: Final = (1 << (32 - _SHIFT)) - 1
# Microseconds per second: a time's unit in the log.
_US: Final = 1_000_000


def _shuffled(words: bytes, width: int) -> bytes:
    """*words* of *width* bytes as planes: every word's first byte, then every second..."""
    return b"".join(words[plane::width] for plane in range(width))


def _unshuffled(planes: memoryview, width: int) -> bytearray:
    """The words :func:`_shuffled` made *planes* of."""
    count = len(planes) // width
    words = bytearray(len(planes))
    for plane in range(width):
        words[plane::width] = planes[plane * count : (plane + 1) * count]
    return words


class _Segment:
    """The newest chunks, in plain arrays, each chunk as a step from the one before."""

    __slots__ = ("data", "marks", "newest", "steps")

    def __init__(self) -> None:
        #: Each chunk's loop time in microseconds, less the one before's (the first: as is).
        self.steps = array("q")
        #: Each chunk's length << _SHIFT | its flags.
        self.marks = array("I")
        self.data = bytearray()
        #: The newest chunk's time in microseconds (0 while empty).
        self.newest = 0

    def __len__(self) -> int:
        return len(self.steps)

    def unsealed(self) -> _Segment:
        return self


class _Sealed:
    """A full segment, compressed: its newest time stays at hand for expiry."""

    __slots__ = ("blob", "count", "newest")

    def __init__(self, segment: _Segment) -> None:
        self.count = len(segment)
        self.newest = segment.newest
        steps = _shuffled(segment.steps.tobytes(), 8)
        marks = _shuffled(segment.marks.tobytes(), 4)
        self.blob = zlib.compress(steps + marks + segment.data, 6)

    def __len__(self) -> int:
        return self.count

    def unsealed(self) -> _Segment:
        raw = memoryview(zlib.decompress(self.blob))
        steps_end = self.count * 8
        marks_end = steps_end + self.count * 4
        segment = _Segment()
        segment.steps.frombytes(_unshuffled(raw[:steps_end], 8))
        segment.marks.frombytes(_unshuffled(raw[steps_end:marks_end], 4))
        segment.data = bytearray(raw[marks_end:])
        segment.newest = self.newest
        return segment


class ChunkLog:
    """The chunks of the last *keep_s* seconds, at most about *max_chunks* of them."""

    def __init__(self, keep_s: float, max_chunks: int, segment: int = SEGMENT) -> None:
        self.keep_s = keep_s
        self.max_chunks = max_chunks
        self.segment = segment
        self._segments: collections.deque[_Segment | _Sealed] = collections.deque()
        self._last = _Segment()
        self._segments.append(self._last)
        #: The chunks of every segment but the last (which is counted by its own length).
        self._sealed = 0

    def __len__(self) -> int:
        return self._sealed + len(self._last)

    @property
    def nbytes(self) -> int:
        """What its segments hold: the sealed ones' streams, the last one's arrays."""
        last = self._last
        sealed = sum(len(s.blob) for s in self._segments if isinstance(s, _Sealed))
        return sealed + len(last.data) + len(last) * 12

    def append(self, at: float, direction: Literal["tx", "rx"], data: bytes, early: bool) -> None:
        """One chunk, at loop time *at* (not before the last one's); *early*: the bus
        refused an answer in it as sooner than the line allows."""
        last = self._last
        if len(last.steps) >= self.segment or len(last.data) + len(data) > _MAX_END:
            last = self._start(at)
        last.data += data
        now = round(at * _US)
        last.steps.append(now - last.newest)
        last.newest = now
        flags = (_RX if direction == "rx" else 0) | (_EARLY if early else 0)
        last.marks.append(len(data) << _SHIFT | flags)

    def _start(self, at: float) -> _Segment:
        """A new last segment, once the old ones past the horizon or the bound are gone
        and the full one is sealed.

        Every chunk of every line is appended: the old segments are judged only
        when a new one starts (hence "plus two segments").
        """
        segments = self._segments
        full = self._last
        self._sealed += len(full)
        if len(full):
            segments[-1] = _Sealed(full)
        horizon = round((at - self.keep_s) * _US)
        while segments and (
            segments[0].newest < horizon or self._sealed - len(segments[0]) >= self.max_chunks
        ):
            self._sealed -= len(segments.popleft())
        self._last = _Segment()
        segments.append(self._last)
        return self._last

    def since(self, start: float) -> Iterator[Kept]:
        """The chunks read back at or after loop time *start*, oldest first."""
        for held in list(self._segments):
            if not len(held) or held.newest / _US < start:
                continue
            segment = held.unsealed()
            data = segment.data
            now = begin = 0
            for step, mark in zip(segment.steps, segment.marks, strict=True):
                now += step
                end = begin + (mark >> _SHIFT)
                at = now / _US
                if at >= start:
                    yield (
                        at,
                        "rx" if mark & _RX else "tx",
                        bytes(data[begin:end]),
                        bool(mark & _EARLY),
                    )
                begin = end
