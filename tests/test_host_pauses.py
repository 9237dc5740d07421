"""The host-pause helpers judge what they claim to (tests/host_pauses.py)."""

from __future__ import annotations

import asyncio
import time

from host_pauses import LoopStalls


async def test_loop_stalls_measure_the_span_the_loop_was_held() -> None:
    loop = asyncio.get_running_loop()
    stalls = LoopStalls()
    try:
        await asyncio.sleep(0.02)  # the probe ticking
        held_start = loop.time()
        time.sleep(0.2)  # the loop held, as a host pause or a blocking call would
        await asyncio.sleep(0.02)  # let the late tick run
        held = stalls.within(held_start, loop.time())
        # Half the span: only the part that overlaps it counts.
        half = stalls.within(held_start + 0.1, held_start + 0.15)
    finally:
        stalls.close()
    assert 0.19 <= held <= 0.22
    assert 0.049 <= half <= 0.051
