"""The line queue's non-waiting take, which the arbiter tries before it queues."""

from __future__ import annotations

import asyncio

from waiting import wait_for

from sj300_async.bus._linequeue import LineQueue


async def test_take_gets_a_free_line_and_never_jumps_the_queue() -> None:
    queue = LineQueue()
    assert queue.take()
    assert queue.busy
    assert not queue.take()  # held
    waiter = asyncio.create_task(queue.acquire())
    await wait_for(lambda: queue.waiting == 1, "the task to queue")
    queue.release()  # handed to the waiter, not freed
    assert queue.busy
    assert not queue.take()
    await waiter
    queue.release()
    assert not queue.busy
    assert queue.take()
    queue.release()
    assert not queue.busy
