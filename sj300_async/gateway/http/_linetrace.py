"""The line, seen: each line's recent traffic, judged frame by frame, and as pcapng.

The workbench's line page shows the last frames of a line with their
meaning, who answered whom and how fast, and what went wrong; a button
downloads the last N seconds for Wireshark. :class:`LineTrace` words one
line's :class:`~sj300_async.gateway.LineTraffic` (the core's recording of
the bus, its window, its sniffer and its pcapng) as the page's JSON.

- A request for frames runs the line's passive sniffer over the window: it
  splits, pairs each reply with its request (response time) and flags bad
  check codes, broken frames, noise, unanswered requests, late and
  unsolicited replies.
- **Early answers** are the bus's own verdict (a reply sooner than the
  line's baud rate allows: a wrong baud rate or a second master,
  docs/RELIABILITY.md rule 8): the trace record says which of a chunk's
  events were refused, and the frames that chunk completed are flagged
  ``early``.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import Any, Final

from ...bus import SniffedFrame, Unanswered
from ...profiles import frame_text
from .. import LineTraffic

__all__ = ["KEEP_S", "MAX_FRAMES", "MAX_RECORDS", "LineTrace"]

#: Seconds of a line's traffic kept (the longest download), and chunks at most.
KEEP_S: Final = LineTraffic.keep_s
MAX_RECORDS: Final = LineTraffic.max_records
#: Frames one answer carries at most (the newest).
MAX_FRAMES: Final = 2_000

Json = dict[str, Any]


class LineTrace:
    """One line's recent traffic as the workbench shows it (see the module docstring)."""

    def __init__(self, traffic: LineTraffic) -> None:
        self.name = traffic.name
        self.traffic = traffic

    def close(self) -> None:
        """Stop recording the line (when the recorder was this trace's own)."""
        self.traffic.close()

    def frames(self, seconds: float, *, node: int | None = None) -> list[Json]:
        """The frames of the last *seconds*, judged, oldest first (at most :data:`MAX_FRAMES`).

        With *node*, only the frames that name it (a request to it, its reply,
        an unanswered request to it); broken frames and noise name no node and
        are left out then.
        """
        traffic = self.traffic
        records, start = traffic.window(seconds)
        sniffer = traffic.sniffer()
        out: list[Json] = []
        for at, direction, data, early in records:
            reports = sniffer.feed(data, at)
            out += self._rows(reports, direction, start, node, early=early and direction == "rx")
        if records:
            now = asyncio.get_running_loop().time()
            out += self._rows(sniffer.tick(now), "", start, node, early=False)
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
                        "time": self.traffic.unix(report.time),
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
                    "time": self.traffic.unix(report.time),
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
        return self.traffic.pcapng(seconds)
