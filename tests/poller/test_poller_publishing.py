"""When a poll's sample is published: once the next request is on the line (issue 18).

Between a drive's last reply and the next drive's request the line is idle,
so the poller publishes a sample (callbacks, iterators) from a loop callback
that runs once the next request has been written. Every sample of a cycle is
out before the cycle is counted, none is lost when the poller stops, and with
``callback_errors="raise"`` samples still go out at once.
"""

from __future__ import annotations

import asyncio

from waiting import wait_for

import sj300_async as sj
from sj300_async.bus import TraceRecord
from sj300_async.sj300 import requests as rq

_NODES = (1, 2, 3)


def _last_request(trace: list[TraceRecord]) -> bytes:
    return [record.data for record in trace if record.direction == "tx"][-1]


async def _last_request_at_each_sample(poller: sj.Poller, trace: list[TraceRecord]) -> list[bytes]:
    """Poll one cycle of status reads; the last request written as each sample came out."""
    written: list[bytes] = []
    poller.on_sample(lambda _sample: written.append(_last_request(trace)))
    async with poller:
        await wait_for(lambda: len(written) >= len(_NODES), "a sample of each drive")
    return written[: len(_NODES)]


async def test_a_sample_is_published_once_the_next_request_is_on_the_line() -> None:
    trace: list[TraceRecord] = []
    async with sj.open_bus("sim://?nodes=1-3", timeout=0.05, trace=trace.append) as bus:
        poller = sj.Poller(interval_s=10.0, reads=("status",))
        poller.add(bus, _NODES)
        written = await _last_request_at_each_sample(poller, trace)
    # Node 1's sample once node 2's request is written, node 2's once node 3's is;
    # the cycle's last one before the cycle ends (nothing else is written).
    assert written == [rq.read_status(2).frame, rq.read_status(3).frame, rq.read_status(3).frame]


async def test_with_raising_callbacks_a_sample_is_published_at_once() -> None:
    trace: list[TraceRecord] = []
    async with sj.open_bus("sim://?nodes=1-3", timeout=0.05, trace=trace.append) as bus:
        poller = sj.Poller(interval_s=10.0, reads=("status",), callback_errors="raise")
        poller.add(bus, _NODES)
        written = await _last_request_at_each_sample(poller, trace)
    # A failing callback must stop the poller before its next request.
    assert written == [rq.read_status(node).frame for node in _NODES]


async def test_every_sample_of_a_cycle_is_out_before_the_cycle_is_counted() -> None:
    async with sj.open_bus("sim://?nodes=1-3", timeout=0.05) as bus:
        poller = sj.Poller(interval_s=0.0)
        poller.add(bus, _NODES)
        cycles_seen: list[tuple[int, int]] = []
        poller.on_sample(lambda s: cycles_seen.append((s.node, poller.bus_stats(bus).cycles)))
        async with poller:
            await wait_for(lambda: len(cycles_seen) >= 3 * len(_NODES), "three cycles of samples")
    first_three_cycles = cycles_seen[: 3 * len(_NODES)]
    assert first_three_cycles == [(node, cycle) for cycle in range(3) for node in _NODES]


async def test_stopping_loses_no_sample_and_none_follows_the_end() -> None:
    # Stopped at many points of its cycle, the poller has published exactly the
    # polls it completed (each one counted in its drive's health), every one of
    # them before its iterators ended.
    for stop_after in range(1, 25):
        await _stop_after(stop_after)


def _watch(
    poller: sj.Poller,
) -> tuple[list[sj.Sample], list[sj.Sample], asyncio.Task[None]]:
    """What a callback and an iterator see of *poller*, and the iterating task
    (started before the polling task, so it misses nothing)."""
    called: list[sj.Sample] = []
    poller.on_sample(called.append)
    iterated: list[sj.Sample] = []

    async def read() -> None:
        async for sample in poller.samples():
            iterated.append(sample)

    return called, iterated, asyncio.create_task(read())


async def _stop_after(samples: int) -> None:
    async with sj.open_bus("sim://?nodes=1-3", timeout=0.05) as bus:
        poller = sj.Poller(interval_s=0.0, buffer=10_000)
        poller.add(bus, _NODES)
        called, iterated, reader = _watch(poller)
        async with poller:
            await wait_for(lambda: len(called) >= samples, f"{samples} samples")
        await asyncio.wait_for(reader, 1.0)
        polls = sum(poller.health(bus, node).polls for node in _NODES)
        assert len(called) == polls
        assert iterated == called


async def test_a_stop_right_after_a_poll_still_publishes_it_before_the_end() -> None:
    # The stop comes between node 2's poll and its (deferred) publication: the
    # stopping task is woken in the same loop turn as the polling task, just
    # after it. The sample still reaches the iterator, before its end.
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    replies = 0

    def trace(record: TraceRecord) -> None:
        nonlocal replies
        if record.direction == "rx" and record.events:
            replies += 1
            if replies == 2:  # node 2's reply: runs before the polling task resumes
                loop.call_soon(stop.set)

    async with sj.open_bus("sim://?nodes=1-3", timeout=0.05, trace=trace) as bus:
        poller = sj.Poller(interval_s=10.0, reads=("status",))
        poller.add(bus, _NODES)
        called, iterated, reader = _watch(poller)
        async with poller:
            await stop.wait()
        await asyncio.wait_for(reader, 1.0)
    assert [s.node for s in called] == [1, 2]
    assert iterated == called
