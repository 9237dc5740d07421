"""The poller polling FR-700 drives, alone and next to an SJ300 bus."""

from __future__ import annotations

import pytest

import sj300_async as sj
from sj300_async.fr700 import Fr700Monitor, Fr700Status
from sj300_async.simulator.fr700 import Fr700SimulatedBus


async def test_fr700_samples_carry_typed_reads_and_parameters() -> None:
    async with sj.open_bus(
        "sim://?protocol=fr700&nodes=0-3", protocol="fr700", timeout=0.05, retries=0
    ) as bus:
        await bus.drive(2).write_parameter(7, 3.3)  # s
        poller = sj.Poller(interval_s=0.01, parameters=["Pr.7", "pr123", "F002"])
        poller.add(bus, [0, 2])
        seen: dict[int, sj.Sample] = {}
        async with poller:
            async for sample in poller.samples():
                seen[sample.node] = sample
                if len(seen) == 2:
                    break
        sample = seen[2]
        assert sample.online
        assert sample.error is None
        assert isinstance(sample.status, Fr700Status)
        assert isinstance(sample.monitor, Fr700Monitor)
        # the FR-700 bus reads its own parameters in their units, not the SJ300 code
        assert sample.parameters == {"Pr.7": 3.3, "Pr.123": 9999}


async def test_fr700_drive_goes_offline_and_back() -> None:
    async with sj.open_bus(
        "sim://?protocol=fr700&nodes=0-3", protocol="fr700", timeout=0.02, retries=0
    ) as bus:
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        poller = sj.Poller(interval_s=0.005, offline_after=2, offline_probe_interval_s=0.05)
        poller.add(bus, [1, 3])
        sim.faults.silence(3)
        async with poller:
            samples = poller.samples()
            async for sample in samples:
                if sample.node == 3 and not sample.online:
                    break
            assert "ReplyTimeoutError" in (poller.health(bus, 3).last_error or "")
            sim.faults.silence(3, False)
            async for sample in samples:
                if sample.node == 3 and sample.online:
                    break


async def test_one_poller_for_both_protocols() -> None:
    async with (
        sj.open_bus("sim://?nodes=1-2", timeout=0.05) as sj300,
        sj.open_bus("sim://?protocol=fr700&nodes=0-1", protocol="fr700", timeout=0.05) as fr700,
    ):
        poller = sj.Poller(interval_s=0.01, parameters=["F002", "Pr.8"])
        poller.add(sj300, [1, 2])
        poller.add(fr700, [0, 1])
        seen: dict[tuple[str, int], sj.Sample] = {}
        async with poller:
            async for sample in poller.samples():
                seen[sample.bus, sample.node] = sample
                if len(seen) == 4:
                    break
        for (bus, _node), sample in seen.items():
            assert sample.error is None
            if bus == fr700.description:
                assert isinstance(sample.status, Fr700Status)
                assert set(sample.parameters) == {"Pr.8"}
            else:
                assert isinstance(sample.status, sj.InverterStatus)
                assert set(sample.parameters) == {"F002"}


def test_parameter_names_are_checked() -> None:
    with pytest.raises(sj.LocalProtocolError):
        sj.Poller(parameters=["Pr.1000"])
    with pytest.raises(sj.LocalProtocolError):
        sj.Poller(parameters=["X123"])
    assert sj.Poller(parameters=["pr 7", "f002"]).parameters == ("Pr.7", "F002")
