"""Leak probes: tasks, timers, file descriptors and memory, before and after a run.

``loop._scheduled`` is asyncio's private timer heap; reading it is the only
way to see a timer that somebody forgot to cancel, so the probe reads it
(CPython's BaseEventLoop; the suite runs on nothing else).
"""

from __future__ import annotations

import asyncio
import gc
import logging
import os
import resource
import sys
import tracemalloc
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import sj300_async as sj


def open_fds() -> int:
    """File descriptors open in this process."""
    return len(os.listdir("/proc/self/fd"))


def live_timers(loop: asyncio.AbstractEventLoop) -> list[asyncio.TimerHandle]:
    """Timers scheduled on *loop* and not cancelled."""
    scheduled = getattr(loop, "_scheduled", [])
    return [h for h in scheduled if not h.cancelled()]


def peak_rss_mib() -> float:
    """Peak resident memory of this process so far (ru_maxrss is KiB on Linux)."""
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


# Starts the command of its argv as its child, passes on SIGINT and SIGTERM, and exits
# with the child's status (128 + N for a child killed by signal N, as a shell does).
_LAUNCHER = """\
import signal, subprocess, sys
child = subprocess.Popen(sys.argv[1:])
for number in (signal.SIGINT, signal.SIGTERM):
    signal.signal(number, lambda n, _: child.send_signal(n))
code = child.wait()
sys.exit(code if code >= 0 else 128 - code)
"""


def counting_its_own_peak(command: Sequence[str]) -> list[str]:
    """*command*, started so that its peak resident memory (``ru_maxrss``) is its own.

    Linux keeps a process's ``ru_maxrss`` across exec, and a child started by
    ``subprocess`` (vfork, then exec) begins with its parent's peak: an
    xdist worker that once held 2 GB hands 2 GB to every program it starts,
    and libFuzzer's ``-rss_limit_mb``, which checks ``ru_maxrss``, stopped a
    fuzzer that used 55 MB (issue 41). A new process, though, starts its own
    count from the memory of the process it was forked from, not from that
    process's inherited count; so a small interpreter is started first (its
    own count is this process's peak, which nobody reads) and it starts
    *command*, whose count begins at the interpreter's 10 MB. An intermediate
    that execs *command* itself (``sh -c 'exec ...'``) would not do: the count
    goes on across exec. Measured from a parent whose peak was 810 MB: 810 MB
    for a child started directly or through ``sh -c 'exec ...'``, 8-10 MB
    through this. (libFuzzer's own check is kept, rather than
    ``-rss_limit_mb=0`` and a bound of ours: it names the input that grew
    the memory, and its ``peak_rss_mb`` figure is then true.)
    """
    return [sys.executable, "-c", _LAUNCHER, *command]


@dataclass
class Baseline:
    """What the process held before a run; :meth:`leaks` lists what is left over after it."""

    tasks: set[asyncio.Task[Any]]
    fds: int
    timers: int

    @classmethod
    def take(cls) -> Baseline:
        # Collected first, as leaks() collects before it counts: garbage an earlier
        # test left in cycles (a socket among it) would otherwise count as held
        # before and be gone after. A gateway gives its frozen objects back to the
        # collector at its stop, so what it left in cycles waits for a full
        # collection, and the next test's leaks() may be the one that runs it.
        gc.collect()
        loop = asyncio.get_running_loop()
        return cls(set(asyncio.all_tasks()), open_fds(), len(live_timers(loop)))

    async def leaks(self, settle_s: float = 1.0) -> list[str]:
        """Wait for stragglers (at most *settle_s*), then report what was not given back.

        It returns as soon as nothing is left over, so the bound costs a clean run
        nothing. 1 s: a full suite on a loaded machine once found the server side
        of a just-closed TCP connection still open after 0.2 s (Python 3.11's
        ``Server.wait_closed`` does not wait for connections to close).
        """
        loop = asyncio.get_running_loop()
        deadline = loop.time() + settle_s
        while True:
            gc.collect()
            found = self._compare(loop)
            if not found or loop.time() >= deadline:
                return found
            await asyncio.sleep(0.01)

    def _compare(self, loop: asyncio.AbstractEventLoop) -> list[str]:
        found = []
        extra = set(asyncio.all_tasks()) - self.tasks
        if extra:
            found.append(f"tasks left running: {sorted(t.get_name() for t in extra)}")
        fds = open_fds()
        if fds != self.fds:
            found.append(f"file descriptors: {self.fds} before, {fds} after")
        timers = live_timers(loop)
        if len(timers) > self.timers:
            found.append(f"timers left scheduled: {timers}")
        return found


def bus_idle(bus: sj.Bus) -> list[str]:
    """Everything the arbiter holds must be given back once no request runs."""
    arbiter = bus._arbiter
    found = []
    if arbiter._outstanding is not None:
        found.append(f"a request is still outstanding: {arbiter._outstanding}")
    if arbiter.queue.busy:
        found.append("the line is still held")
    if arbiter.queue.waiting:
        found.append(f"{arbiter.queue.waiting} tasks still wait for the line")
    return found


@dataclass
class MemoryWatch:
    """tracemalloc over a run: the peak, and the growth between two marks."""

    marks: dict[str, int] = field(default_factory=dict)

    def __enter__(self) -> MemoryWatch:
        tracemalloc.start()
        return self

    def mark(self, name: str) -> None:
        gc.collect()
        self.marks[name] = tracemalloc.get_traced_memory()[0]

    @property
    def peak_mib(self) -> float:
        return round(tracemalloc.get_traced_memory()[1] / 2**20, 2)

    def growth_kib(self, first: str, last: str) -> float:
        return round((self.marks[last] - self.marks[first]) / 1024, 1)

    def __exit__(self, *exc: object) -> None:
        self.final_peak_mib = self.peak_mib
        tracemalloc.stop()


class ErrorLog:
    """Collects what the loop's exception handler would print (never-retrieved exceptions...)."""

    def __init__(self) -> None:
        self.errors: list[str] = []

    def install(self) -> None:
        asyncio.get_running_loop().set_exception_handler(self._handle)

    def _handle(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        self.errors.append(f"{context.get('message')}: {context.get('exception')!r}")


class CountingLogs:
    """Count the library's log records by level instead of letting them pile up in memory.

    pytest's log capture keeps every record of a test; over a hundred reconnect
    cycles that is memory the library did not allocate, so a memory-growth check
    counts records here and keeps none.
    """

    def __init__(self, name: str = "sj300_async") -> None:
        self.logger = logging.getLogger(name)
        self.counts: Counter[str] = Counter()
        self._handler = _CountHandler(self.counts)

    def __enter__(self) -> CountingLogs:
        self._propagate = self.logger.propagate
        self.logger.propagate = False
        self.logger.addHandler(self._handler)
        return self

    def __exit__(self, *exc: object) -> None:
        self.logger.removeHandler(self._handler)
        self.logger.propagate = self._propagate


class _CountHandler(logging.Handler):
    def __init__(self, counts: Counter[str]) -> None:
        super().__init__(logging.INFO)
        self.counts = counts

    def emit(self, record: logging.LogRecord) -> None:
        self.counts[record.levelname] += 1
