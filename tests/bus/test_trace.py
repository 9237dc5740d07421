"""The trace shows the bytes exactly as they crossed the line, and what the parser made of them."""

from __future__ import annotations

import math

from waiting import wait_for

import sj300_async as sj
import sj300_async.bus as sjbus
from sj300_async import sj300 as sj3

from .scripted import MakeRig, reply

# A monitor block whose two hex fields (the terminal monitors) are lower case
# on the wire, as a drive may send them: 4 decimal items, 2 hex, 7 decimal.
_MONITOR = b"0" * 32 + b"0000000e" + b"0000001f" + b"0" * 56


def _monitor_in_pieces(request: sj3.Request) -> list[tuple[float, bytes]]:
    frame = reply(b"%02d" % request.node + _MONITOR)
    return [(0.0, b"xy" + frame[:10]), (0.001, frame[10:60]), (0.002, frame[60:])]


async def test_rx_records_are_the_chunks_as_they_arrived(scripted: MakeRig) -> None:
    async with scripted(_monitor_in_pieces) as rig:
        monitor = await rig.bus.drive(4).read_monitor()
    assert monitor.input_terminals.value == 0x0E
    frame = reply(b"04" + _MONITOR)
    tx = [r for r in rig.trace if r.direction == "tx"]
    rx = [r for r in rig.trace if r.direction == "rx"]
    assert [r.data for r in tx] == [sj3.requests.read_monitor(4).frame]
    # Byte for byte, lower-case hex included, in the chunks the line delivered.
    assert [r.data for r in rx] == [b"xy" + frame[:10], frame[10:60], frame[60:]]
    assert b"0000000e" in b"".join(r.data for r in rx)
    # The garbage is discarded with the first chunk; the reply completes with the last.
    assert [type(e).__name__ for e in rx[0].events] == ["Discarded"]
    assert rx[1].events == ()
    (event,) = rx[2].events
    assert isinstance(event, sj3.DataReply)
    assert rig.bus.dialect.describe(event).startswith("node 04 data 0000")
    assert rx[0].timestamp <= rx[1].timestamp <= rx[2].timestamp


def test_replies_are_described_for_traces() -> None:
    dialect = sj3.SJ300_DIALECT
    assert dialect.describe(sj3.AckReply(3)) == "node 03 ACK"
    assert dialect.describe(sj3.NakReply(3, sj.NakCode(16))).startswith("node 03 NAK 16 (")
    assert dialect.describe(sj3.AckDataReply(3, b"00001000")) == "node 03 ACK + data 00001000"


def _as_kept(records: list[sjbus.TraceRecord]) -> list[sjbus.Kept]:
    # The log keeps times to the microsecond (the pcapng resolution).
    return [(round(r.timestamp * 1e6) / 1e6, r.direction, r.data, bool(r.early)) for r in records]


async def test_a_recorder_keeps_what_the_trace_sees_chunk_for_chunk(scripted: MakeRig) -> None:
    log = sjbus.ChunkLog(keep_s=300.0, max_chunks=1000)
    async with scripted(_monitor_in_pieces) as rig:
        rig.bus.recorder = log
        await rig.bus.drive(4).read_monitor()
        await rig.bus.drive(5).read_monitor()
        kept = list(log.since(-math.inf))
        assert len(kept) == 8  # two requests, two replies in three chunks each
        assert kept == _as_kept(rig.trace)
        rig.bus.recorder = None  # recording stops; the trace goes on
        await rig.bus.drive(6).read_monitor()
    assert list(log.since(-math.inf)) == kept
    assert len(rig.trace) == 12


async def test_a_reconnection_keeps_recording(scripted: MakeRig) -> None:
    log = sjbus.ChunkLog(keep_s=300.0, max_chunks=1000)
    async with scripted(_monitor_in_pieces) as rig:
        rig.bus.recorder = log
        await rig.bus.drive(4).read_monitor()
        first = rig.bus.link.protocol
        rig.bus.link.drop()
        await wait_for(
            lambda: rig.bus.connected and rig.bus.link.protocol is not first, "a new connection"
        )
        await rig.bus.drive(5).read_monitor()  # recorded by the new one, made with the recorder
        assert list(log.since(-math.inf)) == _as_kept(rig.trace)
        assert len(log) == 8
