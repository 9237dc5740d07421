"""The transport contract for FR-700: one suite over memory, TCP and a pty (see conftest.py).

Whatever carries the bytes, an FR-700 bus must give the same answers, the
same typed errors, and release what it opened.
"""

from __future__ import annotations

import asyncio
import gc
import os

import pytest

import sj300_async as sj
from sj300_async.fr700 import Fr700NakCode, Fr700OperationMode

from .conftest import Fr700Line


def _open_fds() -> int:
    gc.collect()
    return len(os.listdir("/proc/self/fd"))


async def test_every_instruction_round_trips(fr700_line: Fr700Line) -> None:
    async with fr700_line.open() as bus:
        d = bus.drive(2)
        await d.write_parameter_raw(7, 5)  # 0.5 s from 0 to 60 Hz
        assert await d.read_parameter_raw(7) == 5
        await d.write_parameter_raw(122, 100)  # bank 1
        assert await d.read_parameter_raw("Pr.122") == 100
        assert await d.read_operation_mode() is Fr700OperationMode.NETWORK
        await d.set_frequency(12.5)
        await d.set_frequency(12.5, eeprom=True)
        assert await d.read_set_frequency(eeprom=True) == 12.5
        await d.run_forward()
        await asyncio.sleep(0.3)
        monitor = await d.read_monitor()
        assert monitor.output_frequency_hz == pytest.approx(12.5)
        status = await d.read_status()
        assert status.running
        assert status.forward
        assert status.up_to_frequency
        reply = await d.multi_command(sj.Direction.FORWARD, 12.5)
        assert reply.ok
        assert reply.value == 12.5
        assert await d.read(0x7F) == 1  # the bank the last parameter access selected
        await d.stop()
        assert fr700_line.sim.drives[2].stored_frequency_hz == 12.5


async def test_many_sequential_transactions_keep_their_values(fr700_line: Fr700Line) -> None:
    async with fr700_line.open() as bus:
        for station in (0, 1, 2, 3):
            await bus.drive(station).set_frequency(10.0 + station)
        for i in range(24):
            station = i % 4
            assert await bus.drive(station).read_set_frequency() == 10.0 + station
        assert bus.stats.transactions.timeouts == 0
        assert bus.stats.bad_frames == 0


async def test_concurrent_callers_all_get_their_own_answers(fr700_line: Fr700Line) -> None:
    async with fr700_line.open() as bus:
        for station in (0, 1, 2, 3):
            await bus.drive(station).write_parameter_raw(7, 10 + station)

        async def reader(station: int) -> list[int]:
            return [await bus.drive(station).read_parameter_raw(7) for _ in range(5)]

        results = await asyncio.gather(*(reader(n) for n in (0, 1, 2, 3)))
        assert results == [[10 + n] * 5 for n in (0, 1, 2, 3)]


async def test_absent_station_times_out_and_the_bus_goes_on(fr700_line: Fr700Line) -> None:
    async with fr700_line.open(timeout=0.1, retries=1) as bus:
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(30).read_status()
        assert bus.drive(30).stats.timeouts == 2
        assert not (await bus.drive(1).read_status()).running


async def test_nak_is_typed(fr700_line: Fr700Line) -> None:
    async with fr700_line.open() as bus:
        with pytest.raises(sj.NakError) as info:
            await bus.drive(3).set_frequency(400.0)
        assert (info.value.node, info.value.code) == (3, Fr700NakCode.DATA_RANGE)


async def test_reset_reaches_the_drive(fr700_line: Fr700Line) -> None:
    async with fr700_line.open() as bus:
        fr700_line.sim.drives[1].trip(now=asyncio.get_running_loop().time())
        assert (await bus.drive(1).read_status()).tripped
        await bus.drive(1).reset()
        assert not (await bus.drive(1).read_status()).tripped


async def test_close_releases_everything(fr700_line: Fr700Line) -> None:
    async with fr700_line.open() as bus:
        await bus.drive(1).read_status()
    await asyncio.sleep(0.05)
    before = _open_fds()
    async with fr700_line.open() as bus:
        await bus.drive(1).read_status()
        assert bus.connected
    await asyncio.sleep(0.05)
    assert _open_fds() <= before
    assert asyncio.all_tasks() == {asyncio.current_task()}
    with pytest.raises(sj.BusClosedError):
        await bus.drive(1).read_status()
