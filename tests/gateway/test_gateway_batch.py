"""The gateway's snapshot batch (gateway/_batch.py): gathered, delivered in order, in pieces.

Snapshots stand in as plain objects: the batch never looks inside them.
"""

from __future__ import annotations

import asyncio
from typing import Any, cast

from waiting import wait_for

from sj300_async.gateway._batch import SnapshotBatch
from sj300_async.profiles import DriveSnapshot


def _snapshots(count: int, start: int = 0) -> list[DriveSnapshot]:
    return [cast(DriveSnapshot, ("snapshot", i)) for i in range(start, start + count)]


class _Deliveries:
    def __init__(self) -> None:
        self.pieces: list[list[Any]] = []
        #: Loop turns seen between pieces: a piece never follows another in one callback.
        self.turns: list[int] = []
        self._turn = 0

    def __call__(self, snapshots: list[DriveSnapshot]) -> None:
        self.pieces.append(list(snapshots))
        self.turns.append(self._turn)

    async def count_turns(self) -> None:
        while True:
            self._turn += 1
            await asyncio.sleep(0)

    @property
    def delivered(self) -> list[Any]:
        return [s for piece in self.pieces for s in piece]


async def test_nothing_is_delivered_before_its_time_then_all_in_order() -> None:
    deliveries = _Deliveries()
    batch = SnapshotBatch(deliveries, every_s=0.05, chunk=1000)
    made = _snapshots(10)
    loop = asyncio.get_running_loop()
    began = loop.time()
    for snapshot in made:
        batch.add(snapshot)
    assert len(batch) == 10
    await asyncio.sleep(0)
    assert deliveries.pieces == []
    await wait_for(lambda: deliveries.delivered == made, "the batch")
    assert loop.time() - began >= 0.05
    assert len(deliveries.pieces) == 1
    assert len(batch) == 0


async def test_a_long_batch_goes_in_pieces_one_loop_callback_each() -> None:
    deliveries = _Deliveries()
    counter = asyncio.get_running_loop().create_task(deliveries.count_turns())
    try:
        batch = SnapshotBatch(deliveries, every_s=0.01, chunk=4)
        made = _snapshots(10)
        for snapshot in made:
            batch.add(snapshot)
        await wait_for(lambda: len(deliveries.delivered) == 10, "every piece")
    finally:
        counter.cancel()
    assert [len(piece) for piece in deliveries.pieces] == [4, 4, 2]
    assert deliveries.delivered == made
    assert len(set(deliveries.turns)) == 3  # the loop ran other tasks between the pieces


async def test_what_comes_while_a_batch_is_delivered_follows_it_in_order() -> None:
    deliveries = _Deliveries()
    first, second = _snapshots(5), _snapshots(5, start=5)

    def deliver(snapshots: list[DriveSnapshot]) -> None:
        if not deliveries.pieces:  # made while the first piece is taken
            for snapshot in second:
                batch.add(snapshot)
        deliveries(snapshots)

    batch = SnapshotBatch(deliver, every_s=0.01, chunk=3)
    for snapshot in first:
        batch.add(snapshot)
    await wait_for(lambda: len(deliveries.delivered) == 10, "everything")
    assert deliveries.delivered == first + second
    assert [len(piece) for piece in deliveries.pieces] == [3, 3, 3, 1]


async def test_flush_delivers_at_once_and_leaves_no_delivery_due() -> None:
    deliveries = _Deliveries()
    batch = SnapshotBatch(deliveries, every_s=0.01, chunk=2)
    made = _snapshots(5)
    for snapshot in made:
        batch.add(snapshot)
    batch.flush()
    assert deliveries.pieces == [made]  # whole, not in pieces: the caller is stopping
    await asyncio.sleep(0.03)
    assert deliveries.pieces == [made]  # the timer was cancelled
    batch.flush()
    assert deliveries.pieces == [made]  # nothing gathered: nothing delivered
    later = _snapshots(1, start=5)
    batch.add(later[0])  # a new batch after a flush
    await wait_for(lambda: len(deliveries.pieces) == 2, "the next batch")
    assert deliveries.pieces[1] == later
