"""The paced simulator's event loop keeps sub-millisecond timer time.

asyncio's default loop on Linux cannot: epoll's time-out is whole
milliseconds, so a 0.3 ms timer fires no sooner than 1 ms after it was set,
0.7 ms late, every time. The select-based loop's timers must land well
inside that, else a paced line blames the host for the emulation's rounding.
"""

from __future__ import annotations

import asyncio
import functools
import os
import selectors
import statistics

from sj300_async.simulator import precise_event_loop

_DELAY_S = 0.0003
_SAMPLES = 41


def _stamp(fired: asyncio.Future[float], loop: asyncio.AbstractEventLoop) -> None:
    fired.set_result(loop.time())


async def _lateness() -> list[float]:
    loop = asyncio.get_running_loop()
    late: list[float] = []
    for _ in range(_SAMPLES):
        fired: asyncio.Future[float] = loop.create_future()
        due = loop.time() + _DELAY_S
        loop.call_at(due, _stamp, fired, loop)
        late.append(await fired - due)
    return late


def test_precise_loop_is_select_based() -> None:
    loop = precise_event_loop()
    try:
        assert isinstance(loop, asyncio.SelectorEventLoop)
        assert isinstance(loop._selector, selectors.SelectSelector)  # type: ignore[attr-defined]
    finally:
        loop.close()


def test_sub_millisecond_timers_fire_on_time() -> None:
    with asyncio.Runner(loop_factory=precise_event_loop) as runner:
        late = runner.run(_lateness())
    # Never early (asyncio may run a timer up to its clock resolution, 1 ns, early).
    assert min(late) > -1e-6
    # epoll would make every one of them >= 0.7 ms late; the median here is
    # normally tens of microseconds (bound loose for a loaded machine).
    assert statistics.median(late) < 0.0004


def test_a_spinning_loop_times_timers_and_sees_descriptors() -> None:
    spinning = functools.partial(precise_event_loop, spin=True)
    with asyncio.Runner(loop_factory=spinning) as runner:
        late = runner.run(_lateness())
        assert min(late) > -1e-6
        assert statistics.median(late) < 0.0004
        # A descriptor that becomes readable ends the poll as a sleep would.
        read_fd, write_fd = os.pipe()
        try:

            async def readable() -> bytes:
                loop = asyncio.get_running_loop()
                ready: asyncio.Future[bytes] = loop.create_future()
                loop.add_reader(read_fd, lambda: ready.set_result(os.read(read_fd, 10)))
                loop.call_later(0.001, os.write, write_fd, b"x")
                try:
                    return await asyncio.wait_for(ready, 1.0)
                finally:
                    loop.remove_reader(read_fd)

            assert runner.run(readable()) == b"x"
        finally:
            os.close(read_fd)
            os.close(write_fd)
