"""A line's recent chunks, kept compactly: time, direction, bytes and the early flag.

Sans-IO. A bus with a recorder (:attr:`~._bus.Bus.recorder`) appends every
chunk it writes and receives here, without the trace hook's record: the
workbench keeps the last 300 seconds of every line's traffic this way (its
line page and pcapng download). At plant scale that is 64 lines, each 128
chunks a second (32 drives, two reads a sample, a request and a reply
each): 2.5 million chunks. As a tuple each (its float, its bytes object,
its slot in a deque) a chunk took about 150 bytes; here it takes its bytes
plus 12, in a few large arrays per :data:`SEGMENT` chunks (see CHANGELOG
for the figures).

Decisions:

- **Whole segments expire, judged when a new one starts.** Then a segment
  is dropped if its newest chunk is older than the horizon, or if the
  chunks after it are *max_chunks* or more. An append is three container
  appends (every chunk of every line comes through it: a chunk's end in
  the segment's bytes and its flags share one word); the log holds at most
  *max_chunks* plus two segments, and chunks older than *keep_s* only in
  the oldest segment or since the last one started. :meth:`ChunkLog.since`
  is by time, so what is held longer is never shown as newer.
- A chunk is returned as the tuple the trace hook's readers use (time,
  ``"tx"`` or ``"rx"``, its bytes, early): built when read, which the line
  page and the download do, not when written, which every chunk of every
  line does.
"""

from __future__ import annotations

import bisect
import collections
from array import array
from collections.abc import Iterator
from typing import Final, Literal

__all__ = ["SEGMENT", "ChunkLog", "Kept"]

#: Chunks per segment: the unit of expiry and of allocation.
SEGMENT: Final = 4096
#: A chunk as read back: loop time, direction, its bytes, found early by the bus.
Kept = tuple[float, Literal["tx", "rx"], bytes, bool]

# A chunk's mark: where its bytes end in the segment's data, shifted past two flags.
_RX: Final = 1
_EARLY: Final = 2
_SHIFT: Final = 2
# A mark is 32 bits: a segment holds at most this many bytes (a new one starts first).
_MAX_END: Final = (1 << (32 - _SHIFT)) - 1


class _Segment:
    __slots__ = ("data", "marks", "times")

    def __init__(self) -> None:
        self.times = array("d")
        #: Each chunk's end in data << _SHIFT | its flags.
        self.marks = array("I")
        self.data = bytearray()


class ChunkLog:
    """The chunks of the last *keep_s* seconds, at most about *max_chunks* of them."""

    def __init__(self, keep_s: float, max_chunks: int, segment: int = SEGMENT) -> None:
        self.keep_s = keep_s
        self.max_chunks = max_chunks
        self.segment = segment
        self._segments: collections.deque[_Segment] = collections.deque()
        self._last = _Segment()
        self._segments.append(self._last)
        #: The chunks of every segment but the last (which is counted by its own length).
        self._sealed = 0

    def __len__(self) -> int:
        return self._sealed + len(self._last.times)

    def append(self, at: float, direction: Literal["tx", "rx"], data: bytes, early: bool) -> None:
        """One chunk, at loop time *at* (not before the last one's); *early*: the bus
        refused an answer in it as sooner than the line allows."""
        last = self._last
        if len(last.times) >= self.segment or len(last.data) + len(data) > _MAX_END:
            last = self._start(at)
        buffer = last.data
        buffer += data
        last.times.append(at)
        flags = (_RX if direction == "rx" else 0) | (_EARLY if early else 0)
        last.marks.append(len(buffer) << _SHIFT | flags)

    def _start(self, at: float) -> _Segment:
        """A new last segment, once the old ones past the horizon or the bound are gone.

        Every chunk of every line is appended: the old segments are judged only
        when a new one starts (hence "plus two segments").
        """
        segments = self._segments
        self._sealed += len(self._last.times)
        horizon = at - self.keep_s
        while segments and (
            segments[0].times[-1] < horizon
            or self._sealed - len(segments[0].times) >= self.max_chunks
        ):
            self._sealed -= len(segments.popleft().times)
        self._last = _Segment()
        segments.append(self._last)
        return self._last

    def since(self, start: float) -> Iterator[Kept]:
        """The chunks at or after loop time *start*, oldest first."""
        for segment in list(self._segments):
            times = segment.times
            if not times or times[-1] < start:
                continue
            first = bisect.bisect_left(times, start)
            marks, data = segment.marks, segment.data
            begin = marks[first - 1] >> _SHIFT if first else 0
            for i in range(first, len(times)):
                mark = marks[i]
                end = mark >> _SHIFT
                yield (
                    times[i],
                    "rx" if mark & _RX else "tx",
                    bytes(data[begin:end]),
                    bool(mark & _EARLY),
                )
                begin = end
