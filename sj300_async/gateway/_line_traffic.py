"""A line's recent traffic, recorded by its bus: what a door may show of the wire.

The workbench's line page shows a line's last frames and downloads its last
N seconds as pcapng (``http/_linetrace.py`` words them). The bus is the
core's: a northbound never holds it (issue 42), so the recording, its
window and the tools that read it (the passive sniffer, the capture
writer) live here, and a door asks :meth:`GatewayLine.traffic
<sj300_async.gateway.GatewayLine.traffic>` for them.

Decisions:

- **Record raw, judge when asked.** The bus appends each chunk to a
  bounded log (:data:`KEEP_S` seconds, at most :data:`MAX_RECORDS`, a
  :class:`~sj300_async.bus.ChunkLog`), with no trace record made for it: a
  line nobody looks at costs an append per chunk. What is kept of a chunk
  is its time, direction, bytes and whether the bus found an answer in it
  early, in a few large arrays: the parsed events are not kept alive, the
  garbage collector has nothing to scan, and a plant's lines (64 of them,
  38,400 chunks each in 300 s) take their bytes plus 12 per chunk. A bus
  that has a recorder already (another reader of the same line) is shared,
  not replaced, and left in place by :meth:`LineTraffic.close`.
- A window of frames is read by the passive sniffer
  (:class:`~sj300_async.bus.LineSniffer`, the one ``sj300 sniff`` uses)
  from :data:`LEAD_S` before it, so that the first replies in it find their
  requests.
- **pcapng** goes through the capture writer that ``--capture`` uses
  (:class:`~sj300_async.bus.CaptureFile` on a memory buffer), so the
  download opens in Wireshark with the project's dissector exactly as a
  capture file does.
"""

from __future__ import annotations

import asyncio
import io
import math
import time
from collections.abc import Iterable
from typing import Any, ClassVar, Final

from ..bus import Bus, CaptureFile, ChunkLog, Kept, LineSniffer, TraceRecord

__all__ = ["KEEP_S", "LEAD_S", "MAX_RECORDS", "LineTraffic"]

#: Seconds of a line's traffic kept (the longest download).
KEEP_S: Final = 300.0
#: Chunks kept at most, whatever their age: a fast line's 300 s in bounded memory.
MAX_RECORDS: Final = 50_000
#: Seconds of traffic the sniffer reads before a window, to pair its first replies.
LEAD_S: Final = 2.0


class LineTraffic:
    """One line's recent traffic, recorded from now until :meth:`close` (module docstring)."""

    #: Seconds kept (:data:`KEEP_S`), and chunks kept at most (:data:`MAX_RECORDS`).
    keep_s: ClassVar[float] = KEEP_S
    max_records: ClassVar[int] = MAX_RECORDS

    def __init__(self, name: str, bus: Bus[Any, Any], keep_s: float = KEEP_S) -> None:
        self.name = name
        self._bus = bus
        # The bus's recorder, shared (the same traffic), or one of ours until close().
        existing = bus.recorder
        self._own = existing is None
        self._records = ChunkLog(keep_s, MAX_RECORDS) if existing is None else existing
        if existing is None:
            bus.recorder = self._records
        else:  # shared: it keeps what the longest-sighted of its readers needs
            existing.keep_s = max(existing.keep_s, keep_s)
        #: Unix time minus loop time: the records carry the loop's clock.
        self._offset = time.time() - _loop_time()

    def close(self) -> None:
        """Stop recording the line (when the recorder was this one's own)."""
        if self._own and self._bus.recorder is self._records:
            self._bus.recorder = None

    def unix(self, loop_time: float) -> float:
        """*loop_time* (a record's) in Unix time."""
        return loop_time + self._offset

    def window(self, seconds: float) -> tuple[list[Kept], float]:
        """The records of the last *seconds* (and :data:`LEAD_S` before), and the start."""
        if not self._records:
            return [], 0.0
        start = _loop_time() - seconds
        return list(self._records.since(start - LEAD_S)), start

    def sniffer(self) -> LineSniffer:
        """A passive sniffer for this line's protocol and settings, to read a window."""
        bus = self._bus
        return LineSniffer(bus.dialect, bus.line, bus.timing)

    def pcapng(self, seconds: float) -> bytes:
        """The last *seconds* of the line as a pcapng file (one interface: this line)."""
        records, start = self.window(seconds)
        return self.pcapng_of(records, start, math.inf)

    def span(self, start: float, end: float) -> list[Kept]:
        """The records from loop time *start* to *end*, copied (to write in a thread)."""
        return [kept for kept in self._records.since(start) if kept[0] <= end]

    def pcapng_of(self, records: Iterable[Kept], start: float, end: float) -> bytes:
        """*records* from loop time *start* to *end* as a pcapng file; touches nothing of
        the running line (callable in a thread)."""
        buffer = io.BytesIO()
        capture = CaptureFile(buffer)
        hook = capture.line(self._bus.dialect, self.name, self._bus.line)
        for at, direction, data, _ in records:
            if start <= at <= end:
                hook(TraceRecord(at, direction, data))
        capture.close()
        return buffer.getvalue()


def _loop_time() -> float:
    return asyncio.get_running_loop().time()
