"""The core's defences every door uses: budgets, off-loop password checks, the log flood
limit, the loop monitor (issue 41).

Each is sans-IO but for the clock or the loop, so these tests drive time
themselves; the doors' own tests show them against real clients.
"""

from __future__ import annotations

import asyncio
import logging

import pytest

from sj300_async.gateway import KeyedBudget, PasswordChecks, hash_password
from sj300_async.gateway import _logflood as logflood
from sj300_async.gateway._logflood import FloodLimit
from sj300_async.gateway._looplag import KEPT_SAMPLES, LAG_BUCKETS_S, TOLERANCE_S, LoopMonitor


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


# -- KeyedBudget ----------------------------------------------------------------------


def test_a_budget_lets_a_burst_through_then_refuses_and_refills() -> None:
    clock = Clock()
    budget = KeyedBudget(3, 0.5, clock=clock)
    assert [budget.spend("10.0.0.1") for _ in range(5)] == [True, True, True, False, False]
    assert budget.refused == 2
    assert budget.retry_after_s("10.0.0.1") == pytest.approx(2.0)
    assert budget.spend("10.0.0.2")  # another key has its own tokens
    clock.now += 2.0  # one token back
    assert budget.spend("10.0.0.1")
    assert not budget.spend("10.0.0.1")


def test_a_refund_gives_a_token_back_and_a_full_bucket_is_not_kept() -> None:
    clock = Clock()
    budget = KeyedBudget(2, 1.0, clock=clock)
    assert budget.spend("a")
    assert len(budget) == 1
    budget.refund("a")
    assert budget.available("a") == 2
    clock.now += 1
    assert [budget.spend("a") for _ in range(3)] == [True, True, False]


def test_a_budget_keeps_at_most_max_keys_forgetting_the_idlest() -> None:
    clock = Clock()
    budget = KeyedBudget(1, 0.001, max_keys=3, clock=clock)
    for key in "abcd":
        assert budget.spend(key)
    assert len(budget) == 3
    assert budget.spend("a")  # forgotten: full again
    assert not budget.spend("d")  # kept: still empty


def test_a_budget_refuses_nonsense_settings() -> None:
    with pytest.raises(ValueError, match="burst"):
        KeyedBudget(0, 1.0)


# -- PasswordChecks --------------------------------------------------------------------


async def test_password_checks_run_off_the_loop_and_a_full_queue_refuses_unchecked() -> None:
    stored = hash_password("right")
    checks = PasswordChecks(queued=4)
    loop = asyncio.get_running_loop()
    lags: list[float] = []
    running = True

    async def probe() -> None:
        while running:
            due = loop.time() + 0.01
            await asyncio.sleep(0.01)
            lags.append(loop.time() - due)

    prober = asyncio.create_task(probe())
    try:
        results = await asyncio.gather(
            checks.verify("right", stored), *(checks.verify("wrong", stored) for _ in range(7))
        )
    finally:
        running = False
        await prober
        checks.close()
    assert results[0] is True
    assert results[1:5] == [False] * 4
    assert results[5:] == [None] * 3  # past 1 running + 4 queued
    assert (checks.checked, checks.busy, checks.pending) == (5, 3, 0)
    # Five scrypt checks (about 65 ms each) ran while the loop kept its 10 ms timer.
    assert len(lags) >= 5
    assert max(lags) < 0.2, max(lags)


async def test_a_cancelled_check_still_counts_as_pending_until_its_thread_ends() -> None:
    stored = hash_password("x")
    checks = PasswordChecks(queued=0)
    first = asyncio.ensure_future(checks.verify("x", stored))
    await asyncio.sleep(0)
    first.cancel()
    assert await checks.verify("x", stored) is None  # the abandoned check still holds the slot
    while checks.pending:
        await asyncio.sleep(0.01)
    assert await checks.verify("x", stored) is True
    checks.close()


# -- FloodLimit ------------------------------------------------------------------------


@pytest.fixture
def flood() -> FloodLimit:
    return FloodLimit(per_interval=3, interval_s=10.0, clock=Clock())


def _record(
    name: str, message: str, *args: object, level: int = logging.ERROR, line: int = 7
) -> logging.LogRecord:
    return logging.LogRecord(name, level, "lib.py", line, message, args, None)


def test_a_library_call_site_passes_n_records_an_interval_whatever_the_arguments(
    flood: FloodLimit, caplog: pytest.LogCaptureFixture
) -> None:
    passed = [flood.filter(_record("asyncua.uaprocessor", "chunk %d", n)) for n in range(10)]
    assert passed == [True] * 3 + [False] * 7
    assert flood.suppressed == {"asyncua.uaprocessor": 7}
    assert flood.filter(_record("asyncua.uaprocessor", "chunk", line=8))  # another call site
    clock = flood._clock
    assert isinstance(clock, Clock)
    clock.now += 10.0
    with caplog.at_level(logging.WARNING, "sj300_async.gateway.logs"):
        flood.flush()
    [announced] = [r.getMessage() for r in caplog.records]
    assert announced.startswith("7 more log records like this one from asyncua.uaprocessor")
    assert announced.endswith("chunk 3")  # the first one suppressed
    assert flood.filter(_record("asyncua.uaprocessor", "chunk %d", 11))  # a new interval


def test_our_own_records_are_limited_only_when_identical_and_never_at_debug(
    flood: FloodLimit,
) -> None:
    own = "sj300_async.gateway"
    assert all(flood.filter(_record(own, "node %d lapsed", n)) for n in range(32))
    assert [flood.filter(_record(own, "node 1 refused")) for _ in range(5)] == [True] * 3 + [
        False
    ] * 2
    assert all(flood.filter(_record(own, "x", level=logging.DEBUG)) for _ in range(50))
    assert flood.suppressed == {own: 2}


def test_the_limit_is_on_every_logger_while_installed_and_gone_after() -> None:
    late = "asyncua.created.after.install"
    limit = logflood.install()
    try:
        assert limit in logging.getLogger("aiohttp.access").filters
        child = logging.getLogger(late)
        assert limit not in child.filters
        limit.flush()  # a logger made since gets it at the next flush
        assert limit in child.filters
        assert logflood.install() is limit  # a second gateway shares it
        logflood.uninstall()
        assert logflood.installed() is limit
    finally:
        logflood.uninstall()
    assert logflood.installed() is None
    assert limit not in logging.getLogger(late).filters
    assert limit not in logging.getLogger("sj300_async").filters


# -- LoopMonitor -----------------------------------------------------------------------


def test_the_monitor_keeps_the_last_samples_in_a_ring_of_fixed_size() -> None:
    monitor = LoopMonitor()
    held = monitor._samples.buffer_info()
    for n in range(KEPT_SAMPLES + 500):
        monitor.record(n / 1e6, float(n))
    assert monitor._samples.buffer_info() == held  # made full size, never grown
    everything = monitor.since(0)  # as far back as kept: the newest KEPT_SAMPLES
    assert everything.samples == KEPT_SAMPLES
    assert everything.max_s == (KEPT_SAMPLES + 499) / 1e6
    assert everything.p50_s == (500 + (KEPT_SAMPLES - 1) // 2) / 1e6
    last = monitor.since(monitor.mark() - 3)
    assert (last.samples, last.p50_s, last.max_s) == (
        3,
        (KEPT_SAMPLES + 498) / 1e6,
        (KEPT_SAMPLES + 499) / 1e6,
    )


def test_the_monitor_counts_lags_into_its_histogram_and_stalls_beyond_the_tolerance() -> None:
    monitor = LoopMonitor(limit_s=0.2)
    mark = monitor.mark()
    for lag in (0.0005, 0.003, 0.03, 0.5):
        monitor.record(lag, 100.0)
    assert monitor.since(mark).samples == 4
    assert monitor.since(mark).max_s == 0.5
    assert monitor._stalled == pytest.approx(0.03 - TOLERANCE_S + 0.5 - TOLERANCE_S)
    [histogram, recent, stalled] = list(monitor.metrics())
    assert stalled.samples[0].value == pytest.approx(monitor.stalled())
    buckets = {s.labels["le"]: s.value for s in histogram.samples if s.name.endswith("_bucket")}
    assert buckets[repr(LAG_BUCKETS_S[0])] == 1
    assert buckets["0.005"] == 2
    assert buckets["0.05"] == 3
    assert buckets["+Inf"] == 4
    assert recent.samples[0].value == 0.5
    assert monitor.problems()[0].startswith("the event loop lagged 500 ms")


async def test_the_monitor_sees_a_stall_and_counts_the_one_going_on() -> None:
    import time

    monitor = LoopMonitor(limit_s=0.1)
    monitor.start()
    try:
        mark = monitor.mark()
        while monitor.mark() < mark + 2:
            await asyncio.sleep(0.01)
        assert monitor.problems() == []
        time.sleep(0.3)  # the stall under test: the loop cannot run the probe
        assert monitor.stalled() >= 0.3 - 0.05 - TOLERANCE_S  # not yet probed: going on
        while monitor.mark() < mark + 3:
            await asyncio.sleep(0.01)
        assert monitor.since(mark).max_s >= 0.25
        assert monitor.problems()
    finally:
        monitor.stop()


def test_a_limit_taken_off_never_comes_back_and_the_last_stop_clears_every_one() -> None:
    """A limit still held by someone after the last gateway stopped (a loop monitor's
    late flush) does not put itself back on the loggers; and the last stop takes every
    flood limit off, whatever put it there."""
    limit = logflood.install()
    logflood.uninstall()
    limit.flush()  # late: after its uninstall
    http = logging.getLogger("sj300_async.gateway.http")
    assert not any(isinstance(f, FloodLimit) for f in http.filters)
    stray = FloodLimit()
    http.addFilter(stray)
    fresh = logflood.install()  # a fresh start clears it at once
    assert [f for f in http.filters if isinstance(f, FloodLimit)] == [fresh]
    http.addFilter(stray)
    logflood.uninstall()  # and so does the last stop
    assert not any(isinstance(f, FloodLimit) for f in http.filters)
