"""The library's protocols read sockets into one reused buffer (transports/_buffered.py).

Over every transport, a protocol built on :class:`BufferedReads` gets every
byte, in order, as ``bytes`` it may keep: each chunk is a copy, so a later
read into the same buffer cannot change one handed over before. Over a
socket, asyncio's transport takes the buffered read path (it asks for the
buffer) and no read takes more than the buffer holds.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from functools import partial

import pytest
from waiting import wait_for

from sj300_async import open_bus
from sj300_async.bus._protocol import LineProtocol
from sj300_async.bus._trace import TraceRecord
from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.transports._buffered import READ_BUFFER_BYTES, BufferedReads
from sj300_async.wire._line import INSTANT_LINE

from .rawline import KINDS, FdFar, RawLine, Recorder, open_raw_line

#: Kinds whose transport is asyncio's own socket transport, reading into our buffer.
_SOCKET_KINDS = ("tcp", "ser2net")
#: Bigger than the buffer, so that it takes several reads into it.
_PAYLOAD_BYTES = 3 * READ_BUFFER_BYTES + 123


def _payload(size: int) -> bytes:
    """*size* bytes that differ from any shift of themselves: a lost, repeated or
    overwritten byte shows."""
    block = bytes((i * 7 + i // 256) % 256 for i in range(4093))  # prime: no period in 16 KiB
    return (block * (size // len(block) + 1))[:size]


class _ChunkRecorder(BufferedReads, Recorder):
    """Records each chunk as handed over, and how often the transport asked for the buffer."""

    def __init__(self) -> None:
        BufferedReads.__init__(self)
        Recorder.__init__(self)
        self.chunks: list[bytes] = []
        self.buffers_asked = 0

    def get_buffer(self, sizehint: int) -> memoryview:
        self.buffers_asked += 1
        return super().get_buffer(sizehint)

    def data_received(self, data: bytes) -> None:
        self.chunks.append(data)
        super().data_received(data)


def _has_received(recorder: Recorder, count: int) -> bool:
    return len(recorder.received) >= count


async def _send(raw: RawLine, payload: bytes, recorder: Recorder) -> None:
    """Send *payload* from the far end and wait until all of it arrived.

    A terminal's far side is written without blocking and its kernel buffer
    holds a few KiB: there it goes a piece at a time, each piece once the
    one before has arrived.
    """
    piece = len(payload) if not isinstance(raw.far, FdFar) else 2048
    for start in range(0, len(payload), piece):
        end = min(start + piece, len(payload))
        raw.far.send(payload[start:end])
        await wait_for(partial(_has_received, recorder, end), f"{end} of {len(payload)} bytes")


@pytest.fixture(params=KINDS)
async def raw(request: pytest.FixtureRequest) -> AsyncIterator[RawLine]:
    async with open_raw_line(request.param) as line:
        yield line


async def test_every_byte_arrives_in_order_as_chunks_that_stay_as_they_were(raw: RawLine) -> None:
    recorder = _ChunkRecorder()
    transport, _ = await raw.open(recorder)
    try:
        payload = _payload(_PAYLOAD_BYTES)
        await _send(raw, payload, recorder)
        assert all(type(chunk) is bytes for chunk in recorder.chunks)
        # Had a chunk been a view of the reused buffer, a later read would have changed it.
        assert b"".join(recorder.chunks) == payload
        assert bytes(recorder.received) == payload
        if raw.kind in _SOCKET_KINDS:
            assert recorder.buffers_asked >= len(recorder.chunks) >= 4  # 3 buffers and a bit
            assert max(len(chunk) for chunk in recorder.chunks) <= READ_BUFFER_BYTES
        else:  # these transports call data_received with chunks of their own
            assert recorder.buffers_asked == 0
    finally:
        transport.close()
        await asyncio.wait_for(recorder.lost.wait(), 5)


async def test_the_line_adapter_reads_a_tcp_bridge_through_its_own_buffer() -> None:
    sim = SimulatedBus(nodes=[1])
    received: list[bytes] = []

    def trace(record: TraceRecord) -> None:
        if record.direction == "rx":
            received.append(record.data)

    async with (
        await serve_tcp(sim, pacing=INSTANT_LINE) as server,
        open_bus(f"tcp://127.0.0.1:{server.port}", line=INSTANT_LINE, trace=trace) as bus,
    ):
        protocol = bus.link.protocol
        assert isinstance(protocol, LineProtocol)
        buffer = protocol.get_buffer(-1)
        assert not any(buffer)  # nothing read yet
        for _ in range(3):
            await bus.drive(1).read_status()
        # Each reply was read into the adapter's buffer, and the parser decoded a copy.
        assert received
        last = received[-1]
        assert bytes(buffer[: len(last)]) == last
        assert bus.stats.transactions.replies == 3
