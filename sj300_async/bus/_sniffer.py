"""The passive sniffer's judgement: frames in, paired and flagged (sans-IO).

A tap hears the whole line in one stream. :class:`LineSniffer` splits it
with the protocol's line framer, tells requests from replies by content
(``classify(outbound=None)``, helped by the request still pending), pairs
each reply with the request it answers (``Dialect.answers``), and flags:

- ``bad check code``: a frame whose check code is wrong (the dialect's
  framer says so); ``broken frame``: any other invalid frame; ``noise``:
  bytes outside any frame;
- ``unanswered``: a request that expects an answer and got none by its
  time-out (reported when the time-out passes, by :meth:`LineSniffer.tick`
  or the next chunk). A broken frame within the time-out counts as its
  answer (flagged itself), so a corrupted reply is not reported twice;
- ``late reply``: the answer to a request that was already unanswered,
  arriving before the next request;
- ``unsolicited``: a reply that answers no request on the line (a
  duplicate, a drive answering nobody, or the other master's);
- ``two masters``: a request while another one still waits for its
  answer, within its time-out: no single master does that. The request it
  interrupted keeps waiting (up to :data:`MAX_INTERRUPTED` of them), so its
  answer is still paired, and it is still reported unanswered when its
  time-out passes without one.

The time-out is the one the host computes (:meth:`BusTiming.response_timeout`
with the request's longest reply and processing time), counted from the
request's first byte: the sniffer sees a frame when it ends, so it
subtracts the request's wire time. A master whose time-out is longer than
that (a large C078 wait, a generous ``--timeout``) gets its slow answers
flagged late; give the sniffer the same ``timeout``.
"""

from __future__ import annotations

import enum
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Final

from ..wire import FrameRole, LineFrame, LineSettings
from ._dialect import Dialect, LineRequest
from ._timing import BusTiming

__all__ = [
    "MAX_INTERRUPTED",
    "Anomaly",
    "LineSniffer",
    "SniffedFrame",
    "SnifferStats",
    "Unanswered",
]

#: Requests interrupted by another master's that keep waiting for their answers; the
#: oldest is forgotten beyond this (a line of many masters needs no more to be judged).
MAX_INTERRUPTED: Final = 8


class Anomaly(enum.Enum):
    """What the sniffer flags (see the module docstring)."""

    BAD_CHECK = "bad check code"
    BROKEN = "broken frame"
    NOISE = "noise"
    UNANSWERED = "unanswered"
    LATE = "late reply"
    UNSOLICITED = "unsolicited"
    TWO_MASTERS = "two masters"


@dataclass(frozen=True, slots=True)
class SniffedFrame:
    """One piece of the line, as the sniffer judged it."""

    #: 1, 2, ... in line order.
    number: int
    #: When the sniffer had the whole piece (the clock of :meth:`LineSniffer.feed`).
    time: float
    frame: LineFrame
    anomalies: tuple[Anomaly, ...] = ()
    #: A reply: the number of the request it answers, and the time since that request ended.
    answers: int | None = None
    latency_s: float | None = None


@dataclass(frozen=True, slots=True)
class Unanswered:
    """A request whose time-out passed without an answer (reported at that time)."""

    request: SniffedFrame
    time: float
    anomalies: tuple[Anomaly, ...] = (Anomaly.UNANSWERED,)


@dataclass(slots=True)
class _Waiting:
    sniffed: SniffedFrame
    deadline: float
    broken_answer: bool = False


@dataclass(slots=True)
class SnifferStats:
    """Counters of everything the sniffer saw."""

    frames: Counter[str] = field(default_factory=Counter)  # by role
    anomalies: Counter[str] = field(default_factory=Counter)
    paired: int = 0
    bytes: int = 0


class LineSniffer:
    """Splits, pairs and flags a tapped line (see the module docstring).

    Args:
        dialect: the line's protocol, configured as the line is (FR-700's
            waiting-time field and terminator decide its frame lengths).
        line: the line's settings (its wire times set the time-outs).
        timing: the masters' timing (its margin, or a fixed time-out).
    """

    def __init__(
        self, dialect: Dialect[Any, Any], line: LineSettings, timing: BusTiming | None = None
    ) -> None:
        self.dialect = dialect
        self.line = line
        self.timing = timing or BusTiming()
        self.stats = SnifferStats()
        self._framer = dialect.line_framer()
        self._count = 0
        self._waiting: _Waiting | None = None
        self._expired: _Waiting | None = None
        # Requests another master's request interrupted, still in their time-out.
        self._interrupted: list[_Waiting] = []

    @property
    def next_deadline(self) -> float | None:
        """When the next pending request times out (call :meth:`tick` then), or None."""
        deadlines = [w.deadline for w in self._interrupted]
        if self._waiting is not None:
            deadlines.append(self._waiting.deadline)
        return min(deadlines, default=None)

    def feed(self, data: bytes, now: float) -> list[SniffedFrame | Unanswered]:
        """A chunk heard at *now*; return what it completed, and time-outs passed before it."""
        self.stats.bytes += len(data)
        reports: list[SniffedFrame | Unanswered] = self.tick(now)
        for piece in self._framer.feed(data):
            reports.append(self._judge(piece, now))
        return reports

    def tick(self, now: float) -> list[SniffedFrame | Unanswered]:
        """Report the pending requests whose time-outs have passed by *now*."""
        timed_out = [w for w in self._interrupted if now > w.deadline]
        if timed_out:
            self._interrupted = [w for w in self._interrupted if now <= w.deadline]
        waiting = self._waiting
        if waiting is not None and now > waiting.deadline:
            self._waiting = None
            self._expired = waiting
            timed_out.append(waiting)
        reports: list[SniffedFrame | Unanswered] = []
        for request in timed_out:
            if not request.broken_answer:  # else its broken answer was flagged already
                self.stats.anomalies[Anomaly.UNANSWERED.value] += 1
                reports.append(Unanswered(request.sniffed, now))
        return reports

    def flush(self, now: float) -> list[SniffedFrame | Unanswered]:
        """The line is gone: report an incomplete frame (as noise) and what was pending."""
        reports: list[SniffedFrame | Unanswered] = [
            self._judge(piece, now) for piece in self._framer.flush()
        ]
        last = max((w.deadline for w in [*self._interrupted, *filter(None, [self._waiting])]),
                   default=None)  # fmt: skip
        if last is not None:
            reports += self.tick(last + 1e-9)
        return reports

    def _judge(self, piece: bytes, now: float) -> SniffedFrame:
        waiting = self._waiting
        pending = waiting or self._expired
        frame = self._framer.classify(
            piece, outbound=None, pending=None if pending is None else pending.sniffed.frame.message
        )
        self._count += 1
        self.stats.frames[frame.role.value] += 1
        role = frame.role
        anomalies: list[Anomaly] = []
        answers = latency = None
        if role is FrameRole.REQUEST:
            if waiting is not None and not waiting.broken_answer:
                anomalies.append(Anomaly.TWO_MASTERS)
                self._interrupted = [*self._interrupted, waiting][-MAX_INTERRUPTED:]
            self._expired = None
            self._waiting = None
        elif role is FrameRole.REPLY:
            matched = self._match(frame)
            if matched is None:
                anomalies.append(Anomaly.UNSOLICITED)
            else:
                if matched is self._expired:
                    anomalies.append(Anomaly.LATE)
                    self._expired = None
                elif matched is self._waiting:
                    self._waiting = None
                else:
                    self._interrupted.remove(matched)
                answers = matched.sniffed.number
                latency = now - matched.sniffed.time
                self.stats.paired += 1
        elif role is FrameRole.BROKEN or role is FrameRole.NOISE:
            if role is FrameRole.NOISE:
                anomalies.append(Anomaly.NOISE)
            else:
                anomalies.append(Anomaly.BAD_CHECK if frame.check_ok is False else Anomaly.BROKEN)
            if waiting is not None:
                waiting.broken_answer = True
        for anomaly in anomalies:
            self.stats.anomalies[anomaly.value] += 1
        sniffed = SniffedFrame(self._count, now, frame, tuple(anomalies), answers, latency)
        if role is FrameRole.REQUEST and frame.expects_reply:
            self._waiting = _Waiting(sniffed, self._deadline(frame, now))
        return sniffed

    def _match(self, reply: LineFrame) -> _Waiting | None:
        for candidate in (self._waiting, *self._interrupted, self._expired):
            if candidate is not None and self.dialect.answers(
                candidate.sniffed.frame.message, reply.message
            ):
                return candidate
        return None

    def _deadline(self, frame: LineFrame, now: float) -> float:
        request: LineRequest = frame.message  # type: ignore[assignment]
        dialect = self.dialect
        timeout = self.timing.response_timeout(
            request,
            self.line,
            dialect.processing_s(request),
            dialect.reply_frame_length(request),
        )
        return now - self.line.wire_time_s(len(frame.data)) + timeout
