"""One test per arbiter rule, over the real loopback transport with a scripted drive."""

from __future__ import annotations

import asyncio

import pytest
from waiting import wait_for

import sj300_async as sj
from sj300_async import sj300 as sj3
from sj300_async.transports import LoopbackTransport

from .scripted import Frames, MakeRig, ack, ack_value, answer_all, nak, reply, status


async def test_answer_is_decoded(scripted: MakeRig) -> None:
    async with scripted() as rig:
        st = await rig.bus.drive(3).read_status()
        assert st == sj.InverterStatus(
            sj.StatusA.RUNNING, sj.StatusB.RUNNING, sj.StatusC.CONSTANT_SPEED
        )
        assert await rig.bus.drive(3).read_parameter_raw("A004") == 1003
        # 0x30^0x33^0x30^0x34 = 0x07; "0306A004" folds to 0x70
        assert rig.written() == [b"\x02030407\r", b"\x020306A00470\r"]
        assert rig.bus.stats.transactions.replies == 2


async def test_frames_from_other_nodes_are_discarded_and_the_wait_goes_on(
    scripted: MakeRig,
) -> None:
    def respond(req: sj3.Request) -> Frames:
        # Node 7 chimes in first (a late reply from an earlier era), then the real answer.
        return [(0.0, ack_value(7, 99999)), (0.005, ack_value(req.node, 1234))]

    async with scripted(respond) as rig:
        assert await rig.bus.drive(2).read_parameter_raw("F002") == 1234
        assert rig.bus.stats.stray_frames == 1
        assert rig.bus.drive(2).stats.discarded_frames == 1


async def test_same_node_wrong_shape_is_not_an_answer(scripted: MakeRig) -> None:
    def respond(req: sj3.Request) -> Frames:
        # A status reply (another command's shape) from the same node, then the ACK+value.
        return [(0.0, status(req.node)), (0.005, ack_value(req.node, 42))]

    async with scripted(respond) as rig:
        assert await rig.bus.drive(5).read_parameter_raw("C078") == 42
        assert rig.bus.stats.stray_frames == 1


async def test_garbage_and_corrupt_frames_are_counted_not_fatal(scripted: MakeRig) -> None:
    def respond(req: sj3.Request) -> Frames:
        corrupt = bytearray(ack_value(req.node, 1))
        corrupt[-3] ^= 0x01  # break the BCC
        return [(0.0, b"\x00\xffnoise" + bytes(corrupt)), (0.005, ack_value(req.node, 77))]

    async with scripted(respond) as rig:
        assert await rig.bus.drive(1).read_parameter_raw("F002") == 77
        assert rig.bus.stats.discarded_bytes == 7
        assert rig.bus.stats.bad_frames == 1


async def test_only_corrupt_answer_fails_typed_after_deadline(scripted: MakeRig) -> None:
    def respond(req: sj3.Request) -> Frames:
        frame = bytearray(ack_value(req.node, 1))
        frame[5] = ord("X")  # a letter where digits belong...
        body = bytes(frame[1:-3])
        import functools
        import operator

        bcc = b"%02X" % functools.reduce(operator.xor, body, 0)  # ...with a matching BCC
        return [(0.0, b"\x02" + body + bcc + b"\r")]

    async with scripted(respond, retries=0) as rig:
        with pytest.raises(sj.RemoteProtocolError, match="corrupted"):
            await rig.bus.drive(1).read_parameter_raw("F002")
        assert rig.bus.stats.transactions.protocol_errors == 1


async def test_late_reply_after_timeout_is_never_the_next_answer(scripted: MakeRig) -> None:
    calls = 0

    def respond(req: sj3.Request) -> Frames:
        nonlocal calls
        calls += 1
        if calls == 1:
            return [(0.08, ack_value(req.node, 111))]  # after the 50 ms time-out
        if req.command is sj3.Command.READ_PARAMETER:
            return [(0.0, ack_value(req.node, 222))]
        return answer_all(req)  # the sync request

    async with scripted(respond, retries=0) as rig:
        drive = rig.bus.drive(4)
        with pytest.raises(sj.ReplyTimeoutError):
            await drive.read_parameter_raw("F002")
        # Same node, same command shape: only the drain can tell the two apart.
        assert await drive.read_parameter_raw("F003") == 222
        assert rig.bus.stats.unsolicited_frames == 1
        assert rig.bus.stats.drains == 1
        assert rig.bus.stats.resyncs == 1  # node 4 missed an answer: a sync went first
        tx_times = [r.timestamp for r in rig.trace if r.direction == "tx"]
        rx_late = next(r.timestamp for r in rig.trace if r.direction == "rx")
        assert tx_times[1] > rx_late  # the second request went out after the late reply


async def test_timeout_is_a_timeouterror_and_retried_then_counted(scripted: MakeRig) -> None:
    async with scripted(lambda req: [], retries=2) as rig:
        with pytest.raises(TimeoutError):
            await rig.bus.drive(9).read_status()
        stats = rig.bus.drive(9).stats
        assert (stats.requests, stats.timeouts, stats.retries) == (3, 3, 2)


@pytest.mark.parametrize(("code", "attempts"), [(2, 3), (8, 3), (11, 1), (13, 1), (16, 1)])
async def test_nak_retry_policy(scripted: MakeRig, code: int, attempts: int) -> None:
    async with scripted(lambda req: [(0.0, nak(req.node, code))], retries=2) as rig:
        with pytest.raises(sj.NakError) as info:
            await rig.bus.drive(6).write_parameter_raw("A004", 500)
        assert (info.value.node, info.value.code) == (6, code)
        assert len(rig.peer.requests) == attempts
        assert rig.bus.drive(6).stats.naks[code] == attempts


async def test_fifo_fairness_under_a_failing_node(scripted: MakeRig) -> None:
    def respond(req: sj3.Request) -> Frames:
        return [] if req.node == 13 else answer_all(req)

    async with scripted(respond, retries=3) as rig:
        order: list[str] = []

        async def dead() -> None:
            with pytest.raises(sj.ReplyTimeoutError):
                await rig.bus.drive(13).read_status()
            order.append("dead-failed")

        async def healthy() -> None:
            for _ in range(3):
                await rig.bus.drive(1).read_status()
                order.append("ok")

        await asyncio.gather(dead(), healthy())
        # The healthy drive was served between the dead drive's retries, not after all of them.
        assert order.index("dead-failed") == len(order) - 1
        nodes = [r.node for r in rig.peer.requests]
        first_dead, last_dead = nodes.index(13), len(nodes) - 1 - nodes[::-1].index(13)
        assert 1 in nodes[first_dead:last_dead]


async def test_stop_jumps_the_queue(scripted: MakeRig) -> None:
    def respond(req: sj3.Request) -> Frames:
        delay = 0.03 if req.command is sj3.Command.READ_MONITOR else 0.0
        return [(delay, frame) for _, frame in answer_all(req)]

    async with scripted(respond) as rig:
        bus = rig.bus
        in_flight = asyncio.create_task(bus.drive(1).read_monitor())
        await asyncio.sleep(0.005)  # the monitor read is on the line
        polls = [asyncio.create_task(bus.drive(n).read_status()) for n in range(2, 12)]
        await asyncio.sleep(0)
        stop = asyncio.create_task(bus.drive(20).stop())
        await asyncio.gather(in_flight, stop, *polls)
        commands = [(r.node, r.command) for r in rig.peer.requests]
        assert commands[0] == (1, sj3.Command.READ_MONITOR)
        assert commands[1] == (20, sj3.Command.RUN)  # before all ten queued polls
        assert rig.peer.requests[1].data == b"0"


async def test_broadcast_gets_no_reply_and_the_line_rests(scripted: MakeRig) -> None:
    timing = sj.BusTiming(margin_s=0.05, broadcast_processing_s=0.02)
    async with scripted(timing=timing) as rig:
        await rig.bus.broadcast.stop()
        await rig.bus.drive(1).read_status()
        tx = [r for r in rig.trace if r.direction == "tx"]
        # "FF000": 0x46^0x46^0x30^0x30^0x30 = 0x30
        assert tx[0].data == b"\x02FF00030\r"
        assert tx[1].timestamp - tx[0].timestamp >= 0.02
        assert rig.bus.broadcast.stats.broadcasts == 1


async def test_a_guard_rests_the_line_after_each_reply(scripted: MakeRig) -> None:
    # 1200 baud 8N1: a character is 8.33 ms; a 3-character guard is 25 ms,
    # counted from the reply's arrival (the trace's rx stamp).
    line = sj.LineSettings(1200)
    timing = sj.BusTiming(margin_s=0.05, guard_chars=3)
    async with scripted(line=line, timing=timing) as rig:
        for _ in range(3):
            await rig.bus.drive(1).read_status()
        tx = [r.timestamp for r in rig.trace if r.direction == "tx"]
        rx = [r.timestamp for r in rig.trace if r.direction == "rx"]
        for reply_at, next_write in zip(rx, tx[1:], strict=False):
            assert next_write - reply_at >= 3 * line.char_time_s


async def test_no_rest_after_a_reply_by_default(scripted: MakeRig) -> None:
    # The default guard is 0 characters (see _timing.py): at 1200 baud a
    # 1-character rest alone would be 8 ms between reply and next request.
    assert sj.BusTiming().guard_chars == 0
    async with scripted(line=sj.LineSettings(1200)) as rig:
        for _ in range(5):
            await rig.bus.drive(1).read_status()
        tx = [r.timestamp for r in rig.trace if r.direction == "tx"]
        rx = [r.timestamp for r in rig.trace if r.direction == "rx"]
        gaps = [nxt - at for at, nxt in zip(rx, tx[1:], strict=False)]
        assert len(gaps) == 4
        assert min(gaps) < sj.LineSettings(1200).char_time_s


async def test_broadcast_refuses_unicast_only_commands(scripted: MakeRig) -> None:
    async with scripted() as rig:
        # The broadcast object offers no reads, and the bus will not make a
        # drive at the broadcast address to ask one through.
        assert not hasattr(rig.bus.broadcast, "read_status")
        with pytest.raises(sj.LocalProtocolError, match=r"node must be 1\.\.32, got 255"):
            await rig.bus.drive(sj3.BROADCAST).read_status()
        # Refused before anything reached the wire.
        assert rig.written() == []
        assert rig.peer.received == b""
        assert rig.peer.requests == []


async def test_closed_bus_refuses(scripted: MakeRig) -> None:
    async with scripted() as rig:
        pass
    with pytest.raises(sj.BusClosedError):
        await rig.bus.drive(1).read_status()


async def test_request_while_link_down_fails_promptly(scripted: MakeRig) -> None:
    policy = sj.ReconnectPolicy(initial_s=5.0, max_s=5.0)
    async with scripted(reconnect=policy) as rig:
        rig.bus.link.drop()
        await asyncio.sleep(0.01)
        loop = asyncio.get_running_loop()
        start = loop.time()
        with pytest.raises(sj.TransportError, match="not connected") as info:
            await rig.bus.drive(1).read_status()
        assert isinstance(info.value, ConnectionError)
        assert loop.time() - start < 0.01


async def test_link_drop_mid_transaction_fails_waiter_and_reconnects(scripted: MakeRig) -> None:
    policy = sj.ReconnectPolicy(initial_s=0.01, max_s=0.02)
    async with scripted(lambda req: [], reconnect=policy, retries=0) as rig:
        task = asyncio.create_task(rig.bus.drive(1).read_status())
        await asyncio.sleep(0.005)
        rig.bus.link.drop()
        with pytest.raises(sj.TransportError):
            await task
        await asyncio.wait_for(rig.bus.link.wait_connected(), 1)
        for _ in range(100):
            if rig.bus.connected:
                break
            await asyncio.sleep(0.005)
        assert rig.bus.stats.disconnects == 1
        assert rig.bus.stats.connects == 2


async def test_read_only_refuses_every_mutating_command(scripted: MakeRig) -> None:
    async with scripted(read_only=True) as rig:
        d = rig.bus.drive(1)
        for call in (
            d.run_forward(),
            d.run_reverse(),
            d.stop(),
            d.set_frequency(10),
            d.set_terminals(sj.InputTerminal.FW),
            d.write_parameter("F002", 1.0),
            d.write_parameter_raw("A004", 500),
            d.initialize(),
            d.store(),
            d.recalculate_constants(),
            rig.bus.broadcast.stop(),
        ):
            with pytest.raises(sj.ReadOnlyError):
                await call
        assert await d.read_status() == sj.InverterStatus(
            sj.StatusA.RUNNING, sj.StatusB.RUNNING, sj.StatusC.CONSTANT_SPEED
        )
        assert [r.command for r in rig.peer.requests] == [sj3.Command.READ_STATUS]


async def test_echo_is_stripped(scripted: MakeRig) -> None:
    def respond(req: sj3.Request) -> Frames:
        return [(0.0, req.frame + ack(req.node))]  # the adapter hands our request back first

    async with scripted(respond, strip_echo=True) as rig:
        await rig.bus.drive(1).run_forward()
        assert rig.bus.stats.echo_bytes == len(rig.peer.requests[0].frame)
        assert rig.bus.stats.bad_frames == 0


async def test_without_echo_stripping_the_echo_is_a_counted_bad_frame(scripted: MakeRig) -> None:
    def respond(req: sj3.Request) -> Frames:
        return [(0.0, req.frame + ack(req.node))]

    async with scripted(respond) as rig:
        await rig.bus.drive(1).run_forward()
        assert rig.bus.stats.bad_frames == 1


async def test_unsolicited_frames_between_transactions_are_counted(scripted: MakeRig) -> None:
    async with scripted() as rig:
        protocol = rig.bus.link.protocol
        assert protocol is not None
        transport = protocol._transport
        assert isinstance(transport, LoopbackTransport)
        transport.inject(reply(b"05\x06"))
        await asyncio.sleep(0.001)
        assert rig.bus.stats.unsolicited_frames == 1
        assert (await rig.bus.drive(1).read_parameter_raw("F002")) == 1001


async def test_a_request_that_waited_across_a_reconnect_is_not_sent_on_the_new_one(
    scripted: MakeRig,
) -> None:
    """A transaction never moves to a new connection: the new one's first request is one
    made for it (the gateway's pending stop relies on it, issue 26)."""

    def respond(req: sj3.Request) -> Frames:
        return [] if req.node == 1 else answer_all(req)  # node 1 is silent

    policy = sj.ReconnectPolicy(initial_s=0.001, max_s=0.001)
    timing = sj.BusTiming(margin_s=0.5)  # the drain below waits this out: time to reconnect
    async with scripted(respond, reconnect=policy, retries=0, timing=timing) as rig:
        with pytest.raises(sj.ReplyTimeoutError):
            await rig.bus.drive(1).read_status()  # the next request drains the line first
        waiting = asyncio.create_task(rig.bus.drive(2).read_status())
        await wait_for(lambda: rig.bus.stats.drains == 1, "the request draining the line")
        old = rig.peer
        rig.bus.link.drop()
        await wait_for(lambda: rig.bus.connected and rig.peer is not old, "reconnected")
        with pytest.raises(sj.TransportError, match="reconnected while the request waited"):
            await waiting
        assert rig.peer.requests == []  # nothing of the old connection's went on the new one
        await rig.bus.drive(2).read_status()
        assert [r.node for r in rig.peer.requests] == [2]


async def test_a_sync_that_rested_across_a_reconnect_is_not_sent_on_the_new_one(
    scripted: MakeRig,
) -> None:
    """The same rule inside the sync a node that missed answers gets first: its rest
    (the guard interval after a reply) spans the drop and the reconnect."""
    silent = {2}

    def respond(req: sj3.Request) -> Frames:
        return [] if req.node in silent else answer_all(req)

    policy = sj.ReconnectPolicy(initial_s=0.001, max_s=0.001)
    line = sj.LineSettings(9600)
    # A long guard (300 characters, 0.3 s at 9600 baud): time to reconnect in it.
    timing = sj.BusTiming(margin_s=0.2, guard_chars=300)
    async with scripted(respond, reconnect=policy, retries=0, timing=timing, line=line) as rig:
        with pytest.raises(sj.ReplyTimeoutError):
            await rig.bus.drive(2).read_status()  # node 2 must be synced before its next
        silent.clear()
        await rig.bus.drive(3).read_status()  # drains; its answer starts the guard rest
        waiting = asyncio.create_task(rig.bus.drive(2).read_status())  # rests in its sync
        await wait_for(lambda: rig.bus._arbiter.queue.busy, "the sync resting on the line")
        old = rig.peer
        rig.bus.link.drop()
        await wait_for(lambda: rig.bus.connected and rig.peer is not old, "reconnected")
        with pytest.raises(sj.TransportError, match="reconnected while the request waited"):
            await waiting
        assert rig.peer.requests == []
