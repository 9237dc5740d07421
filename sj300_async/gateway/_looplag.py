"""The event loop's lag, measured all the time: how late the loop runs what is due.

The gateway's one event loop carries the poll, the leases, the lapse
stops and every client. :class:`LoopMonitor` schedules a probe every
:data:`PROBE_S` and records how late the loop ran it: that lateness is
what any timer, reply or heartbeat due at that moment waited too. It is
served as a histogram (``sj300_gateway_loop_lag_seconds``), its recent
maximum as a gauge, and ``/healthz`` says "degraded" while the largest
lag of the last :data:`RECENT_S` is over ``limit_s``.

**Stall time is not lease time.** A client that heartbeats within its
lease must never lose it to the gateway's own stall: its heartbeat may sit
in the socket, unread, while the loop is stuck. The monitor adds up every
probe's lateness beyond :data:`TOLERANCE_S` (:meth:`LoopMonitor.stalled`,
seconds the loop could not run anything) and the lease counts only the
rest (:mod:`._control`). The stall that is still going on counts too: the
first loop turn after a stall reads the sockets before it runs its timers,
so a heartbeat read then is judged with that stall already credited.

Decisions:

- **A probe, not a hook into the loop's internals**: ``call_at`` on
  whatever loop runs (asyncio's, uvloop), 20 times a second, about 2 µs
  each. Lateness is measured against the time the probe was due.
- **Samples kept for the tests and the benchmark** (:data:`KEPT_SAMPLES`,
  ten minutes at 20 a second): :meth:`LoopMonitor.mark` and
  :meth:`LoopMonitor.since` give the quantiles of a stretch of time. In one
  preallocated array (96 KB from the start): a deque of floats grew for ten
  minutes to 384 KB, growth a soak counted after its fifth (issue 44).
- The monitor also runs :func:`._logflood` 's once-a-second flush, so the
  gateway has one periodic timer of its own instead of two, and the
  service manager's watchdog ping (:meth:`LoopMonitor.keep_alive`,
  :mod:`._sdnotify`): a loop stuck past systemd's ``WatchdogSec`` sends none.
"""

from __future__ import annotations

import asyncio
import bisect
from array import array
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from ._model import DEFAULT_LOOP_LAG_LIMIT_S

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = [
    "LAG_BUCKETS_S",
    "PROBE_S",
    "RECENT_S",
    "TOLERANCE_S",
    "LagSummary",
    "LoopMonitor",
]

#: Seconds between two probes.
PROBE_S: Final = 0.05
#: Lateness a probe may have without counting as a stall (timer slack, a busy turn).
TOLERANCE_S: Final = 0.02
#: The histogram's upper bounds.
LAG_BUCKETS_S: Final = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)
#: ``/healthz`` looks at the largest lag of this many seconds back.
RECENT_S: Final = 10.0
#: Samples kept for :meth:`LoopMonitor.since`.
KEPT_SAMPLES: Final = 12_000


@dataclass(frozen=True, slots=True)
class LagSummary:
    """The lag over a stretch of probes."""

    samples: int
    p50_s: float
    p99_s: float
    max_s: float


class LoopMonitor:
    """The loop's lag (see the module docstring).

    Args:
        limit_s: the lag over which :meth:`problems` reports the gateway degraded.
        every_second: called about once a second from the probe (the log flood's flush).
    """

    def __init__(
        self,
        limit_s: float = DEFAULT_LOOP_LAG_LIMIT_S,
        every_second: Callable[[], None] | None = None,
    ) -> None:
        self.limit_s = limit_s
        self._every_second = every_second
        self._loop: asyncio.AbstractEventLoop | None = None
        self._handle: asyncio.TimerHandle | None = None
        self._due = 0.0
        self._buckets = [0] * (len(LAG_BUCKETS_S) + 1)
        self._sum = 0.0
        self._count = 0
        self._stalled = 0.0
        #: The last KEPT_SAMPLES lags, a ring: probe n's at n % KEPT_SAMPLES.
        self._samples = array("d", [0.0]) * KEPT_SAMPLES
        #: (time, lag) of every probe over the tolerance in the last RECENT_S.
        self._recent: deque[tuple[float, float]] = deque()
        #: The largest lag since the start.
        self.max_s = 0.0
        self._next_second = 0.0
        #: The service manager's watchdog ping, and when it is due next (keep_alive).
        self._alive: Callable[[], object] | None = None
        self._alive_every_s = 0.0
        self._next_alive = 0.0

    def start(self) -> None:
        """Start probing on the running loop."""
        self._loop = asyncio.get_running_loop()
        now = self._loop.time()
        self._next_second = now + 1.0
        self._schedule(now)

    def stop(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None

    def _schedule(self, now: float) -> None:
        assert self._loop is not None
        self._due = now + PROBE_S
        self._handle = self._loop.call_at(self._due, self._probe)

    def _probe(self) -> None:
        assert self._loop is not None
        now = self._loop.time()
        self.record(max(0.0, now - self._due), now)
        if now >= self._next_second:
            self._next_second = now + 1.0
            if self._every_second is not None:
                self._every_second()
        if self._alive is not None and now >= self._next_alive:
            self._next_alive = now + self._alive_every_s
            self._alive()
        self._schedule(now)

    def keep_alive(self, ping: Callable[[], object], every_s: float) -> None:
        """Call *ping* from the probe every *every_s* (a service watchdog: a loop stuck
        longer than the watchdog's time sends no ping), the first at the next probe."""
        self._alive, self._alive_every_s, self._next_alive = ping, every_s, 0.0

    def record(self, lag: float, now: float) -> None:
        """Count one probe's *lag* (also how the tests feed it)."""
        self._buckets[bisect.bisect_left(LAG_BUCKETS_S, lag)] += 1
        self._sum += lag
        self._samples[self._count % KEPT_SAMPLES] = lag
        self._count += 1
        self.max_s = max(self.max_s, lag)
        if lag > TOLERANCE_S:
            self._stalled += lag - TOLERANCE_S
            self._recent.append((now, lag))
        while self._recent and self._recent[0][0] < now - RECENT_S:
            self._recent.popleft()

    # -- what the leases, /healthz and /metrics read ------------------------------------

    def stalled(self) -> float:
        """Seconds the loop has been stalled since the start, the stall going on included."""
        if self._loop is None or self._handle is None:
            return self._stalled
        ongoing = self._loop.time() - self._due - TOLERANCE_S
        return self._stalled + max(0.0, ongoing)

    def recent_max_s(self) -> float:
        """The largest lag of the last :data:`RECENT_S` (0 when none was over the tolerance)."""
        if self._loop is not None:
            horizon = self._loop.time() - RECENT_S
            while self._recent and self._recent[0][0] < horizon:
                self._recent.popleft()
        return max((lag for _, lag in self._recent), default=0.0)

    def problems(self) -> list[str]:
        worst = self.recent_max_s()
        if worst <= self.limit_s:
            return []
        return [
            f"the event loop lagged {worst * 1000:.0f} ms in the last {RECENT_S:g} s "
            f"(loop_lag_limit_s {self.limit_s:g}): something is blocking it"
        ]

    def mark(self) -> int:
        """A mark for :meth:`since`: the number of probes so far."""
        return self._count

    def since(self, mark: int) -> LagSummary:
        """The lag of the probes after *mark* (at most the last :data:`KEPT_SAMPLES`)."""
        count = self._count
        taken = min(count - mark, count, KEPT_SAMPLES)
        if taken <= 0:
            return LagSummary(0, 0.0, 0.0, 0.0)
        lags = sorted(self._samples[n % KEPT_SAMPLES] for n in range(count - taken, count))
        return LagSummary(
            taken,
            lags[(taken - 1) // 2],
            lags[min(taken - 1, int(taken * 0.99))],
            lags[-1],
        )

    def metrics(self) -> Iterator[Metric]:
        from prometheus_client.core import (
            CounterMetricFamily,
            GaugeMetricFamily,
            HistogramMetricFamily,
        )

        cumulative: list[tuple[str, float]] = []
        total = 0
        for bound, count in zip((*LAG_BUCKETS_S, float("inf")), self._buckets, strict=True):
            total += count
            cumulative.append(("+Inf" if bound == float("inf") else repr(bound), total))
        yield HistogramMetricFamily(
            "sj300_gateway_loop_lag_seconds",
            f"How late the event loop ran a probe due every {PROBE_S:g} s: what any timer, "
            "reply or heartbeat due then waited too.",
            buckets=cumulative,
            sum_value=self._sum,
        )
        yield GaugeMetricFamily(
            "sj300_gateway_loop_lag_recent_max_seconds",
            f"The largest loop lag of the last {RECENT_S:g} s (/healthz is degraded past "
            "loop_lag_limit_s).",
            value=self.recent_max_s(),
        )
        yield CounterMetricFamily(
            "sj300_gateway_loop_stalled_seconds",
            f"Seconds the loop was stalled (each probe's lateness beyond {TOLERANCE_S:g} s), "
            "not counted against any lease.",
            value=self._stalled,
        )
