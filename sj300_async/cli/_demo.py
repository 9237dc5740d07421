"""The embedded demo of ``sj300 monitor``: eight simulated drives doing something worth watching.

:func:`run_demo` drives a ``sim://`` bus through the public Drive API, as a
program on the line would: it starts the drives at different speeds and
ramp times, then now and then changes a setpoint, reverses or stops a drive
and starts it again. Every ``trip_every_s`` (give or take) one running drive
trips (the simulator's fault hook, as a fault inside the drive would), sits
in its trip for a few seconds, and is reset the way its profile resets a
drive (SJ300: the RS terminal through command 02) and started again.

It shares the bus with the poller: its commands queue on the same arbiter.
A command that fails is skipped; the demo goes on.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
from collections.abc import AsyncIterator, Awaitable
from typing import Final

from ..bus import Bus
from ..profiles import get_profile
from ..wire import Direction, LocalProtocolError, SJ300Error

__all__ = ["DEMO_NODES", "DEMO_URL", "demo_running", "run_demo"]

_log = logging.getLogger("sj300_async.cli.demo")

#: The demo's bus (``sj300 monitor`` without --url, ``sj300 gateway --demo``), and its nodes.
DEMO_URL: Final = "sim://?nodes=1-8"
DEMO_NODES: Final = "1-8"
#: Setpoints the demo picks from (Hz; the simulated drives' maximum is 50 Hz).
_SETPOINTS: Final = (10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 45.0, 50.0)
#: Trips the demo causes: None is the over-current code that fits the drive's phase; the
#: others are SJ300 trip factors (overload, over-voltage, thermal), which the demo's
#: simulated line (the SJ300's, unless --protocol says otherwise) names.
_TRIP_CODES: Final = (None, None, 5, 7, 21)


async def run_demo(
    bus: Bus,
    *,
    trip_every_s: float = 12.0,
    tripped_s: float = 4.0,
    tick_s: float = 0.5,
    seed: int | None = None,
) -> None:
    """Animate the simulated drives of *bus* until cancelled.

    Args:
        trip_every_s: mean time between trips (the first comes after half of it).
        tripped_s: how long a tripped drive waits for its reset.
        tick_s: time between the demo's decisions.
        seed: for a repeatable show.

    Raises:
        LocalProtocolError: *bus* is not a ``sim://`` bus.
    """
    if bus.simulator is None:
        raise LocalProtocolError("the demo needs a sim:// bus")
    await _Demo(bus, random.Random(seed), trip_every_s, tripped_s, tick_s).run()


class _Demo:
    def __init__(
        self, bus: Bus, rng: random.Random, trip_every_s: float, tripped_s: float, tick_s: float
    ) -> None:
        assert bus.simulator is not None
        self._bus = bus
        self._profile = get_profile(bus.dialect.name)
        self._sim = bus.simulator
        self._rng = rng
        self._trip_every_s = trip_every_s
        self._tripped_s = tripped_s
        self._tick_s = tick_s
        self._nodes = sorted(self._sim.drives)
        #: What the demo last commanded each drive (STOP when stopped or tripped).
        self._running: dict[int, Direction] = dict.fromkeys(self._nodes, Direction.STOP)
        #: Tripped drives and the loop time of their reset.
        self._resets: dict[int, float] = {}

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        for node in self._nodes:
            ramp = self._rng.choice((2.0, 3.0, 5.0, 8.0))
            drive = self._bus.drive(node)
            for code in self._profile.ramp_parameters:  # acceleration, deceleration time
                await self._do(drive.write_parameter(code, ramp))
            if node != self._nodes[-1]:  # one drive starts stopped: something to start later
                await self._start(node)
        next_trip = loop.time() + self._trip_every_s / 2
        while True:
            await asyncio.sleep(self._tick_s)
            now = loop.time()
            for node, at in list(self._resets.items()):
                if now >= at:
                    del self._resets[node]
                    await self._reset(node)
            if now >= next_trip:
                self._trip(now)
                next_trip = now + self._trip_every_s * self._rng.uniform(0.7, 1.3)
            if self._rng.random() < 0.6:
                await self._change()

    async def _do(self, step: Awaitable[None]) -> bool:
        try:
            await step
        except SJ300Error as exc:
            _log.debug("demo step failed: %s", exc)
            return False
        return True

    async def _start(self, node: int, direction: Direction | None = None) -> None:
        drive = self._bus.drive(node)
        if direction is None:
            direction = self._rng.choice((Direction.FORWARD, Direction.FORWARD, Direction.REVERSE))
        await self._do(drive.set_frequency(self._rng.choice(_SETPOINTS)))
        run = drive.run_forward() if direction is Direction.FORWARD else drive.run_reverse()
        if await self._do(run):
            self._running[node] = direction

    async def _change(self) -> None:
        candidates = [n for n in self._nodes if n not in self._resets]
        if not candidates:
            return
        node = self._rng.choice(candidates)
        drive = self._bus.drive(node)
        direction = self._running[node]
        if direction is Direction.STOP:
            await self._start(node)
            return
        action = self._rng.random()
        if action < 0.5:
            await self._do(drive.set_frequency(self._rng.choice(_SETPOINTS)))
        elif action < 0.75:
            other = Direction.REVERSE if direction is Direction.FORWARD else Direction.FORWARD
            await self._start(node, other)
        elif await self._do(drive.stop()):
            self._running[node] = Direction.STOP

    def _trip(self, now: float) -> None:
        running = [n for n, d in self._running.items() if d is not Direction.STOP]
        if not running:
            return
        node = self._rng.choice(running)
        if self._sim.drives[node].trip(self._rng.choice(_TRIP_CODES), now=now):
            self._running[node] = Direction.STOP  # a trip clears the run command
            self._resets[node] = now + self._tripped_s

    async def _reset(self, node: int) -> None:
        await self._do(self._profile.reset(self._bus.drive(node)))
        await self._start(node)


@contextlib.asynccontextmanager
async def demo_running(buses: list[Bus]) -> AsyncIterator[None]:
    """Animate the simulated drives of each of *buses* while the block runs.

    A demo that fails is logged when the block ends (it stops; nothing else does).
    """
    tasks = [asyncio.create_task(run_demo(bus), name="sj300 demo") for bus in buses]
    try:
        yield
    finally:
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.wait(tasks)
        for task in tasks:
            if not task.cancelled() and task.exception() is not None:
                _log.warning("the demo stopped: %s", task.exception())
