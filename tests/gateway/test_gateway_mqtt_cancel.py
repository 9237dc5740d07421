"""The MQTT northbounds stop even when a cancellation gets lost on the way.

Python 3.11's ``asyncio.wait_for`` (inside aiomqtt's publish, before the
client was ours) returns the awaited result and drops a cancellation that
arrives in the same loop turn (gh-86296). The bridge's publisher then
waited for work forever and the gateway's stop with it: the MQTT
benchmark's child hung in 2 runs out of 7.
"""

from __future__ import annotations

import asyncio
import sys

import pytest

from sj300_async.gateway.mqttlink import cancel_and_wait


async def _loses_one_cancellation(ended: list[str]) -> None:
    try:
        await asyncio.sleep(10)
    except asyncio.CancelledError:
        pass  # lost, as wait_for can lose it
    try:
        await asyncio.sleep(10)
    finally:
        ended.append("ended")


async def test_a_task_that_loses_a_cancellation_is_cancelled_again() -> None:
    ended: list[str] = []
    task = asyncio.create_task(_loses_one_cancellation(ended))
    await asyncio.sleep(0)
    async with asyncio.timeout(5):
        await cancel_and_wait({task})
    assert task.cancelled()
    assert ended == ["ended"]


async def test_tasks_that_ended_with_an_error_are_waited_for_and_left_to_the_caller() -> None:
    async def fails() -> None:
        raise OSError("the connection's error")

    task = asyncio.create_task(fails())
    await asyncio.sleep(0)
    await cancel_and_wait({task})
    with pytest.raises(OSError, match="the connection's error"):
        task.result()


async def test_on_this_python_wait_for_can_lose_a_cancellation() -> None:
    """Why the bridge cancels again: the race, reproduced (3.11 loses it; 3.12 keeps it)."""
    loop = asyncio.get_running_loop()
    answer: asyncio.Future[None] = loop.create_future()
    got: list[str] = []

    async def publish() -> None:
        await asyncio.wait_for(answer, 5)
        got.append("answer")

    task = asyncio.create_task(publish())
    await asyncio.sleep(0)  # inside wait_for now
    answer.set_result(None)  # the broker's acknowledgement ...
    task.cancel()  # ... and the stop, in the same loop turn
    await asyncio.wait({task})
    if sys.version_info >= (3, 12):  # wait_for is asyncio.timeout since: the race is gone
        assert task.cancelled()
        return
    assert not task.cancelled()
    assert got == ["answer"]
    assert task.cancelling() == 1  # asked to cancel, and ran on


async def test_a_task_gets_its_patience_before_it_is_cancelled_again() -> None:
    """A connection's task says "offline" as it ends: a second cancellation would cut it."""
    steps: list[str] = []

    async def says_goodbye() -> None:
        try:
            await asyncio.sleep(10)
        except asyncio.CancelledError:
            steps.append("cancelled")
            await asyncio.sleep(0.3)  # publishing "offline", say
            steps.append("said offline")
            raise

    task = asyncio.create_task(says_goodbye())
    await asyncio.sleep(0)
    await cancel_and_wait({task}, patience_s=5)
    assert steps == ["cancelled", "said offline"]
    assert task.cancelled()
