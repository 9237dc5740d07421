"""Captures of a known exchange, parsed back byte for byte (issue 17's first must-show).

A bus runs a scripted exchange on the simulator with a capture open and a
trace hook watching. The capture is read back with the pcapng reader and
checked against three independent accounts of what crossed the line: the
frames the library's encoders make, the trace records (every chunk as it
was written or arrived), and the simulator's faults.
"""

from __future__ import annotations

import asyncio
import random
import time
from itertools import pairwise
from pathlib import Path

import pytest
from waiting import wait_for

import sj300_async as sj
from sj300_async.bus import CaptureFile, TraceRecord
from sj300_async.sj300 import _requests as requests
from sj300_async.transports import LineFaults, LoopbackTransport
from sj300_async.wire._pcapng import (
    FLAG_CHECK_ERROR,
    FLAG_NOISE,
    PacketDirection,
    read_pcapng,
)


def _loopback(bus: sj.Bus[sj.Drive, sj.Broadcast]) -> LoopbackTransport:
    """The sim:// bus's transport, to put bytes on the line as if a drive sent them."""
    protocol = bus.link.protocol
    assert protocol is not None
    transport = protocol._transport
    assert isinstance(transport, LoopbackTransport)
    return transport


async def _known_exchange(bus: sj.Bus[sj.Drive, sj.Broadcast]) -> None:
    drive = bus.drive(1)
    await drive.read_status()
    await drive.set_frequency(12.5)
    with pytest.raises(sj.NakError):
        await bus.drive(2).read_parameter_raw("A999")  # no such parameter: NAK 16
    bus.simulator.faults.corrupt_next(3)
    await bus.drive(3).read_status()  # a corrupted reply, then the retry's good one
    await bus.broadcast.stop()


async def test_a_known_exchange_reads_back_byte_for_byte(tmp_path: Path) -> None:
    path = tmp_path / "known.pcapng"
    trace: list[TraceRecord] = []
    wall_before = time.time()
    async with sj.open_bus(
        "sim://?nodes=1-3&baudrate=19200", capture=path, trace=trace.append
    ) as bus:
        await _known_exchange(bus)
    wall_after = time.time()

    capture = read_pcapng(path.read_bytes())
    (interface,) = capture.interfaces
    assert (interface.linktype, interface.description, interface.speed) == (
        147,
        "sj300 19200 8N1",
        19200,
    )
    assert capture.application.startswith("sj300_async ")
    outbound = [p for p in capture.packets if p.direction is PacketDirection.OUTBOUND]
    inbound = [p for p in capture.packets if p.direction is PacketDirection.INBOUND]
    assert len(outbound) + len(inbound) == len(capture.packets)

    # What the host wrote: the encoders' frames, in order (the retry after the
    # corrupted reply is preceded by the sync request the arbiter sends).
    written = [p.data for p in outbound]
    assert written[0] == requests.read_status(1).frame
    assert written[1] == requests.set_frequency(1, 12.5).frame
    assert written[2] == requests.read_parameter(2, "A999").frame
    assert written[3] == requests.read_status(3).frame
    assert written[-1] == requests.run(0xFF, sj.Direction.STOP).frame
    # ... and exactly what the trace saw written, byte for byte.
    assert written == [r.data for r in trace if r.direction == "tx"]

    # What arrived: the same bytes as the trace's chunks, cut at frame boundaries.
    received = b"".join(r.data for r in trace if r.direction == "rx")
    assert b"".join(p.data for p in inbound) == received
    assert all(p.data.startswith(b"\x02") and p.data.endswith(b"\r") for p in inbound)
    assert inbound[0].data == b"\x02010200010002\r"  # node 1's status, as the simulator sends it
    assert inbound[1].data == b"\x0201\x0607\r"  # the ACK of the set-frequency
    assert inbound[2].data[3:6] == b"\x1516"  # node 2's NAK 16

    # Only the corrupted reply is marked, as a check-code error with its comment.
    marked = [p for p in inbound if p.flags & (FLAG_CHECK_ERROR | FLAG_NOISE)]
    assert len(marked) == 1
    assert marked[0].flags & FLAG_CHECK_ERROR
    assert marked[0].comment == "broken frame: bad BCC"
    assert marked[0].data[1:3] == b"03"
    assert all(p.comment == "" for p in capture.packets if p is not marked[0])

    # Timestamps: in order, in the run's wall-clock window, and spaced as the trace was.
    stamps = [p.timestamp_us for p in capture.packets]
    assert stamps == sorted(stamps)
    assert wall_before * 1e6 - 1000 <= stamps[0]
    assert stamps[-1] <= wall_after * 1e6 + 1000
    tx_times = [r.timestamp for r in trace if r.direction == "tx"]
    for (a, b), (ta, tb) in zip(pairwise(outbound), pairwise(tx_times), strict=True):
        assert abs((b.timestamp_us - a.timestamp_us) - (tb - ta) * 1e6) <= 2


async def test_replies_split_into_fragments_are_captured_as_whole_frames(tmp_path: Path) -> None:
    path = tmp_path / "fragments.pcapng"
    chunks: list[bytes] = []
    to_host = LineFaults(rng=random.Random(7), fragment_max=3)
    async with sj.open_bus(
        "sim://?nodes=1-2",
        capture=path,
        faults=(None, to_host),
        trace=lambda r: chunks.append(r.data) if r.direction == "rx" else None,
    ) as bus:
        for _ in range(5):
            await bus.drive(1).read_monitor()
            await bus.drive(2).read_parameter("F002")
    assert to_host.counts["fragmented"] == 10
    assert len(chunks) > 40  # many chunks per reply ...
    inbound = [
        p.data
        for p in read_pcapng(path.read_bytes()).packets
        if p.direction is PacketDirection.INBOUND
    ]
    assert len(inbound) == 10  # ... but one packet per reply
    assert b"".join(inbound) == b"".join(chunks)
    assert {len(p) for p in inbound} == {110, 15}  # monitor data, ACK + 8 digits


async def test_noise_on_the_line_is_captured_and_marked(tmp_path: Path) -> None:
    path = tmp_path / "noise.pcapng"
    async with sj.open_bus("sim://?nodes=1", capture=path) as bus:
        await bus.drive(1).read_status()
        _loopback(bus).inject(b"\xff\x00zz")
        await bus.drive(1).read_status()
    packets = read_pcapng(path.read_bytes()).packets
    noise = [p for p in packets if p.flags & FLAG_NOISE]
    assert [p.data for p in noise] == [b"\xff\x00zz"]
    assert noise[0].comment == "noise: bytes outside a frame"


async def test_one_capture_file_holds_several_lines(tmp_path: Path) -> None:
    path = tmp_path / "lines.pcapng"
    with CaptureFile(path) as capture:
        async with (
            sj.open_bus("sim://?nodes=1", capture=capture) as sj300_bus,
            sj.open_bus("sim://?nodes=1", protocol="fr700", capture=capture) as fr700_bus,
        ):
            await sj300_bus.drive(1).read_status()
            await fr700_bus.drive(1).read_output_frequency()
        assert not capture.closed  # the caller's file stays open for more lines
    parsed = read_pcapng(path.read_bytes())
    assert [i.linktype for i in parsed.interfaces] == [147, 148]
    assert {p.interface for p in parsed.packets} == {0, 1}


async def test_the_capture_follows_the_trace_hook_being_replaced(tmp_path: Path) -> None:
    """--trace sets the bus's hook after opening: the capture must not be lost."""
    path = tmp_path / "traced.pcapng"
    seen: list[TraceRecord] = []
    async with sj.open_bus("sim://?nodes=1", capture=path) as bus:
        await bus.drive(1).read_status()
        bus.trace = seen.append
        await bus.drive(1).read_status()
        bus.trace = None
        await bus.drive(1).read_status()
    assert len(seen) == 2
    assert len(read_pcapng(path.read_bytes()).packets) == 6


async def test_a_capture_that_cannot_be_written_is_a_typed_error(tmp_path: Path) -> None:
    with pytest.raises(sj.LocalProtocolError, match=r"cannot write capture .*missing"):
        async with sj.open_bus("sim://?nodes=1", capture=tmp_path / "missing" / "x.pcapng"):
            pass


async def test_a_bus_that_outlives_its_capture_file_keeps_working(tmp_path: Path) -> None:
    capture = CaptureFile(tmp_path / "short.pcapng")
    async with sj.open_bus("sim://?nodes=1", capture=capture) as bus:
        await bus.drive(1).read_status()
        capture.close()
        await bus.drive(1).read_status()
    assert len(read_pcapng((tmp_path / "short.pcapng").read_bytes()).packets) == 2
    assert (capture.packets, capture.unwritten) == (2, 2)


async def test_an_unfinished_frame_is_captured_as_noise_when_the_capture_closes(
    tmp_path: Path,
) -> None:
    path = tmp_path / "cut.pcapng"
    received: list[bytes] = []
    async with sj.open_bus(
        "sim://?nodes=1",
        capture=path,
        trace=lambda r: received.append(r.data) if r.direction == "rx" else None,
    ) as bus:
        await bus.drive(1).read_status()
        _loopback(bus).inject(b"\x020102")  # the start of a frame, and then nothing
        await wait_for(lambda: received[-1] == b"\x020102", "the partial frame to arrive")
    packets = read_pcapng(path.read_bytes()).packets
    assert packets[-1].data == b"\x020102"
    assert packets[-1].flags & FLAG_NOISE
    assert packets[-1].comment == "noise: frame cut short"


async def test_a_frame_cut_short_by_the_next_one_is_noise_and_the_next_one_whole(
    tmp_path: Path,
) -> None:
    path = tmp_path / "restart.pcapng"
    async with sj.open_bus("sim://?nodes=1", capture=path) as bus:
        _loopback(bus).inject(b"\x020102")
        await asyncio.sleep(0)  # delivered on the next loop turn, before the request
        await bus.drive(1).read_status()
    packets = read_pcapng(path.read_bytes()).packets
    assert [p.data for p in packets[-2:]] == [b"\x020102", b"\x02010200010002\r"]
    assert packets[-2].comment == "noise: frame cut short"
    assert not packets[-1].flags & (FLAG_NOISE | FLAG_CHECK_ERROR)
