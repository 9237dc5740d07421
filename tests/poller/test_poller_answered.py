"""A drive that has never answered: ``answered`` stays False until its first reply."""

from __future__ import annotations

import pytest

import sj300_async as sj
from sj300_async.sj300 import NakCode, NakReply, Request


async def test_answered_turns_true_at_the_first_reply_and_stays() -> None:
    async with sj.open_bus("sim://?nodes=1-4", timeout=0.02, retries=0) as bus:
        sim = bus.simulator
        assert sim is not None
        sim.faults.silence(3, True)
        poller = sj.Poller(interval_s=0.005, offline_after=2, offline_probe_interval_s=0.05)
        poller.add(bus, [1, 3])
        assert not poller.health(bus, 1).answered  # nothing polled yet
        seen: list[sj.Sample] = []
        async with poller:
            samples = poller.samples()
            async for sample in samples:
                seen.append(sample)
                if sample.node == 3 and not sample.online:
                    break
            never = [s for s in seen if s.node == 3]
            assert len(never) == 2
            # Polled in full (online) until offline_after failures, but never answered.
            assert [s.online for s in never] == [True, False]
            assert not any(s.answered for s in never)
            assert not poller.health(bus, 3).answered
            assert all(s.answered for s in seen if s.node == 1)
            assert poller.health(bus, 1).answered
            sim.faults.silence(3, False)
            async for sample in samples:
                if sample.node == 3 and sample.online:
                    assert sample.answered
                    break
            # Silent again: no longer online in time, but it has answered once.
            sim.faults.silence(3, True)
            async for sample in samples:
                if sample.node == 3 and sample.error is not None:
                    assert sample.answered
                    break
        assert poller.health(bus, 3).answered


async def test_a_refusal_is_an_answer(monkeypatch: pytest.MonkeyPatch) -> None:
    async with sj.open_bus("sim://?nodes=1", timeout=0.05, retries=0) as bus:
        sim = bus.simulator
        assert sim is not None
        drive = sim.drives[1]

        def refuse(request: Request, now: float) -> NakReply:  # a drive that refuses everything
            return NakReply(request.node, NakCode.EXECUTION_DISABLED)

        monkeypatch.setattr(drive, "handle", refuse)
        poller = sj.Poller(interval_s=0.005)
        poller.add(bus, [1])
        got: list[sj.Sample] = []
        async with poller:
            async for sample in poller.samples():
                got.append(sample)
                break
        [sample] = got
        assert sample.error is not None
        assert "NakError" in sample.error
        assert sample.answered  # it is there: it refused
