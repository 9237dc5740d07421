"""Counters for a bus and for each drive on it.

Live objects, updated by the arbiter; :meth:`TransactionStats.snapshot`
gives a frozen copy for reporting.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections import Counter
from dataclasses import dataclass, field
from typing import Final

__all__ = [
    "LATENCY_BUCKETS_S",
    "BusStats",
    "BusTransactionStats",
    "StatsSnapshot",
    "TransactionStats",
]

#: Upper bounds of the bus's round-trip-time histogram, in seconds (a last,
#: unbounded bucket follows): from a fast 19200-baud exchange to a retry's worth.
LATENCY_BUCKETS_S: Final = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)


@dataclass(frozen=True, slots=True)
class StatsSnapshot:
    """A frozen copy of :class:`TransactionStats`."""

    requests: int
    replies: int
    broadcasts: int
    timeouts: int
    retries: int
    naks: dict[int, int]
    transport_errors: int
    protocol_errors: int
    cancelled: int
    discarded_frames: int
    latency_min_s: float | None
    latency_mean_s: float | None
    latency_max_s: float | None


class TransactionStats:
    """Counters of the transactions one drive (or a whole bus) took part in."""

    __slots__ = (
        "_latency_sum",
        "broadcasts",
        "cancelled",
        "discarded_frames",
        "latency_max_s",
        "latency_min_s",
        "naks",
        "protocol_errors",
        "replies",
        "requests",
        "retries",
        "timeouts",
        "transport_errors",
    )

    def __init__(self) -> None:
        #: Requests written to the line (each attempt counts once, a sync request too).
        self.requests = 0
        #: Valid answers received (positive or NAK).
        self.replies = 0
        #: Broadcasts written.
        self.broadcasts = 0
        #: Attempts that ended without an answer.
        self.timeouts = 0
        #: Attempts that were repeated after a transmission error or time-out.
        self.retries = 0
        #: Negative replies by error code.
        self.naks: Counter[int] = Counter()
        #: Attempts failed because the link was down or dropped.
        self.transport_errors = 0
        #: Attempts that ended with a corrupted answer (bad BCC, bad characters).
        self.protocol_errors = 0
        #: Attempts abandoned because the caller was cancelled while on the line.
        self.cancelled = 0
        #: Frames received during this drive's transactions that were not its answer.
        self.discarded_frames = 0
        self.latency_min_s = math.inf
        self.latency_max_s = 0.0
        self._latency_sum = 0.0

    def record_latency(self, seconds: float) -> None:
        """Add one round-trip time (write to answer)."""
        self._latency_sum += seconds
        if seconds < self.latency_min_s:
            self.latency_min_s = seconds
        if seconds > self.latency_max_s:
            self.latency_max_s = seconds

    @property
    def latency_sum_s(self) -> float:
        """The sum of every recorded round-trip time (a histogram's ``_sum``)."""
        return self._latency_sum

    @property
    def latency_mean_s(self) -> float | None:
        """Mean round-trip time of the answered requests, or None before the first."""
        return self._latency_sum / self.replies if self.replies else None

    def snapshot(self) -> StatsSnapshot:
        """Return a frozen copy of the counters."""
        answered = self.replies > 0
        return StatsSnapshot(
            requests=self.requests,
            replies=self.replies,
            broadcasts=self.broadcasts,
            timeouts=self.timeouts,
            retries=self.retries,
            naks=dict(self.naks),
            transport_errors=self.transport_errors,
            protocol_errors=self.protocol_errors,
            cancelled=self.cancelled,
            discarded_frames=self.discarded_frames,
            latency_min_s=self.latency_min_s if answered else None,
            latency_mean_s=self.latency_mean_s,
            latency_max_s=self.latency_max_s if answered else None,
        )


class BusTransactionStats(TransactionStats):
    """A whole bus's transaction totals, with a histogram of the round-trip times.

    Only the bus totals keep the histogram (a Prometheus exporter's latency
    histogram reads it); each drive's counters stay as small as they were.
    """

    __slots__ = ("latency_counts",)

    def __init__(self) -> None:
        super().__init__()
        #: Round trips per bucket of :data:`LATENCY_BUCKETS_S` (not cumulative),
        #: the last element counting those slower than every bound.
        self.latency_counts = [0] * (len(LATENCY_BUCKETS_S) + 1)

    def record_latency(self, seconds: float) -> None:
        super().record_latency(seconds)
        self.latency_counts[bisect_left(LATENCY_BUCKETS_S, seconds)] += 1

    def record_answer(self, drive: TransactionStats, seconds: float) -> None:
        """One answered request: a reply and its round-trip time, in these totals
        and in *drive*'s own counters (unless *drive* is these totals).

        The arbiter's one call per answer, where it made two calls and four
        statements of its own.
        """
        self.replies += 1
        self._latency_sum += seconds
        if seconds < self.latency_min_s:
            self.latency_min_s = seconds
        if seconds > self.latency_max_s:
            self.latency_max_s = seconds
        self.latency_counts[bisect_left(LATENCY_BUCKETS_S, seconds)] += 1
        if drive is not self:
            drive.replies += 1
            drive._latency_sum += seconds
            if seconds < drive.latency_min_s:
                drive.latency_min_s = seconds
            if seconds > drive.latency_max_s:
                drive.latency_max_s = seconds


@dataclass(slots=True)
class BusStats:
    """Counters of a whole bus: the transaction totals plus what only the line sees."""

    #: Totals over all drives (and broadcasts).
    transactions: BusTransactionStats = field(default_factory=BusTransactionStats)
    #: Bytes written to the line (echo included when the adapter echoes) and received.
    bytes_written: int = 0
    bytes_received: int = 0
    #: Bytes thrown away by the reply parser (garbage, cut-off and overlong frames).
    discarded_bytes: int = 0
    #: Complete frames rejected by the parser (bad BCC, bad characters...).
    bad_frames: int = 0
    #: Valid frames received during a transaction that were not its answer (other node,
    #: wrong shape for the command).
    stray_frames: int = 0
    #: Valid frames received while no transaction was waiting (late replies, drained).
    unsolicited_frames: int = 0
    #: Frames shaped like the answer that arrived sooner than the line allows: a
    #: duplicate or a stray (see ``BusTiming.answer_floor``); discarded.
    early_frames: int = 0
    #: Sync requests sent to a node after it missed an answer (a time-out or a
    #: corrupted answer), so that its late replies cannot be taken for the next
    #: answer; also counted among the drive's requests.
    resyncs: int = 0
    #: Drains performed after failed transactions.
    drains: int = 0
    #: Corrupted replies the host asked the device to send again (FR-700 format F).
    reoutput_requests: int = 0
    #: Local-echo bytes removed: whole, exact copies of written frames (see
    #: :mod:`._protocol`).
    echo_bytes: int = 0
    #: Written frames whose echo was removed.
    echo_frames: int = 0
    #: Expected echoes that did not come (their bytes went to the parser): with
    #: ``echo=1`` every one, with ``echo=auto`` those on a line known to echo.
    echo_mismatches: int = 0
    #: Does the line echo? True: the last written frame (of known fate) came back;
    #: False: it did not; None: not known yet, or never looked (``echo=0``).
    echo_detected: bool | None = None
    #: Successful (re)connections of the link.
    connects: int = 0
    #: Times the link was lost.
    disconnects: int = 0
