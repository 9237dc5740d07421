"""The MQTT bridge's outbox: what waits, in which order, and what a lost batch costs."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import Any

import pytest
from waiting import wait_for

from sj300_async.gateway.mqtt._outbox import MAX_IN_FLIGHT, Out, Outbox
from sj300_async.gateway.mqtt._stats import BridgeStats


class Stuck:
    """A client whose publishes never complete (a broker that stopped answering)."""

    async def publish_many(self, *args: object, **kwargs: object) -> None:
        await asyncio.Event().wait()


class Recorder:
    """A client that takes every publish at once and keeps the batches."""

    def __init__(self, on_batch: Any = None) -> None:
        self.batches: list[list[str]] = []
        self.on_batch = on_batch

    async def publish_many(self, messages: list[tuple[str, bytes, bool]], qos: int) -> None:
        self.batches.append([topic for topic, _, _ in messages])
        if self.on_batch is not None:
            self.on_batch(len(self.batches))


async def test_a_stop_mid_batch_counts_what_it_could_not_confirm() -> None:
    outbox = Outbox(BridgeStats())
    for n in range(100):
        outbox.put(Out(f"t/{n}", b"x", retain=True))
    sending = asyncio.create_task(outbox.send(Stuck(), 1))  # type: ignore[arg-type]
    await wait_for(lambda: not outbox.pending, "the batch taken from the outbox")
    sending.cancel()
    with pytest.raises(asyncio.CancelledError):
        await sending
    assert (outbox.stats.published, outbox.stats.lost) == (0, 100)


def _configs(made: list[int], count: int) -> Iterator[Out]:
    for n in range(count):
        made.append(n)
        yield Out(f"config/{n}", b"{}", retain=True)


async def test_an_announcement_is_made_a_chunk_at_a_time_after_what_else_waits() -> None:
    made: list[int] = []
    outbox = Outbox(BridgeStats())
    total = 3 * MAX_IN_FLIGHT + 7
    outbox.announce(_configs(made, total))
    outbox.put(Out("state/1", b"{}", retain=True, drive=("hall", 1)))
    counts: list[int] = []

    def on_batch(batches: int) -> None:
        counts.append(len(made))  # configs made when this chunk went out
        if batches == 2:  # a state put while the announcement is under way
            outbox.put(Out("state/2", b"{}", retain=True, drive=("hall", 2)))

    client = Recorder(on_batch)
    await outbox.send(client, 1)  # type: ignore[arg-type]
    topics = [topic for batch in client.batches for topic in batch]
    assert topics[0] == "state/1"  # what waited goes first, in the first chunk
    assert sorted(t for t in topics if t.startswith("config/")) == sorted(
        f"config/{n}" for n in range(total)
    )
    # state/2 went in the chunk after it was put, not behind the rest of the configs.
    assert topics.index("state/2") <= 2 * MAX_IN_FLIGHT + 1
    # Never more configs made than one chunk ahead of what was sent.
    assert all(c <= (i + 1) * MAX_IN_FLIGHT for i, c in enumerate(counts))
    assert max(len(batch) for batch in client.batches) <= MAX_IN_FLIGHT
    assert (outbox.stats.published, outbox.announcing, len(outbox)) == (total + 2, None, 0)


async def test_a_new_announcement_takes_the_place_of_one_under_way() -> None:
    made: list[int] = []
    outbox = Outbox(BridgeStats())
    outbox.announce(_configs(made, 10 * MAX_IN_FLIGHT))
    again: list[int] = []

    def on_batch(batches: int) -> None:
        if batches == 1:
            outbox.announce(_configs(again, 5))

    await outbox.send(Recorder(on_batch), 1)  # type: ignore[arg-type]
    assert (len(made), len(again)) == (MAX_IN_FLIGHT, 5)


def test_abandon_counts_what_was_made_and_forgets_the_announcement() -> None:
    outbox = Outbox(BridgeStats())
    made: list[int] = []
    outbox.announce(_configs(made, 1000))
    outbox.put(Out("a", b"", retain=True))
    outbox.put_error(Out("e", b"", retain=False))
    assert outbox.waiting
    assert outbox.abandon() == 2
    assert not outbox.waiting
    assert made == []
