"""The drive model's caches: whatever changes an input is seen at once, even at the same instant.

A simulated drive keeps what it derives from its parameters until RAM is
written, and the run state (with the status and monitor replies made from
it) until a latch changes or the output moves; the bus reuses the frame of
a reply it is handed again, and the request parser decodes a body once.
The first tests change each input and read back at the same ``now``; the
property test runs random request sequences against drives that keep
nothing and compares every byte.
"""

from __future__ import annotations

import logging
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async import LocalProtocolError, TripHistory
from sj300_async.simulator import Faults, RunState
from sj300_async.simulator.sj300 import SimulatedBus, SimulatedDrive
from sj300_async.simulator.sj300._trips import TripLog
from sj300_async.sj300 import Request, RequestParser
from sj300_async.wire import BadFrame

from .simwire import ack, exchange, fields, reply_data, request

RATE_HZ_PER_S = 50.0 / 30.0  # European factory values: A004 = 50.0 Hz, F002 = F003 = 30.00 s
HOUR_S = 3600.0
FW = b"0000000000000001"
FRS = b"0000000000000800"  # bit 11
RS = b"0000000000040000"  # bit 18
NONE = b"0000000000000000"


def status(bus: SimulatedBus, now: float) -> bytes:
    [reply] = exchange(bus, request(b"01", b"04"), now)
    return reply_data(reply)


def monitor(bus: SimulatedBus, now: float) -> list[bytes]:
    [reply] = exchange(bus, request(b"01", b"03"), now)
    return fields(reply_data(reply))


def send(bus: SimulatedBus, command: bytes, data: bytes, now: float) -> None:
    assert exchange(bus, request(b"01", command, data), now) == [ack(b"01")]


def running_at(centi_hz: bytes, now: float = 0.0) -> SimulatedBus:
    bus = SimulatedBus(nodes=[1])
    send(bus, b"01", centi_hz, now)
    send(bus, b"00", b"1", now)
    return bus


# -- each input, read back at the same instant -----------------------------------


def test_07_writing_f002_changes_the_ramp_at_once() -> None:
    bus = running_at(b"005000")
    assert int(monitor(bus, 3.0)[0]) == round(RATE_HZ_PER_S * 3 * 100)
    send(bus, b"07", b"F00200001000", 3.0)  # 10.00 s from 0 to 50 Hz: 5 Hz per second
    assert int(monitor(bus, 3.0)[0]) == round(RATE_HZ_PER_S * 3 * 100)
    assert int(monitor(bus, 4.0)[0]) == round((RATE_HZ_PER_S * 3 + 5.0) * 100)


def test_01_while_running_changes_the_goal_at_once() -> None:
    bus = running_at(b"001000")
    assert status(bus, 10.0) == b"03010300"  # constant speed at 10 Hz
    send(bus, b"01", b"002000", 10.0)
    assert status(bus, 10.0) == b"03010400"  # accelerating toward 20 Hz
    send(bus, b"01", b"000500", 10.0)
    assert status(bus, 10.0) == b"03010200"  # decelerating toward 5 Hz
    assert int(monitor(bus, 13.0)[0]) == 500


def test_00_stop_at_a_0_hz_setpoint_drops_the_direction_at_once() -> None:
    bus = running_at(b"000000")
    assert status(bus, 5.0) == b"03010500"  # running forward at 0 Hz
    assert monitor(bus, 5.0)[2] == b"00000001"
    send(bus, b"00", b"0", 5.0)
    assert status(bus, 5.0) == b"02000100"
    assert monitor(bus, 5.0)[2] == b"00000000"


def test_trip_reset_and_power_cycle_are_seen_at_the_same_instant() -> None:
    bus = running_at(b"001000")
    drive = bus.drives[1]
    assert status(bus, 10.0) == b"03010300"
    assert drive.trip(7, now=10.0)
    assert status(bus, 10.0)[:4] == b"0802"  # A: trip, B: tripped
    assert drive.state(10.0) is RunState.TRIPPED
    assert drive.reset(10.0)
    assert status(bus, 10.0) == b"02000100"  # stopped: the trip cleared the run command
    send(bus, b"00", b"1", 10.0)
    assert status(bus, 10.0) == b"03010900"  # forward start
    drive.power_cycle(10.0)
    assert status(bus, 10.0) == b"02000100"
    assert drive.output_hz(10.0) == 0.0


def test_02_terminals_are_seen_at_the_same_instant() -> None:
    bus = running_at(b"001000")
    assert status(bus, 10.0) == b"03010300"
    send(bus, b"02", FRS, 10.0)
    assert status(bus, 10.0)[:2] == b"04"  # A: free-run stop
    assert int(monitor(bus, 10.0)[0]) == 0
    send(bus, b"02", NONE, 10.0)
    assert status(bus, 10.0) == b"03010900"  # restarting from 0 Hz
    assert int(monitor(bus, 10.0)[4], 16) == 0
    send(bus, b"02", RS, 10.0)  # C001 puts RS on input terminal 1
    assert int(monitor(bus, 10.0)[4], 16) == 0b10


def test_07_terminal_assignment_moves_the_monitor_bit_at_once() -> None:
    bus = SimulatedBus(nodes=[1])
    send(bus, b"02", RS, 0.0)
    assert int(monitor(bus, 0.0)[4], 16) == 0b10
    send(bus, b"07", b"C00200000018", 0.0)  # RS also on input terminal 2
    assert int(monitor(bus, 0.0)[4], 16) == 0b110


def test_monitor_hours_tick_over_while_nothing_else_changes() -> None:
    bus = running_at(b"001000")
    first = monitor(bus, 10.0)
    assert (first[11], first[12]) == (b"00000000", b"00000000")
    later = monitor(bus, 10.0 + HOUR_S)
    assert (later[11], later[12]) == (b"00000001", b"00000001")
    assert later[:11] == first[:11]


def test_trip_history_is_read_again_after_a_trip_and_after_08() -> None:
    bus = SimulatedBus(nodes=[1])
    [empty] = exchange(bus, request(b"01", b"05"))
    assert bus.drives[1].trip(7, now=0.0)
    [one] = exchange(bus, request(b"01", b"05"))
    assert one != empty
    assert fields(reply_data(one))[0] == b"00000001"
    send(bus, b"08", b"", 0.0)  # B084 = 00: clear the history
    assert exchange(bus, request(b"01", b"05")) == [empty]


def test_a_c078_write_changes_the_reply_delay_at_once() -> None:
    bus = SimulatedBus(nodes=[1], processing_s=0.0)
    assert [t.delay_s for t in bus.receive(request(b"01", b"04"), 0.0)] == [0.0]
    bus.drives[1].set_parameter("C078", 20)
    assert [t.delay_s for t in bus.receive(request(b"01", b"04"), 0.0)] == [0.02]


def test_08_and_a_power_cycle_bring_back_the_parameters_at_once() -> None:
    bus = SimulatedBus(nodes=[1], processing_s=0.0)
    drive = bus.drives[1]
    drive.set_parameter("C078", 20, store=False)
    assert drive.reply_delay_s == 0.02
    drive.power_cycle(0.0)  # C078 was not stored
    assert drive.reply_delay_s == 0.0
    send(bus, b"07", b"C07800000020", 0.0)
    send(bus, b"07", b"B08400000001", 0.0)  # 08 initializes the parameters
    [reply] = bus.receive(request(b"01", b"08"), 0.0)
    assert reply.delay_s == 0.0  # answered already with the factory C078
    assert drive.reply_delay_s == 0.0


def test_trip_log_history_is_the_same_object_until_the_log_changes() -> None:
    log = TripLog()
    first = log.history()
    assert log.history() is first
    log.record(first.records[0])
    assert log.history() is not first
    assert log.history().total_count == 1
    cleared = log.history()
    log.clear()
    assert log.history() is not cleared
    assert log.history() == first


def test_faults_pending_names_the_nodes_a_fault_may_act_on() -> None:
    faults = Faults()
    assert not faults.pending(1)
    faults.drop_next(1)
    faults.late(2, 0.5)
    assert faults.pending(1)
    assert faults.pending(2)
    assert not faults.pending(3)
    assert faults.apply(1, b"\x0201\x0607\r") is None
    assert not faults.pending(1)
    faults.clear()
    assert not faults.pending(2)


def test_a_repeated_frame_is_counted_and_logged_every_time(
    caplog: pytest.LogCaptureFixture,
) -> None:
    parser = RequestParser()
    good, bad = request(b"01", b"04"), request(b"01", b"04")[:-3] + b"00\r"
    with caplog.at_level(logging.DEBUG, logger="sj300_async.parser"):
        events = [*parser.feed(good), *parser.feed(good), *parser.feed(bad), *parser.feed(bad)]
    assert [type(e) for e in events] == [Request, Request, BadFrame, BadFrame]
    assert events[0] == events[1]
    assert parser.stats.frames == 2
    assert parser.stats.bad_frames == 2
    assert sum("bad frame" in r.getMessage() for r in caplog.records) == 2


# -- random sequences against drives that keep nothing ------------------------------


class _FreshTripLog(TripLog):
    """A trip log that builds its history again for every read."""

    def history(self) -> TripHistory:
        self._history = None
        return super().history()


class _RecomputingDrive(SimulatedDrive):
    """A drive that keeps nothing between two uses: every read works the model out afresh.

    Moving the memory's version makes the drive read its parameters again
    and take a new snapshot, as if RAM had just been written.
    """

    def __init__(self, node: int, **kwargs: Any) -> None:
        super().__init__(node, **kwargs)
        self._trips = _FreshTripLog()

    def _settings(self) -> Any:
        self._memory.version += 1
        return super()._settings()

    def _snapshot(self) -> Any:
        self._memory.version += 1
        return super()._snapshot()


def _hex(bits: frozenset[int]) -> bytes:
    return b"%016X" % sum(1 << bit for bit in bits)


# FW, CF1, CF2, JG, 2CH, FRS, EXT, AT, RS: what C001..C008 and the run model look at.
_terminals = st.frozensets(st.sampled_from([0, 1, 2, 3, 6, 9, 11, 12, 16, 18])).map(_hex)
_writes = st.sampled_from(
    [
        b"F00100000000",
        b"F00100001000",
        b"F00100005000",
        b"F00200000001",
        b"F00200001000",
        b"F00300000050",
        b"F00300360000",
        b"A00100000001",
        b"A00200000001",
        b"A00200000003",
        b"A00300000300",
        b"A00400000300",
        b"A00400000600",
        b"B08400000001",
        b"B08400000002",
        b"B08500000002",
        b"C00100000001",
        b"C00200000011",
        b"C00800000018",
        b"C07800000020",
        b"H00300000005",
    ]
)
_frames = st.one_of(
    st.tuples(st.just(b"00"), st.sampled_from([b"0", b"1", b"2"])),
    st.tuples(st.just(b"01"), st.sampled_from([b"000000", b"000500", b"002500", b"006000"])),
    st.tuples(st.just(b"02"), _terminals),
    st.tuples(st.sampled_from([b"03", b"04", b"05", b"08", b"09", b"0A", b"0B"]), st.just(b"")),
    st.tuples(st.just(b"06"), st.sampled_from([b"F001", b"A004", b"C078"])),
    st.tuples(st.just(b"07"), _writes),
).flatmap(
    lambda frame: st.sampled_from([b"01", b"02", b"FF"]).map(lambda node: request(node, *frame))
)
_events = st.one_of(
    st.tuples(st.just("trip"), st.sampled_from([None, 7, 12])),
    st.tuples(st.just("reset"), st.none()),
    st.tuples(st.just("power_cycle"), st.none()),
    st.tuples(st.just("set_parameter"), _writes),
)
_steps = st.lists(
    st.tuples(
        st.sampled_from([0.0, 0.0, 0.0, 0.001, 0.25, 2.0, 7.0, 40.0, 2 * HOUR_S]),
        st.one_of(_frames, _events),
        st.sampled_from([1, 2]),
    ),
    max_size=60,
)


def _observe(drive: SimulatedDrive, now: float) -> tuple[object, ...]:
    return (
        drive.state(now),
        drive.output_hz(now),
        drive.status(now),
        drive.monitor(now),
        drive.trip_history(),
        drive.reply_delay_s,
        dict(drive.parameters),
    )


@settings(max_examples=200, deadline=None)
@given(_steps)
def test_cached_drives_answer_as_drives_that_keep_nothing(
    steps: list[tuple[float, bytes | tuple[str, Any], int]],
) -> None:
    cached = SimulatedBus(nodes=[1, 2])
    fresh = SimulatedBus(nodes=[1, 2])
    fresh.drives = {node: _RecomputingDrive(node) for node in (1, 2)}
    now = 100.0
    for dt, action, node in steps:
        now += dt
        if isinstance(action, bytes):
            assert cached.receive(action, now) == fresh.receive(action, now)
            continue
        name, arg = action
        results: list[bool | str] = []  # what trip/reset return, or the refusal's message
        for drive in (cached.drives[node], fresh.drives[node]):
            if name == "trip":
                results.append(drive.trip(arg, now=now))
            elif name == "reset":
                results.append(drive.reset(now))
            elif name == "power_cycle":
                drive.power_cycle(now)
            else:
                try:
                    drive.set_parameter(arg[:4].decode(), int(arg[4:]), store=False)
                except LocalProtocolError as exc:  # refused: the same way by both
                    results.append(str(exc))
        assert results[:1] == results[1:]
        assert _observe(cached.drives[node], now) == _observe(fresh.drives[node], now)
    for node in (1, 2):
        assert _observe(cached.drives[node], now) == _observe(fresh.drives[node], now)
