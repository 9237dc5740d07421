"""The transport contract: one suite, run over every transport (see conftest.py).

Whatever carries the bytes — memory, TCP, a pseudo-terminal through pyserial,
a socat + ser2net bridge — the bus must give the same answers, the same
typed errors, and release what it opened.
"""

from __future__ import annotations

import asyncio
import gc
import os

import pytest
from waiting import wait_for

import sj300_async as sj

from .conftest import Line


def _open_fds() -> int:
    gc.collect()  # earlier tests' unreachable objects may still hold descriptors
    return len(os.listdir("/proc/self/fd"))


def _line_fds() -> set[tuple[str, str]]:
    """The descriptors that carry a line: sockets and (pseudo-)terminals, with their targets."""
    found: set[tuple[str, str]] = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:  # closed meanwhile (e.g. listdir's own descriptor)
            continue
        if target.startswith(("socket:", "/dev/pts/", "/dev/ptmx", "/dev/tty")):
            found.add((fd, target))
    return found


async def test_every_command_round_trips(line: Line) -> None:
    async with line.open() as bus:
        d = bus.drive(2)
        await d.write_parameter("F002", 0.5)  # 0.5 s from 0 to maximum frequency
        assert await d.read_parameter("F002") == 0.5
        await d.write_parameter_raw("C078", 0)
        assert await d.read_parameter_raw("C078") == 0
        await d.set_frequency(12.5)
        await d.run_forward()
        # Wait for the ramp (F002 = 0.5 s) to reach the setpoint, reading the monitor.
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 5.0
        monitor = await d.read_monitor()
        while monitor.output_frequency_hz != pytest.approx(12.5) and loop.time() < deadline:
            await asyncio.sleep(0.02)
            monitor = await d.read_monitor()
        assert monitor.output_frequency_hz == pytest.approx(12.5)
        assert monitor.direction is sj.Direction.FORWARD
        status = await d.read_status()
        assert status.a is sj.StatusA.RUNNING
        await d.set_terminals(sj.InputTerminal(0))
        history = await d.read_trip_history()
        assert len(history.records) == 6
        assert await d.can_store() is True  # no EEPROM write in progress before store()
        await d.store()
        await d.recalculate_constants()
        await d.stop()
        assert line.sim.drives[2].stored_parameters["F002"] == 50


async def test_many_sequential_transactions_keep_their_values(line: Line) -> None:
    async with line.open() as bus:
        for node in (1, 2, 3, 4):
            await bus.drive(node).write_parameter_raw("A020", 100 * node)
        for i in range(60):
            node = 1 + i % 4
            assert await bus.drive(node).read_parameter_raw("A020") == 100 * node
        assert bus.stats.transactions.timeouts == 0
        assert bus.stats.bad_frames == 0


async def test_concurrent_callers_all_get_their_own_answers(line: Line) -> None:
    async with line.open() as bus:
        for node in (1, 2, 3, 4):
            await bus.drive(node).write_parameter_raw("A020", 1000 + node)

        async def reader(node: int) -> list[int]:
            return [await bus.drive(node).read_parameter_raw("A020") for _ in range(10)]

        results = await asyncio.gather(*(reader(n) for n in (1, 2, 3, 4)))
        assert results == [[1000 + n] * 10 for n in (1, 2, 3, 4)]


async def test_absent_node_times_out_and_the_bus_goes_on(line: Line) -> None:
    async with line.open(timeout=0.1, retries=1) as bus:
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(30).read_status()
        assert bus.drive(30).stats.timeouts == 2
        assert (await bus.drive(1).read_status()).b is sj.StatusB.STOPPED


async def test_nak_is_typed(line: Line) -> None:
    async with line.open() as bus:
        with pytest.raises(sj.NakError) as info:
            await bus.drive(3).read_parameter_raw("A999")
        assert (info.value.node, info.value.code) == (3, sj.NakCode.ABNORMAL_PARAMETER)


async def test_broadcast_reaches_every_drive(line: Line) -> None:
    async with line.open() as bus:
        await bus.broadcast.write_parameter_raw("A020", 4242)
        for node in (1, 2, 3, 4):
            assert await bus.drive(node).read_parameter_raw("A020") == 4242


async def test_close_releases_everything(line: Line) -> None:
    # Warm up once so lazily-opened files (e.g. /dev/urandom) are not counted.
    idle_line = _line_fds()
    async with line.open() as bus:
        await bus.drive(1).read_status()
    # Closing may finish in the background (serial: in a thread; the far end
    # closes its side when it sees ours go): wait until the line's descriptors
    # opened for the warm-up are gone.
    await wait_for(lambda: _line_fds() <= idle_line, "the warm-up's line descriptors to close")
    before = _open_fds()
    async with line.open() as bus:
        await bus.drive(1).read_status()
        assert bus.connected
    # The transport may finish closing in the background (pyserial's
    # connection_lost runs in a task that waits for the port to close in a
    # thread): no task may be left once it has.
    me = asyncio.current_task()
    await wait_for(lambda: asyncio.all_tasks() == {me}, "every task but the test's to end")
    await wait_for(lambda: _open_fds() <= before, f"the open descriptors to return to {before}")
    with pytest.raises(sj.BusClosedError):
        await bus.drive(1).read_status()
