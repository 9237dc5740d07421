"""The poller over in-memory simulated buses."""

from __future__ import annotations

import asyncio
from contextlib import AbstractAsyncContextManager

import pytest
from waiting import wait_for

import sj300_async as sj


def _fast_bus(nodes: str = "1-4") -> AbstractAsyncContextManager[sj.Bus[sj.Drive, sj.Broadcast]]:
    return sj.open_bus(f"sim://?nodes={nodes}", timeout=0.02, retries=0)


async def test_samples_carry_typed_reads_and_parameters() -> None:
    async with _fast_bus() as bus:
        await bus.drive(2).write_parameter("F002", 7.5)
        poller = sj.Poller(interval_s=0.01, parameters=["F002"])
        poller.add(bus, [1, 2])
        seen: dict[int, sj.Sample] = {}
        async with poller:
            async for sample in poller.samples():
                seen[sample.node] = sample
                if len(seen) == 2:
                    break
        s = seen[2]
        assert s.online
        assert s.error is None
        assert isinstance(s.status, sj.InverterStatus)
        assert isinstance(s.monitor, sj.MonitorData)
        assert s.parameters == {"F002": 7.5}
        assert s.latency_s is not None


async def test_offline_after_n_failures_probed_less_often_then_back_online() -> None:
    async with _fast_bus() as bus:
        sim = bus.simulator
        assert sim is not None
        poller = sj.Poller(interval_s=0.005, offline_after=3, offline_probe_interval_s=0.2)
        poller.add(bus, [1, 3])
        sim.faults.silence(3, True)
        async with poller:
            samples = poller.samples()
            async for sample in samples:
                if sample.node == 3 and not sample.online:
                    break
            health = poller.health(bus, 3)
            assert health.consecutive_failures == 3
            assert "ReplyTimeoutError" in (health.last_error or "")
            # While offline, node 3 is probed at most every 0.2 s; node 1 keeps being polled.
            loop = asyncio.get_running_loop()
            polls_3, polls_1 = health.polls, poller.health(bus, 1).polls
            start = loop.time()
            await wait_for(
                lambda: poller.health(bus, 1).polls - polls_1 >= 5, "five polls of node 1"
            )
            elapsed = loop.time() - start
            probes = poller.health(bus, 3).polls - polls_3
            assert probes <= 1 + int(elapsed / 0.2), (probes, elapsed)
            sim.faults.silence(3, False)
            async for sample in samples:
                if sample.node == 3 and sample.online:
                    break
            assert poller.health(bus, 3).consecutive_failures == 0


async def test_commands_interleave_without_waiting_for_a_cycle() -> None:
    async with _fast_bus("1-8") as bus:
        poller = sj.Poller(interval_s=0.0, parameters=["F002", "F003", "A004"])
        poller.add(bus, range(1, 9))
        loop = asyncio.get_running_loop()
        async with poller:
            # Polling at full speed.
            await wait_for(lambda: poller.bus_stats(bus).cycles >= 2, "two polling cycles")
            cycle = poller.bus_stats(bus).mean_cycle_s
            assert cycle is not None
            start = loop.time()
            await bus.drive(5).set_frequency(12.0)
            waited = loop.time() - start
            stop_start = loop.time()
            await bus.drive(5).stop()
            stop_waited = loop.time() - stop_start
        # A command waits for the transaction on the line, not for the 8-drive cycle.
        assert waited < cycle / 4, (waited, cycle)
        assert stop_waited < cycle / 4, (stop_waited, cycle)


async def test_two_buses_are_polled_concurrently() -> None:
    async with _fast_bus("1-2") as a, _fast_bus("1-3") as b:
        a.simulator.faults.late(1, 0.01)  # bus A is slow; B must not wait for it
        poller = sj.Poller(interval_s=0.0)
        poller.add(a, [1, 2])
        poller.add(b, [1, 2, 3])
        counts: dict[str, int] = {}
        poller.on_sample(lambda s: counts.__setitem__(s.bus, counts.get(s.bus, 0) + 1))
        async with poller:
            await wait_for(
                lambda: counts.get(a.description, 0) >= 3 and counts.get(b.description, 0) >= 100,
                "3 samples from bus A and 100 from bus B",
            )
        assert set(counts) == {a.description, b.description}
        # B's cycle is not held back by A's slow drive.
        assert counts[b.description] > 3 * counts[a.description]


async def test_cancellation_stops_polling_cleanly() -> None:
    async with _fast_bus() as bus:
        poller = sj.Poller(interval_s=0.001)
        poller.add(bus, [1, 2])

        consumed = 0

        async def consume() -> None:
            nonlocal consumed
            async with poller:
                async for _ in poller.samples():
                    consumed += 1

        task = asyncio.create_task(consume())
        await wait_for(lambda: consumed >= 3, "three samples consumed")
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        assert asyncio.all_tasks() == {asyncio.current_task(), *_bus_tasks()}
        # The bus is still usable and in sync after the poller was cancelled mid-poll.
        await bus.drive(1).write_parameter_raw("A020", 1234)
        assert await bus.drive(1).read_parameter_raw("A020") == 1234
        assert bus._arbiter._outstanding is None


def _bus_tasks() -> set[asyncio.Task[object]]:
    return {t for t in asyncio.all_tasks() if t.get_name().startswith("sj300 link")}


async def test_slow_consumer_drops_are_counted() -> None:
    async with _fast_bus() as bus:
        poller = sj.Poller(interval_s=0.0, buffer=2)
        poller.add(bus, [1])
        async with poller:
            samples = poller.samples()
            first = await samples.__anext__()
            # Do not read: the buffer overflows.
            await wait_for(lambda: poller.dropped_samples > 0, "a dropped sample")
            assert poller.dropped_samples > 0
            second = await samples.__anext__()
            assert second.timestamp > first.timestamp
            await samples.aclose()


async def test_samples_iterator_ends_when_the_poller_stops() -> None:
    async with _fast_bus() as bus:
        poller = sj.Poller(interval_s=0.01)
        poller.add(bus, [1])
        got: list[sj.Sample] = []

        async def reader() -> None:
            async for s in poller.samples():
                got.append(s)

        async with poller:
            task = asyncio.create_task(reader())
            await wait_for(lambda: len(got) >= 3, "three samples")
        await asyncio.wait_for(task, 1)
        # Node 1's samples, online, in order, until the poller stopped.
        assert len(got) >= 2
        assert {s.node for s in got} == {1}
        assert {s.bus for s in got} == {bus.description}
        assert all(s.online and s.error is None for s in got)
        assert all(isinstance(s.status, sj.InverterStatus) for s in got)
        timestamps = [s.timestamp for s in got]
        assert timestamps == sorted(timestamps)
        assert len(set(timestamps)) == len(timestamps)


def test_bad_configuration_is_refused() -> None:
    with pytest.raises(sj.LocalProtocolError):
        sj.Poller(reads=["temperature"])  # type: ignore[list-item]
    with pytest.raises(sj.LocalProtocolError):
        sj.Poller(offline_after=0)
    with pytest.raises(sj.LocalProtocolError):
        sj.Poller(parameters=["X123"])


async def test_a_hold_starts_no_poll_until_every_hold_is_released() -> None:
    async with _fast_bus("1-2") as bus:
        poller = sj.Poller(interval_s=0.0)
        poller.add(bus, [1, 2])
        with pytest.raises(sj.LocalProtocolError, match="without a hold"):
            poller.release(bus)
        async with poller:
            await wait_for(lambda: poller.health(bus, 2).polls >= 1, "a first poll")
            poller.hold(bus)
            poller.hold(bus.description)  # holds nest; a bus or its description
            # A poll under way when the hold came goes on; after it, none starts.
            polled = sum(poller.health(bus, n).polls for n in (1, 2))
            for _ in range(20):  # our own requests get the line, turn after turn
                await bus.drive(1).read_status()
            held = sum(poller.health(bus, n).polls for n in (1, 2))
            assert held - polled <= 1
            for _ in range(20):
                await bus.drive(2).read_status()
            assert sum(poller.health(bus, n).polls for n in (1, 2)) == held
            poller.release(bus)
            for _ in range(20):
                await bus.drive(1).read_status()
            assert sum(poller.health(bus, n).polls for n in (1, 2)) == held  # one hold left
            poller.release(bus)
            await wait_for(
                lambda: sum(poller.health(bus, n).polls for n in (1, 2)) >= held + 2,
                "polls again",
            )
