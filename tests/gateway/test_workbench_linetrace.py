"""The workbench's line trace records through the bus's recorder, and gives it back.

The recording is the core's (:class:`~sj300_async.gateway.LineTraffic`, what a
line gives a northbound instead of its bus); the workbench's trace words it.
A recording gives the bus a recorder of its own and takes it away when
closed; on a bus that records already it reads the same log and leaves it
there. What it shows is what crossed the line (the frames of a read, in order).
"""

from __future__ import annotations

import sj300_async as sj
from sj300_async.bus import ChunkLog
from sj300_async.gateway import LineTraffic
from sj300_async.gateway.http._linetrace import KEEP_S, MAX_RECORDS, LineTrace


async def test_a_trace_records_the_line_until_it_is_closed() -> None:
    async with sj.open_bus("sim://?nodes=1", timeout=0.05, retries=0) as bus:
        trace = LineTrace(LineTraffic("line1", bus))
        log = bus.recorder
        assert isinstance(log, ChunkLog)
        assert (log.keep_s, log.max_chunks) == (KEEP_S, MAX_RECORDS)
        await bus.drive(1).read_status()
        frames = trace.frames(60.0)
        assert [f["direction"] for f in frames] == ["tx", "rx"]
        assert [f["node"] for f in frames] == [1, 1]
        trace.close()
        assert bus.recorder is None
        before = len(log)
        await bus.drive(1).read_status()
        assert len(log) == before  # nothing recorded once closed


async def test_a_trace_shares_a_recorder_the_bus_has_and_leaves_it() -> None:
    async with sj.open_bus("sim://?nodes=1", timeout=0.05, retries=0) as bus:
        mine = bus.recorder = ChunkLog(keep_s=10.0, max_chunks=100)
        trace = LineTrace(LineTraffic("line1", bus))
        assert bus.recorder is mine
        await bus.drive(1).read_status()
        assert len(mine) == 2
        assert len(trace.frames(60.0)) == 2
        trace.close()
        assert bus.recorder is mine
