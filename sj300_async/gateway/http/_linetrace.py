"""The line, seen: each line's recent traffic, judged frame by frame, and as pcapng.

The workbench's line page shows the last frames of a line with their
meaning, who answered whom and how fast, and what went wrong; a button
downloads the last N seconds for Wireshark. :class:`LineTrace` is one
line's record, kept by the bus's recorder (every chunk written and
received, :attr:`~sj300_async.bus.Bus.recorder`).

Decisions:

- **Record raw, judge when asked.** The bus appends each chunk to a
  bounded log (:data:`KEEP_S` seconds, at most :data:`MAX_RECORDS`, a
  :class:`~sj300_async.bus.ChunkLog`), with no trace record made for it: a
  line nobody looks at costs an append per chunk. What is kept of a chunk
  is its time, direction, bytes and whether the bus found an answer in it
  early, in a few large arrays: the parsed events are not kept alive, the
  garbage collector has nothing to scan, and a plant's lines (64 of them,
  38,400 chunks each in 300 s) take their bytes plus 12 per chunk. A
  bus that has a recorder already (another reader of the same line) is
  shared, not replaced. A request for frames
  runs the passive sniffer (:class:`~sj300_async.bus.LineSniffer`, the
  one ``sj300 sniff`` uses) over the window: it splits, pairs each reply
  with its request (response time) and flags bad check codes, broken
  frames, noise, unanswered requests, late and unsolicited replies. It
  starts :data:`LEAD_S` before the window so that the first replies in it
  find their requests.
- **Early answers** are the bus's own verdict (a reply sooner than the
  line's baud rate allows: a wrong baud rate or a second master,
  docs/RELIABILITY.md rule 8): the trace record says which of a chunk's
  events were refused, and the frames that chunk completed are flagged
  ``early``.
- **pcapng** goes through the capture writer that ``--capture`` uses
  (:class:`~sj300_async.bus.CaptureFile` on a memory buffer), so the
  download opens in Wireshark with the project's dissector exactly as a
  capture file does.
"""

from __future__ import annotations

import io
import time
from collections.abc import Iterable
from typing import Any, Final

from ...bus import (
    Bus,
    CaptureFile,
    ChunkLog,
    Kept,
    LineSniffer,
    SniffedFrame,
    TraceRecord,
    Unanswered,
)
from ...profiles import frame_text

__all__ = ["KEEP_S", "LEAD_S", "MAX_RECORDS", "LineTrace"]

#: Seconds of a line's traffic kept (the longest download).
KEEP_S: Final = 300.0
#: Chunks kept at most, whatever their age: a fast line's 300 s in bounded memory.
MAX_RECORDS: Final = 50_000
#: Seconds of traffic the sniffer reads before a window, to pair its first replies.
LEAD_S: Final = 2.0
#: Frames one answer carries at most (the newest).
MAX_FRAMES: Final = 2_000

Json = dict[str, Any]


class LineTrace:
    """One line's recent traffic (see the module docstring); a :data:`TraceHook`."""

    def __init__(self, name: str, bus: Bus[Any, Any]) -> None:
        self.name = name
        self._bus = bus
        # The bus's recorder, shared (the same traffic), or one of ours until close().
        existing = bus.recorder
        self._own = existing is None
        self._records = ChunkLog(KEEP_S, MAX_RECORDS) if existing is None else existing
        if existing is None:
            bus.recorder = self._records
        #: Unix time minus loop time: the records carry the loop's clock.
        self._offset = time.time() - _loop_time()

    def close(self) -> None:
        """Stop recording the line (when the recorder was this trace's own)."""
        if self._own and self._bus.recorder is self._records:
            self._bus.recorder = None

    def unix(self, loop_time: float) -> float:
        return loop_time + self._offset

    def _window(self, seconds: float) -> tuple[list[Kept], float]:
        """The records of the last *seconds* (and :data:`LEAD_S` before), and the start."""
        if not self._records:
            return [], 0.0
        start = _loop_time() - seconds
        return list(self._records.since(start - LEAD_S)), start

    def frames(self, seconds: float, *, node: int | None = None) -> list[Json]:
        """The frames of the last *seconds*, judged, oldest first (at most :data:`MAX_FRAMES`).

        With *node*, only the frames that name it (a request to it, its reply,
        an unanswered request to it); broken frames and noise name no node and
        are left out then.
        """
        records, start = self._window(seconds)
        sniffer = LineSniffer(self._bus.dialect, self._bus.line, self._bus.timing)
        out: list[Json] = []
        for at, direction, data, early in records:
            reports = sniffer.feed(data, at)
            out += self._rows(reports, direction, start, node, early=early and direction == "rx")
        if records:
            out += self._rows(sniffer.tick(_loop_time()), "", start, node, early=False)
        return out[-MAX_FRAMES:]

    def _rows(
        self,
        reports: Iterable[SniffedFrame | Unanswered],
        direction: str,
        start: float,
        node: int | None,
        *,
        early: bool,
    ) -> list[Json]:
        rows = []
        for report in reports:
            if isinstance(report, Unanswered):
                frame = report.request.frame
                if report.time < start or (node is not None and frame.node != node):
                    continue
                rows.append(
                    {
                        "kind": "unanswered",
                        "time": self.unix(report.time),
                        "request": report.request.number,
                        "node": frame.node,
                        "summary": frame.summary,
                        "anomalies": [a.value for a in report.anomalies],
                    }
                )
                continue
            frame = report.frame
            if report.time < start or (node is not None and frame.node != node):
                continue
            anomalies = [a.value for a in report.anomalies]
            if early and frame.valid:
                anomalies.append("early")
            rows.append(
                {
                    "kind": "frame",
                    "n": report.number,
                    "time": self.unix(report.time),
                    "direction": direction,
                    "role": frame.role.value,
                    "node": frame.node,
                    "summary": frame.summary,
                    "text": frame_text(frame.data[:256]),
                    "bytes": len(frame.data),
                    "answers": report.answers,
                    "latency_ms": None
                    if report.latency_s is None
                    else round(report.latency_s * 1000, 3),
                    "anomalies": anomalies,
                }
            )
        return rows

    def pcapng(self, seconds: float) -> bytes:
        """The last *seconds* of the line as a pcapng file (one interface: this line)."""
        records, start = self._window(seconds)
        buffer = io.BytesIO()
        capture = CaptureFile(buffer)
        hook = capture.line(self._bus.dialect, self.name, self._bus.line)
        for at, direction, data, _ in records:
            if at >= start:
                hook(TraceRecord(at, direction, data))
        capture.close()
        return buffer.getvalue()


def _loop_time() -> float:
    import asyncio

    return asyncio.get_running_loop().time()
