"""The in-memory server: a bus on the event loop's clock behind a plain send callable."""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

import pytest

from sj300_async.simulator import LinePacing, PacedLine, SimulatorEndpoint
from sj300_async.simulator.sj300 import SimulatedBus

from .simwire import ack, data_reply, request


class Host:
    """Collects what the endpoint sends, with the loop time of each delivery."""

    def __init__(self) -> None:
        self.chunks: list[tuple[float, bytes]] = []
        self._arrived = asyncio.Event()

    def send(self, data: bytes) -> None:
        self.chunks.append((asyncio.get_running_loop().time(), data))
        self._arrived.set()

    @property
    def data(self) -> bytes:
        return b"".join(chunk for _, chunk in self.chunks)

    async def wait_for(self, nbytes: int) -> bytes:
        async with asyncio.timeout(2.0):
            while len(self.data) < nbytes:
                self._arrived.clear()
                await self._arrived.wait()
        return self.data


async def test_works_with_a_plain_callable() -> None:
    host = Host()
    ep = SimulatorEndpoint(SimulatedBus(nodes=[1]), send=host.send)
    ep.data_received(request(b"01", b"04"))
    expected = data_reply(b"01", b"02000100")
    assert await host.wait_for(len(expected)) == expected
    ep.close()


async def test_never_sends_from_inside_data_received() -> None:
    host = Host()
    ep = SimulatorEndpoint(SimulatedBus(nodes=[1], processing_s=0.0), send=host.send)
    ep.data_received(request(b"01", b"0B"))
    assert host.chunks == []  # a host writing from its own callback is not re-entered
    assert await host.wait_for(7) == ack(b"01")
    ep.close()


async def test_a_server_may_answer_from_inside_data_received() -> None:
    host = Host()
    bus = SimulatedBus(nodes=[1], processing_s=0.0)
    ep = SimulatorEndpoint(bus, send=host.send, defer=False)
    ep.data_received(request(b"01", b"0B"))
    assert [chunk for _, chunk in host.chunks] == [ack(b"01")]  # sent at once
    # A reply with a delay still waits for it.
    bus.drives[1].processing_s = 0.01
    ep.data_received(request(b"01", b"0B"))
    assert len(host.chunks) == 1
    assert await host.wait_for(2 * 7) == ack(b"01") * 2
    ep.close()


async def test_reply_waits_for_c078() -> None:
    host = Host()
    ep = SimulatorEndpoint(SimulatedBus(nodes=[1], wait_ms=50), send=host.send)
    loop = asyncio.get_running_loop()
    sent_at = loop.time()
    ep.data_received(request(b"01", b"0B"))
    await host.wait_for(7)
    assert host.chunks[0][0] - sent_at >= 0.050
    ep.close()


async def test_replies_keep_their_order() -> None:
    host = Host()
    ep = SimulatorEndpoint(SimulatedBus(nodes=[1, 2], processing_s=0.0), send=host.send)
    ep.data_received(b"".join(request(b"%02d" % n, b"0B") for n in (1, 2, 1, 2, 1)))
    expected = b"".join(ack(b"%02d" % n) for n in (1, 2, 1, 2, 1))
    assert await host.wait_for(len(expected)) == expected
    ep.close()


async def test_a_delayed_reply_arrives_after_a_later_one() -> None:
    host = Host()
    bus = SimulatedBus(nodes=[1, 2], processing_s=0.0)
    ep = SimulatorEndpoint(bus, send=host.send)
    bus.faults.delay_next(1, 0.05)
    ep.data_received(request(b"01", b"0B"))
    ep.data_received(request(b"02", b"0B"))
    assert await host.wait_for(14) == ack(b"02") + ack(b"01")
    ep.close()


async def test_close_cancels_pending_replies_and_is_idempotent() -> None:
    host = Host()
    bus = SimulatedBus(nodes=[1])
    bus.faults.late(1, 0.05)
    ep = SimulatorEndpoint(bus, send=host.send)
    ep.data_received(request(b"01", b"0B"))
    assert ep.pending == 1
    ep.close()
    assert ep.pending == 0
    ep.close()
    ep.data_received(request(b"01", b"0B"))  # discarded, no error
    await asyncio.sleep(0.1)
    assert host.chunks == []
    assert ep.closed


async def test_can_be_built_outside_the_loop_and_used_inside() -> None:
    host = Host()
    ep = await asyncio.to_thread(SimulatorEndpoint, SimulatedBus(nodes=[1]), host.send)
    ep.data_received(request(b"01", b"0B"))
    assert await host.wait_for(7) == ack(b"01")
    ep.close()


async def test_pacing_holds_every_byte_for_its_wire_time() -> None:
    pacing = LinePacing(1200, 8, "N", 1)  # 8.33 ms a character: measurable, still short
    char = pacing.char_time_s
    host = Host()
    bus = SimulatedBus(nodes=[1])
    ep = SimulatorEndpoint(bus, send=host.send, pacing=pacing)
    loop = asyncio.get_running_loop()
    req = request(b"01", b"04")  # 7 characters
    expected = data_reply(b"01", b"02000100")  # 13 characters
    written_at = loop.time()
    ep.data_received(req)
    assert await host.wait_for(len(expected)) == expected

    first_byte_start = written_at + len(req) * char + bus.drives[1].reply_delay_s
    delivered = 0
    for at, chunk in host.chunks:
        delivered += len(chunk)
        # no byte before its last bit has crossed the line
        assert at >= first_byte_start + delivered * char - 0.001, (delivered, at - written_at)
    assert len(host.chunks) > 1  # delivered a few characters at a time
    # and not much later than the physical limit
    assert host.chunks[-1][0] - written_at < (len(req) + len(expected)) * char + 0.05
    ep.close()


@dataclass
class _Paced:
    """A status request just handed to a drive behind a 1200-baud line, one
    character per delivery (``group_s=0``)."""

    host: Host
    bus: SimulatedBus
    endpoint: SimulatorEndpoint
    char: float
    written_at: float
    req: bytes
    expected: bytes


def _status_request_on_a_paced_line() -> _Paced:
    pacing = LinePacing(1200, 8, "N", 1)  # 8.33 ms a character
    host = Host()
    bus = SimulatedBus(nodes=[1])
    ep = SimulatorEndpoint(bus, send=host.send, line=PacedLine(pacing, group_s=0.0))
    written_at = asyncio.get_running_loop().time()
    req = request(b"01", b"04")
    ep.data_received(req)
    expected = data_reply(b"01", b"02000100")
    return _Paced(host, bus, ep, pacing.char_time_s, written_at, req, expected)


async def test_single_characters_each_at_its_stop_bit() -> None:
    paced = _status_request_on_a_paced_line()
    host, bus, ep, char = paced.host, paced.bus, paced.endpoint, paced.char
    written_at, req, expected = paced.written_at, paced.req, paced.expected
    assert await host.wait_for(len(expected)) == expected
    first_byte_start = written_at + len(req) * char + bus.drives[1].reply_delay_s
    delivered = 0
    for at, chunk in host.chunks:
        delivered += len(chunk)
        assert at >= first_byte_start + delivered * char - 1e-6  # never early
    assert len(host.chunks) > len(expected) // 2  # (a loaded loop may merge a few)
    ep.close()


async def test_characters_due_together_go_out_in_one_send() -> None:
    paced = _status_request_on_a_paced_line()
    host, bus, ep, char = paced.host, paced.bus, paced.endpoint, paced.char
    written_at, req, expected = paced.written_at, paced.req, paced.expected
    # The loop wakes late: blocked (on purpose, not waiting for anything) until
    # the whole reply has crossed the line. Every character is then due at once.
    # A blocking sleep is the subject here, not a wait for a state: only a loop
    # that really runs late makes its timers find later deliveries due.
    reply_end = written_at + (len(req) + len(expected)) * char + bus.drives[1].reply_delay_s
    time.sleep(max(0.0, reply_end - asyncio.get_running_loop().time()) + 0.01)
    assert await host.wait_for(len(expected)) == expected
    assert len(host.chunks) == 1
    assert host.chunks[0][0] >= reply_end
    ep.close()


async def test_endpoints_sharing_a_paced_line_queue_behind_each_other() -> None:
    pacing = LinePacing(2400, 8, "N", 1)  # 4.17 ms a character
    line = PacedLine(pacing)
    bus = SimulatedBus(nodes=[1, 2], processing_s=0.0)
    a, b = Host(), Host()
    ep_a = SimulatorEndpoint(bus, send=a.send, line=line)
    ep_b = SimulatorEndpoint(bus, send=b.send, line=line)
    loop = asyncio.get_running_loop()
    start = loop.time()
    ep_a.data_received(request(b"01", b"0B"))
    ep_b.data_received(request(b"02", b"0B"))
    await a.wait_for(7)
    await b.wait_for(7)
    # four frames of 7 characters crossed one line, one after the other
    assert b.chunks[-1][0] - start >= 28 * pacing.char_time_s - 0.001
    ep_a.close()
    ep_b.close()


@pytest.mark.parametrize("chunk", [1, 3])
async def test_paced_request_written_in_pieces(chunk: int) -> None:
    host = Host()
    ep = SimulatorEndpoint(SimulatedBus(nodes=[1]), send=host.send, pacing=LinePacing(115200))
    raw = request(b"01", b"0B")
    for i in range(0, len(raw), chunk):
        ep.data_received(raw[i : i + chunk])
    assert await host.wait_for(7) == ack(b"01")
    ep.close()
