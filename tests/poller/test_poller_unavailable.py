"""A parameter the drive refuses is unavailable, not a failed poll (issue 26).

The simulated drive withholds a parameter (``withheld_parameters``: it
answers NAK 16, as a firmware without the parameter does); the drive stays
online, its status and monitor keep coming, the other parameters too, and
the refused one is named once in the log until it reads again.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator

import pytest

import sj300_async as sj
from sj300_async.profiles import DriveReadings, DriveSnapshot, build_snapshot, get_profile
from sj300_async.simulator.sj300 import SimulatedBus

_LOGGER = "sj300_async.poller"


def _simulator(bus: sj.Bus[sj.Drive, sj.Broadcast]) -> SimulatedBus:
    sim = bus.simulator
    assert isinstance(sim, SimulatedBus)
    return sim


async def _polls(poller: sj.Poller, node: int, count: int) -> list[sj.Sample]:
    """The next *count* samples of *node*."""
    out: list[sj.Sample] = []
    samples: AsyncIterator[sj.Sample] = poller.samples()
    async for sample in samples:
        if sample.node == node:
            out.append(sample)
            if len(out) == count:
                break
    return out


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [
        r.getMessage() for r in caplog.records if r.name == _LOGGER and r.levelno == logging.WARNING
    ]


async def test_a_refused_parameter_is_unavailable_and_the_drive_stays_online(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, _LOGGER)
    async with sj.open_bus("sim://?nodes=1-2", timeout=0.05, retries=0) as bus:
        _simulator(bus).drives[1].withheld_parameters.add("F002")
        poller = sj.Poller(interval_s=0.005, parameters=["F002", "A004"], offline_after=1)
        poller.add(bus, [1, 2])
        async with poller:
            refused = await _polls(poller, 1, 4)
            for sample in refused:
                assert sample.online
                assert sample.answered
                assert sample.error is None
                assert sample.status is not None
                assert sample.monitor is not None
                assert sample.parameters == {"A004": 50.0}  # the read after it, too
                assert sample.unavailable == {"F002"}
            health = poller.health(bus, 1)
            assert (health.failures, health.consecutive_failures) == (0, 0)
            assert health.unavailable == {"F002"}
            # Named once, however many polls refused it; the other drive not at all.
            assert _warnings(caplog) == [
                f"{bus.description} node 01: parameter F002 unavailable "
                "(the drive refuses to read it); the drive stays online"
            ]

            _simulator(bus).drives[1].withheld_parameters.clear()
            await _polls(poller, 1, 1)  # one that may have begun before
            (again,) = await _polls(poller, 1, 1)
            assert again.parameters == {"F002": 30.0, "A004": 50.0}
            assert again.unavailable == frozenset()
            assert poller.health(bus, 1).unavailable == set()
            assert any(
                r.getMessage() == f"{bus.description} node 01: parameter F002 reads again"
                for r in caplog.records
            )

            _simulator(bus).drives[1].withheld_parameters.add("F002")
            await _polls(poller, 1, 3)
            assert len(_warnings(caplog)) == 2  # refused again after reading: named again


async def test_a_time_out_still_fails_the_poll() -> None:
    async with sj.open_bus("sim://?nodes=1", timeout=0.02, retries=0) as bus:
        sim = _simulator(bus)
        sim.drives[1].withheld_parameters.add("F002")
        poller = sj.Poller(interval_s=0.005, parameters=["F002", "A004"], offline_after=2)
        poller.add(bus, [1])
        async with poller:
            await _polls(poller, 1, 1)
            sim.faults.silence(1, True)
            failed = await _polls(poller, 1, 2)
        assert failed[-1].online is False
        assert failed[-1].error is not None
        assert "ReplyTimeoutError" in failed[-1].error
        assert failed[-1].unavailable == frozenset()  # nothing was refused: nothing answered


def test_readings_drop_a_refused_parameter_until_it_reads_again() -> None:
    profile = get_profile("sj300")
    readings = DriveReadings()

    def sample(started: float, parameters: dict[str, float], unavailable: set[str]) -> sj.Sample:
        return sj.Sample(
            bus="sim://", node=1, timestamp=started + 0.1, online=True, status=None,
            monitor=None, parameters=parameters, error=None, latency_s=None, answered=True,
            started=started, unavailable=frozenset(unavailable),
        )  # fmt: skip

    def snapshot() -> DriveSnapshot:
        return build_snapshot(profile, readings, line="l", node=1, unit=1, now=10.0, wall=0.0)

    readings.take(sample(1.0, {"F002": 3.0, "A004": 50.0}, set()), profile)
    assert snapshot().parameters["F002"].raw == 300
    assert snapshot().unavailable_parameters == frozenset()

    readings.take(sample(2.0, {"A004": 50.0}, {"F002"}), profile)
    assert "F002" not in snapshot().parameters  # no value, not a stale one
    assert snapshot().unavailable_parameters == {"F002"}
    assert snapshot().parameters["A004"].at == 2.1

    # A write's read-back after the poll began stays: the refusal is older.
    readings.set_parameter("F002", 400, 3.5)
    readings.take(sample(3.0, {"A004": 50.0}, {"F002"}), profile)
    assert snapshot().parameters["F002"].raw == 400
    assert snapshot().unavailable_parameters == frozenset()

    readings.take(sample(4.0, {}, {"F002"}), profile)
    readings.take(sample(5.0, {"F002": 5.0}, set()), profile)
    assert snapshot().parameters["F002"].raw == 500
    assert snapshot().unavailable_parameters == frozenset()
