"""Time-outs, deadlines, closing and draining (issue 14, items 5 and 6), and the
dialect methods behind the plausibility floor and the resync (items 1 and 2).

``timeout`` is the time-out of one attempt; a call makes up to ``retries + 1``
attempts with a drain after each failed one, and ``deadline`` bounds the
whole call. The error says all of it. Figures are printed (``pytest -s``).
"""

from __future__ import annotations

import asyncio
import logging
import pickle
import re

import pytest
from toyproto import TOY_DIALECT, ToyRequest
from waiting import wait_for

import sj300_async as sj
from sj300_async import fr700 as fr
from sj300_async import sj300 as sj3
from sj300_async.simulator import serve_tcp
from sj300_async.simulator._pacing import MIN_REPLY_CHARS, PlausibleLine
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.wire._line import INSTANT_LINE

from .scripted import Frames, MakeRig, answer_all, status


def silent(request: sj3.Request) -> Frames:
    return []


# -- the time-out error -------------------------------------------------------------------


async def test_a_silent_drive_fails_with_attempts_and_total_time(scripted: MakeRig) -> None:
    timing = sj.BusTiming(fixed_timeout_s=0.05)
    async with scripted(silent, timing=timing, retries=2) as rig:
        loop = asyncio.get_running_loop()
        started = loop.time()
        with pytest.raises(sj.ReplyTimeoutError) as info:
            await rig.bus.drive(4).read_status()
        took = loop.time() - started
    error = info.value
    print(f"\n{error}\n(wall time {took:.3f} s)")
    # 3 attempts of 50 ms, and a drain of 50 ms before each retry: 250 ms at least.
    assert re.fullmatch(
        r"node 04 did not answer command 04: 3 attempts of 50 ms each, 0\.\d\d s in all"
        r" \(2 of them sync requests after a missed answer\)",
        str(error),
    )
    assert error.attempts == 3
    assert error.timeout_s == 0.05
    assert error.elapsed_s is not None
    assert 0.25 <= error.elapsed_s <= took
    assert f"{error.elapsed_s:.2f} s in all" in str(error)
    copy = pickle.loads(pickle.dumps(error))
    assert (type(copy), str(copy), copy.attempts, copy.elapsed_s, copy.timeout_s) == (
        sj.ReplyTimeoutError,
        str(error),
        3,
        error.elapsed_s,
        0.05,
    )


async def test_attempts_with_different_time_outs_give_the_range(scripted: MakeRig) -> None:
    # Computed time-outs: the status request's and its syncs' (09, then 03) differ.
    async with scripted(silent, line=sj.LineSettings(19200), retries=2) as rig:
        with pytest.raises(sj.ReplyTimeoutError) as info:
            await rig.bus.drive(7).read_status()
    print(f"\n{info.value}")
    assert re.match(
        r"node 07 did not answer command 04: 3 attempts of \d+\.\.\d+ ms, ", str(info.value)
    )


async def test_one_attempt_says_so(scripted: MakeRig) -> None:
    timing = sj.BusTiming(fixed_timeout_s=0.03)
    async with scripted(silent, timing=timing, retries=0) as rig:
        with pytest.raises(sj.ReplyTimeoutError, match=r"1 attempt of 30 ms, 0\.0\d s in all$"):
            await rig.bus.drive(1).read_status()


def test_reply_timeout_error_defaults_and_pickling() -> None:
    plain = sj.ReplyTimeoutError("x")
    assert (plain.attempts, plain.elapsed_s, plain.timeout_s) == (1, None, None)
    assert isinstance(plain, TimeoutError)
    assert str(plain) == "x"
    assert plain.errno is None
    copy = pickle.loads(pickle.dumps(plain))
    assert (str(copy), copy.attempts, copy.elapsed_s) == ("x", 1, None)


# -- the call deadline ------------------------------------------------------------------


async def test_the_deadline_stops_the_retries(scripted: MakeRig) -> None:
    # 50 ms attempts, 5 retries allowed, 120 ms for the call: the second attempt
    # starts at about 100 ms (after the drain), the third would start after 120 ms.
    timing = sj.BusTiming(fixed_timeout_s=0.05, call_deadline_s=0.12)
    async with scripted(silent, timing=timing, retries=5) as rig:
        with pytest.raises(sj.ReplyTimeoutError) as info:
            await rig.bus.drive(2).read_status()
        assert len(rig.peer.requests) == 2
    error = info.value
    print(f"\n{error}")
    assert error.attempts == 2
    assert error.elapsed_s is not None
    assert 0.12 <= error.elapsed_s < 0.12 + 0.05 + 0.05
    assert str(error).endswith("; call deadline 0.12 s")


async def test_open_bus_takes_a_deadline() -> None:
    async with sj.open_bus("sim://?nodes=1", timeout=0.03, deadline=0.05, retries=5) as bus:
        assert bus.timing.call_deadline_s == 0.05
        assert bus.timing.fixed_timeout_s == 0.03
        with pytest.raises(sj.ReplyTimeoutError) as info:
            await bus.drive(2).read_status()  # nobody at node 2
    assert info.value.attempts == 2


async def test_a_call_that_waits_past_its_deadline_is_never_sent(scripted: MakeRig) -> None:
    # The first call holds the line for its whole 200 ms attempt; the second, queued
    # behind it, has 100 ms: it fails without a write.
    timing = sj.BusTiming(fixed_timeout_s=0.2, call_deadline_s=0.1)
    async with scripted(silent, timing=timing, retries=2) as rig:
        first = asyncio.create_task(rig.bus.drive(1).read_status())
        await asyncio.sleep(0.01)
        with pytest.raises(sj.ReplyTimeoutError) as info:
            await rig.bus.drive(2).read_status()
        with pytest.raises(sj.ReplyTimeoutError):
            await first
        assert [r.node for r in rig.peer.requests] == [1]
    print(f"\n{info.value}")
    assert info.value.attempts == 0
    assert re.fullmatch(
        r"node 02: command 04 not sent: the line was busy for the whole call deadline"
        r" of 0\.1 s \(0\.\d\d s\)",
        str(info.value),
    )


def test_bus_timing_refuses_bad_deadlines_and_speeds() -> None:
    for deadline in (0, -1, float("inf"), float("nan"), "1"):
        with pytest.raises(sj.LocalProtocolError, match="deadline"):
            sj.BusTiming(call_deadline_s=deadline)  # type: ignore[arg-type]
    for baud in (0, -1, True, 1.5, None):
        with pytest.raises(sj.LocalProtocolError, match="plausible_baudrate"):
            sj.BusTiming(plausible_baudrate=baud)  # type: ignore[arg-type]


# -- closing and draining -------------------------------------------------------------


async def test_a_read_in_flight_when_the_bus_closes_gets_bus_closed(scripted: MakeRig) -> None:
    async with scripted(silent, timing=sj.BusTiming(fixed_timeout_s=5.0)) as rig:
        in_flight = asyncio.create_task(rig.bus.drive(1).read_status())
        queued = asyncio.create_task(rig.bus.drive(2).read_status())
        while not rig.peer.requests:
            await asyncio.sleep(0.001)
        rig.bus.close()
        results = await asyncio.gather(in_flight, queued, return_exceptions=True)
    for result in results:
        assert type(result) is sj.BusClosedError, result
    print(f"\n{results[0]}")
    assert "closed while waiting for node 01" in str(results[0])


async def test_a_dropped_link_is_still_a_transport_error(scripted: MakeRig) -> None:
    async with scripted(silent, timing=sj.BusTiming(fixed_timeout_s=5.0)) as rig:
        in_flight = asyncio.create_task(rig.bus.drive(1).read_status())
        while not rig.peer.requests:
            await asyncio.sleep(0.001)
        rig.bus.link.drop()
        with pytest.raises(sj.TransportError) as info:
            await in_flight
        assert type(info.value) is sj.TransportError
        assert "connection lost" in str(info.value)


async def test_a_request_queued_when_the_link_drops_fails_and_frees_the_line(
    scripted: MakeRig,
) -> None:
    # Node 1 never answers; node 2's request waits behind it for the line. The
    # link drops: both fail at once, and once it is back the line is free (a
    # line held by a failed queued request would starve every later call).
    def respond(request: sj3.Request) -> Frames:
        return [] if request.node == 1 else answer_all(request)

    # (The line is drained after the failure: as long as the 0.5 s time-out.)
    async with scripted(respond, timing=sj.BusTiming(fixed_timeout_s=0.5)) as rig:
        bus = rig.bus
        in_flight = asyncio.create_task(bus.drive(1).read_status())
        queued = asyncio.create_task(bus.drive(2).read_status())
        await wait_for(lambda: rig.peer.requests, "node 1's request on the line")
        await wait_for(lambda: bus._arbiter.queue.waiting == 1, "node 2's request queued")
        bus.link.drop()
        for task in (in_flight, queued):
            with pytest.raises(sj.TransportError):
                await task
        assert not bus._arbiter.queue.busy
        await wait_for(lambda: bus.link.connected, "the link back")
        assert isinstance(await bus.drive(2).read_status(), sj.InverterStatus)


async def test_the_drain_warning_says_what_it_waited_for(
    scripted: MakeRig, caplog: pytest.LogCaptureFixture
) -> None:
    # Node 1 times out (20 ms); then the line babbles for 300 ms: the drain wants
    # 20 ms of quiet and gives up after drain_max_s = 0.1 s.
    def respond(request: sj3.Request) -> Frames:
        if request.node == 1:
            return [(0.02 + 0.005 * i, b"\x00") for i in range(60)]
        return [(0.0, status(request.node))]

    timing = sj.BusTiming(fixed_timeout_s=0.02, drain_max_s=0.1)
    async with scripted(respond, timing=timing, retries=0) as rig:
        with pytest.raises(sj.ReplyTimeoutError):
            await rig.bus.drive(1).read_status()
        with caplog.at_level(logging.WARNING, logger="sj300_async.arbiter"):
            await rig.bus.drive(2).read_status()
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    print("\n" + "\n".join(warnings))
    assert warnings == [
        "line did not go quiet for 0.020 s (the failed request's time-out) "
        "within 0.1 s (drain_max_s); going on"
    ]


# -- the plausibility floor -------------------------------------------------------------


def test_the_floor_is_the_wire_time_at_the_fastest_line() -> None:
    timing = sj.BusTiming()
    request = sj3.requests.read_parameter(1, "A003")  # 12 characters
    shortest = sj3.SJ300Dialect().shortest_reply_length(request)  # a NAK: 9
    assert shortest == 9
    at_19200 = 21 * 10 / 19200 * 0.95
    assert timing.answer_floor(request, INSTANT_LINE, shortest) == 0.0
    # A line declared slower than the drives can run: the floor of the fastest one.
    assert timing.answer_floor(request, sj.LineSettings(9600), shortest) == pytest.approx(at_19200)
    assert timing.answer_floor(request, sj.LineSettings(19200, parity="E"), shortest) == (
        pytest.approx(at_19200)
    )
    # A faster line than that (a converter at 115200): its own.
    fast = timing.answer_floor(request, sj.LineSettings(115200), shortest)
    assert fast == pytest.approx(21 * 10 / 115200 * 0.95)


# -- the dialects' shortest replies and sync requests ------------------------------------


def test_sj300_shortest_replies() -> None:
    dialect = sj3.SJ300Dialect()
    rq = sj3.requests
    assert dialect.shortest_reply_length(rq.run(1, sj.Direction.STOP)) == 7  # ACK
    assert dialect.shortest_reply_length(rq.read_status(1)) == 9  # NAK (the data: 14)
    assert dialect.shortest_reply_length(rq.can_store(1)) == 9  # ACK + 2 and NAK alike


def test_sj300_sync_requests_have_a_shape_no_pending_reply_has() -> None:
    dialect = sj3.SJ300Dialect()
    rq = sj3.requests

    def sync(*pending: sj3.Request) -> sj3.Command | None:
        chosen = dialect.sync_request(5, pending)
        if chosen is None:
            return None
        assert chosen.node == 5
        assert not dialect.writes(chosen)
        for request in pending:  # no late reply to a pending request answers it
            assert not dialect.answers(chosen, _positive_reply(request))
        return chosen.command

    read = rq.read_parameter(5, "A003")
    assert sync(read) is sj3.Command.CAN_STORE
    assert sync(read, rq.can_store(5)) is sj3.Command.READ_STATUS
    assert sync(rq.can_store(5), rq.read_status(5)) is sj3.Command.READ_MONITOR
    assert sync(rq.can_store(5), rq.read_status(5), rq.read_monitor(5)) is None


def _positive_reply(request: sj3.Request) -> sj3.Reply:
    """What the drive answers *request* with, parsed by the library's own parser."""
    (frame,) = answer_all(request)
    events = sj3.ReplyParser().feed(frame[1])
    assert len(events) == 1
    event = events[0]
    assert isinstance(event, (sj3.AckReply, sj3.AckDataReply, sj3.DataReply, sj3.NakReply))
    return event


def test_fr700_shortest_replies() -> None:
    dialect = fr.Fr700Dialect()  # CR terminator
    assert dialect.shortest_reply_length(fr.requests.read(0, "H7A")) == 5  # NAK + CR
    assert dialect.shortest_reply_length(fr.requests.write(0, "HFA", 2)) == 4  # ACK + CR
    bare = fr.Fr700Dialect(terminator="")
    assert bare.shortest_reply_length(fr.requests.read(0, "H7A")) == 4


def test_fr700_sync_requests_read_a_width_no_pending_reply_has() -> None:
    dialect = fr.Fr700Dialect()
    rq = fr.requests

    def sync(*pending: fr.Fr700Request) -> int | None:
        chosen = dialect.sync_request(3, pending)
        if chosen is None:
            return None
        assert chosen.station == 3
        assert not dialect.writes(chosen)
        assert chosen.kind is fr.requests.Fr700RequestKind.READ
        return chosen.instruction

    status_read, frequency = rq.read(3, "H7A"), rq.read(3, "H6F")
    assert sync(rq.write(3, "HFA", 2)) == 0x7A  # a write is answered by ACK
    assert sync(rq.multi_command(3, 2, 10.0)) == 0x7A  # a C1: 12 characters
    assert sync(status_read) == 0x6F  # 2 digits pending: read 4
    assert sync(frequency) == 0x7A
    assert sync(status_read, frequency) is None
    assert sync(rq.read(3, "H74")) is None  # an unknown width may be any


def test_toy_sync_requests_only_tell_writes_apart() -> None:
    write, read = ToyRequest(2, "set", 5), ToyRequest(2, "speed")
    assert TOY_DIALECT.sync_request(2, [write]) == ToyRequest(2, "status")
    assert TOY_DIALECT.sync_request(2, [write, read]) is None
    assert TOY_DIALECT.shortest_reply_length(read) == 6


# -- the simulator's servers obey the floor --------------------------------------------


def test_a_plausible_line_hands_replies_over_no_sooner_than_physics() -> None:
    line = PlausibleLine()  # 19200 baud, 10 bits a character
    char_s = 10 / 19200
    assert line.receive(1.0, b"x" * 8) == [(1.0, b"x" * 8)]  # the drive hears it at once
    assert line.transmit(1.001, b"reply") == [(1.0 + (8 + MIN_REPLY_CHARS) * char_s, b"reply")]
    # A slower drive is not held back any further.
    assert line.transmit(1.5, b"reply") == [(1.5, b"reply")]


async def test_a_tcp_simulator_answers_a_host_with_a_line() -> None:
    # tcp:// assumes 19200 baud behind the socket: the simulator's answers must
    # never look early; served at once, they would all be refused.
    sim = SimulatedBus(nodes=[1])
    async with await serve_tcp(sim) as server:
        url = f"tcp://127.0.0.1:{server.port}"
        async with sj.open_bus(url, timeout=0.5, retries=0) as bus:
            for _ in range(5):
                await bus.drive(1).read_status()
            assert bus.stats.early_frames == 0
    async with await serve_tcp(sim, pacing=sj.LineSettings(baudrate=0)) as server:
        url = f"tcp://127.0.0.1:{server.port}"
        async with sj.open_bus(url, timeout=0.05, retries=0) as bus:
            with pytest.raises(sj.ReplyTimeoutError):
                await bus.drive(1).read_status()  # answered at once: refused as early
            assert bus.stats.early_frames == 1
        async with sj.open_bus(url, line=INSTANT_LINE, timeout=0.5) as bus:
            await bus.drive(1).read_status()  # a host told there is no line takes it
            assert bus.stats.early_frames == 0
