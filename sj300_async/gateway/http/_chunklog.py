"""A line's recent chunks, kept compactly: time, direction, bytes and the early flag.

Sans-IO. The workbench keeps the last :data:`~._linetrace.KEEP_S` seconds
of every line's traffic (the line page and its pcapng download). At plant
scale that is 64 lines, each 128 chunks a second (32 drives, two reads a
sample, a request and a reply each): 2.5 million chunks. As a tuple each
(its float, its bytes object, its slot in a deque) a chunk took about 150
bytes; here it takes its bytes plus 13, in a few large arrays per
:data:`SEGMENT` chunks (see CHANGELOG for the figures).

Decisions:

- **Whole segments expire, judged when a new one starts.** Then a segment
  is dropped if its newest chunk is older than the horizon, or if the
  chunks after it are *max_chunks* or more. An append is four array
  appends (every chunk of every line comes through it); the log holds at
  most *max_chunks* plus two segments, and chunks older than *keep_s* only
  in the oldest segment or since the last one started. :meth:`ChunkLog.since`
  is by time, so what is held longer is never shown as newer.
- A chunk is returned as the tuple the trace used before (time, ``"tx"``
  or ``"rx"``, its bytes, early): built when read, which the line page and
  the download do, not when written, which every chunk of every line does.
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

_RX: Final = 1
_EARLY: Final = 2


class _Segment:
    __slots__ = ("data", "ends", "flags", "times")

    def __init__(self) -> None:
        self.times = array("d")
        #: Where each chunk's bytes end in data.
        self.ends = array("I")
        self.flags = array("B")
        self.data = bytearray()

    def __len__(self) -> int:
        return len(self.times)


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
        return self._sealed + len(self._last)

    def append(self, at: float, direction: Literal["tx", "rx"], data: bytes, early: bool) -> None:
        """One chunk, at loop time *at* (not before the last one's).

        Every chunk of every line comes through here: the old segments are
        judged only when a new one starts (hence "plus two segments").
        """
        last = self._last
        if len(last.times) >= self.segment:
            last = self._start(at)
        last.data += data
        last.times.append(at)
        last.ends.append(len(last.data))
        last.flags.append(_RX * (direction == "rx") | _EARLY * early)

    def _start(self, at: float) -> _Segment:
        """A new last segment, once the old ones past the horizon or the bound are gone."""
        segments = self._segments
        self._sealed += len(self._last)
        horizon = at - self.keep_s
        while segments and (
            segments[0].times[-1] < horizon or self._sealed - len(segments[0]) >= self.max_chunks
        ):
            self._sealed -= len(segments.popleft())
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
            ends, flags, data = segment.ends, segment.flags, segment.data
            begin = ends[first - 1] if first else 0
            for i in range(first, len(times)):
                end = ends[i]
                flag = flags[i]
                yield (
                    times[i],
                    "rx" if flag & _RX else "tx",
                    bytes(data[begin:end]),
                    bool(flag & _EARLY),
                )
                begin = end
