"""Cancelling a caller at any point leaves the bus usable and in sync."""

from __future__ import annotations

import asyncio

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sj300_async as sj
from sj300_async import sj300 as sj3

from .scripted import Frames, MakeRig, Responder, ack_value, answer_all


def node_specific(delay: float) -> Responder:
    """Each node answers a parameter read with a value that names the node and the code."""

    def respond(req: sj3.Request) -> Frames:
        if req.command is sj3.Command.READ_PARAMETER:
            return [(delay, ack_value(req.node, req.node * 10000 + int(req.data[1:])))]
        return [(delay, frame) for _, frame in answer_all(req)]

    return respond


async def _scenario(scripted: MakeRig, steps: int, delay: float, queued: int) -> None:
    # No answer is ever missing here, so the reply margin only has to outlast a
    # loaded machine's scheduling stalls (50 ms did not, once in a full `make test`); the
    # drains of some cancelled examples wait it out, so it is not larger.
    async with scripted(node_specific(delay), retries=0, timing=sj.BusTiming(margin_s=0.2)) as rig:
        bus = rig.bus
        victim = asyncio.create_task(bus.drive(1).read_parameter_raw("F002"))
        others = [
            asyncio.create_task(bus.drive(n).read_parameter_raw("A004"))
            for n in range(2, 2 + queued)
        ]
        for _ in range(steps):
            await asyncio.sleep(0)
        victim.cancel()
        results = await asyncio.gather(victim, *others, return_exceptions=True)
        assert isinstance(results[0], asyncio.CancelledError) or results[0] == 10002
        assert results[1:] == [n * 10000 + 4 for n in range(2, 2 + queued)]
        # In sync afterwards: every node answers its own question, in any order of asking.
        for node, code in ((1, "F003"), (7, "C078"), (1, "A001"), (3, "B084")):
            assert await bus.drive(node).read_parameter_raw(code) == node * 10000 + int(code[1:])
        assert not bus._arbiter.queue.busy
        assert bus._arbiter.queue.waiting == 0
        assert bus._arbiter._outstanding is None


# `scripted` is a stateless factory: every example opens its own bus.
@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    steps=st.integers(min_value=0, max_value=30),
    delay=st.sampled_from([0.0, 0.002]),
    queued=st.integers(min_value=0, max_value=3),
)
def test_cancel_at_any_point(scripted: MakeRig, steps: int, delay: float, queued: int) -> None:
    asyncio.run(_scenario(scripted, steps, delay, queued))


async def test_cancel_while_queued_sends_nothing(scripted: MakeRig) -> None:
    async with scripted(node_specific(0.01)) as rig:
        first = asyncio.create_task(rig.bus.drive(1).read_status())
        await asyncio.sleep(0)
        queued = asyncio.create_task(rig.bus.drive(2).read_status())
        await asyncio.sleep(0)
        queued.cancel()
        await first
        await asyncio.gather(queued, return_exceptions=True)
        assert [r.node for r in rig.peer.requests] == [1]
        assert rig.bus.stats.drains == 0


async def test_cancel_in_flight_drains_and_is_counted(scripted: MakeRig) -> None:
    async with scripted(node_specific(0.02)) as rig:
        task = asyncio.create_task(rig.bus.drive(1).read_parameter_raw("F002"))
        await asyncio.sleep(0.005)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        assert task.cancelled()
        assert rig.bus.drive(1).stats.cancelled == 1
        # The cancelled request's answer arrives at 20 ms: it must not answer this one.
        assert await rig.bus.drive(1).read_parameter_raw("F003") == 10003
        assert rig.bus.stats.unsolicited_frames == 1
        assert rig.bus.stats.drains == 1


async def test_cancellederror_is_never_wrapped(scripted: MakeRig) -> None:
    async with scripted(lambda req: []) as rig:
        task = asyncio.create_task(rig.bus.drive(1).read_status())
        await asyncio.sleep(0.001)
        task.cancel()
        with pytest.raises(asyncio.CancelledError) as info:
            await task
        assert not isinstance(info.value, sj.SJ300Error)
