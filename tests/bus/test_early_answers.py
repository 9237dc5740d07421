"""Answers that come sooner than the line allows (rule 8): the call's error says so.

Issue 27, item 3: a peer faster than the line (an emulator, a test double)
ended in a bare "did not answer", although it had answered each time. The
peer here is the simulator over real TCP answering at once; the bus
expects a 1200-baud line (its URL and its plausibility floor), so every
answer comes about 160 ms sooner than the line could carry it, far more
than any scheduling delay.
"""

from __future__ import annotations

import re
from collections.abc import AsyncIterator

import pytest

import sj300_async as sj
from sj300_async.bus import ChunkLog, TraceRecord
from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.wire import INSTANT_LINE

#: The line the bus believes in: slow enough that an instant answer is plainly early.
SLOW = 1200
TIMING = sj.BusTiming(margin_s=0.1, plausible_baudrate=SLOW)


@pytest.fixture
async def instant_peer() -> AsyncIterator[str]:
    """``tcp://HOST:PORT`` of simulated drive 1, answering the moment a request is in."""
    server = await serve_tcp(SimulatedBus([1]), pacing=INSTANT_LINE)
    async with server:
        yield f"tcp://127.0.0.1:{server.port}"


async def test_answers_refused_as_early_are_named_in_the_time_out(instant_peer: str) -> None:
    url = f"{instant_peer}?baudrate={SLOW}"
    async with sj.open_bus(url, timing=TIMING, retries=1) as bus:
        with pytest.raises(sj.ReplyTimeoutError) as caught:
            await bus.drive(1).read_status()
        early = bus.stats.early_frames
    message = str(caught.value)
    assert message.startswith("node 01 did not answer command 04: 2 attempts"), message
    # The first attempt's answer and the sync's (rule 9): both came, both early.
    assert early == 2
    assert re.search(r"; 2 answers came up to 1\d\d\.\d ms sooner", message), message  # ~160 ms
    assert f"sooner than a {SLOW}-baud line can carry request and answer" in message
    assert "were refused as early" in message
    assert "add baudrate=0 to the URL, which turns the check off" in message
    assert f"for a line faster than {SLOW} baud give its speed (baudrate=N)" in message
    assert caught.value.attempts == 2


async def test_one_early_answer_is_singular(instant_peer: str) -> None:
    async with sj.open_bus(f"{instant_peer}?baudrate={SLOW}", timing=TIMING, retries=0) as bus:
        with pytest.raises(sj.ReplyTimeoutError, match=r"; 1 answer came up to .* was refused"):
            await bus.drive(1).read_status()


async def test_baudrate_0_in_the_url_takes_the_same_answers(instant_peer: str) -> None:
    async with sj.open_bus(f"{instant_peer}?baudrate=0", timing=TIMING, retries=0) as bus:
        status = await bus.drive(1).read_status()
        assert status.b is sj.StatusB.STOPPED
        assert bus.stats.early_frames == 0


async def test_a_silent_node_says_nothing_of_early_answers(instant_peer: str) -> None:
    # A node that answers early, then one that does not answer at all: the
    # second call's error is a plain time-out (nothing of the first carries over).
    async with sj.open_bus(f"{instant_peer}?baudrate={SLOW}", timing=TIMING, retries=0) as bus:
        with pytest.raises(sj.ReplyTimeoutError, match="refused as early"):
            await bus.drive(1).read_status()
        with pytest.raises(sj.ReplyTimeoutError) as caught:
            await bus.drive(2).read_status()
    assert "early" not in str(caught.value)
    assert str(caught.value).startswith("node 02 did not answer command 04: 1 attempt")


async def test_the_trace_record_names_the_answers_refused_as_early(instant_peer: str) -> None:
    records: list[TraceRecord] = []
    url = f"{instant_peer}?baudrate={SLOW}"
    async with sj.open_bus(url, timing=TIMING, retries=0, trace=records.append) as bus:
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(1).read_status()
    received = [r for r in records if r.direction == "rx" and r.events]
    assert received, records
    reply = received[0]
    assert reply.early == reply.events  # the status answer: refused
    assert all(e is f for e, f in zip(reply.early, reply.events, strict=True))  # the same objects


async def test_a_timely_answer_is_not_marked_early(instant_peer: str) -> None:
    records: list[TraceRecord] = []
    url = f"{instant_peer}?baudrate=0"
    async with sj.open_bus(url, timing=TIMING, retries=0, trace=records.append) as bus:
        await bus.drive(1).read_status()
    received = [r for r in records if r.direction == "rx" and r.events]
    assert len(received) == 1, records
    assert received[0].early == ()


async def test_a_recorder_marks_the_chunk_with_an_answer_refused_as_early(
    instant_peer: str,
) -> None:
    log = ChunkLog(keep_s=300.0, max_chunks=100)
    async with sj.open_bus(f"{instant_peer}?baudrate={SLOW}", timing=TIMING, retries=0) as bus:
        bus.recorder = log
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(1).read_status()
    received = [chunk for chunk in log.since(0.0) if chunk[1] == "rx"]
    assert received
    assert all(early for *_, early in received), received


async def test_a_recorder_leaves_a_timely_answer_unmarked(instant_peer: str) -> None:
    log = ChunkLog(keep_s=300.0, max_chunks=100)
    async with sj.open_bus(f"{instant_peer}?baudrate=0", timing=TIMING, retries=0) as bus:
        bus.recorder = log
        await bus.drive(1).read_status()
    kept = list(log.since(0.0))
    assert kept[0][1] == "tx"
    assert any(chunk[1] == "rx" for chunk in kept)
    assert not any(early for *_, early in kept)
