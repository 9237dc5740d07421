"""The bus's byte counters and round-trip histogram (what a metrics exporter reads)."""

from __future__ import annotations

import sj300_async as sj
from sj300_async.bus import TraceRecord
from sj300_async.bus._stats import LATENCY_BUCKETS_S, BusTransactionStats, TransactionStats


async def test_bytes_and_latencies_are_counted_as_they_crossed_the_line() -> None:
    records: list[TraceRecord] = []
    async with sj.open_bus("sim://?nodes=1-2", trace=records.append) as bus:
        for node in (1, 2, 1):
            await bus.drive(node).read_status()
        await bus.drive(2).read_parameter("A004")
        stats = bus.stats
        assert stats.bytes_written == sum(len(r.data) for r in records if r.direction == "tx")
        assert stats.bytes_received == sum(len(r.data) for r in records if r.direction == "rx")
        assert stats.bytes_written > 0
        assert stats.bytes_received > 0
        totals = stats.transactions
        assert isinstance(totals, BusTransactionStats)
        assert sum(totals.latency_counts) == totals.replies == 4
        # Each drive's own counters stay without a histogram.
        assert not hasattr(bus.drive(1).stats, "latency_counts")


def test_the_histogram_puts_each_round_trip_in_its_bucket() -> None:
    stats = BusTransactionStats()
    for seconds in (0.001, 0.005, 0.0051, 4.9, 5.0, 60.0):
        stats.record_latency(seconds)
    counts = dict(zip((*LATENCY_BUCKETS_S, float("inf")), stats.latency_counts, strict=True))
    assert counts[0.005] == 2  # bounds are inclusive, as Prometheus's "le"
    assert counts[0.01] == 1
    assert counts[5.0] == 2
    assert counts[float("inf")] == 1
    assert stats.latency_max_s == 60.0


def test_an_answer_is_counted_in_the_totals_and_in_the_drive_once_each() -> None:
    totals, drive = BusTransactionStats(), TransactionStats()
    totals.record_answer(drive, 0.004)
    totals.record_answer(drive, 0.002)
    for stats in (totals, drive):
        assert stats.replies == 2
        assert (stats.latency_min_s, stats.latency_max_s) == (0.002, 0.004)
        assert stats.latency_sum_s == 0.006
    assert sum(totals.latency_counts) == 2
    # A call made with the totals as its own counters counts once, not twice.
    totals.record_answer(totals, 0.003)
    assert totals.replies == 3
    assert sum(totals.latency_counts) == 3
    assert drive.replies == 2
