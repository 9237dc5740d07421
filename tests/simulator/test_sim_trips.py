"""Trip injection: the history records the event and its values, status shows it, RS clears it."""

from __future__ import annotations

import pytest

from sj300_async import LocalProtocolError
from sj300_async.simulator import RunState
from sj300_async.simulator.sj300 import SimulatedBus

from .simwire import ack, exchange, fields, reply_data, request

RS = b"0000000000040000"  # bit 18
EXT = b"0000000000001000"  # bit 12
FW = b"0000000000000001"
NONE = b"0000000000000000"


def history(bus: SimulatedBus, node: bytes = b"01") -> list[list[bytes]]:
    """[[total count], record 1 fields, ..., record 6 fields] from a command 05 reply."""
    [reply] = exchange(bus, request(node, b"05"))
    items = fields(reply_data(reply))
    assert len(items) == 55
    return [items[:1]] + [items[1 + 9 * i : 10 + 9 * i] for i in range(6)]


def monitor(bus: SimulatedBus, now: float) -> list[bytes]:
    [reply] = exchange(bus, request(b"01", b"03"), now)
    return fields(reply_data(reply))


def status(bus: SimulatedBus, now: float) -> bytes:
    [reply] = exchange(bus, request(b"01", b"04"), now)
    return reply_data(reply)


def running_at_10_hz(now: float = 0.0) -> SimulatedBus:
    bus = SimulatedBus(nodes=[1, 2])
    assert exchange(bus, request(b"01", b"01", b"001000"), now) == [ack(b"01")]
    assert exchange(bus, request(b"01", b"00", b"1"), now) == [ack(b"01")]
    return bus


def test_trip_is_recorded_with_the_values_at_trip_time() -> None:
    bus = running_at_10_hz()
    before = monitor(bus, 10.0)
    assert bus.drives[1].trip(code=7, now=10.0)

    count, newest, *rest = history(bus)
    assert count == [b"00000001"]
    assert newest[0] == b"00000007"  # trip factor E07
    assert newest[1] == b"00000003"  # status A: running
    assert newest[2] == b"00000008"  # status B bit 3: over-voltage
    assert newest[3] == b"00000003"  # status C: constant speed
    assert newest[4] == b"00000100"  # 10.0 Hz, x 10
    assert newest[5] == b"00000000"  # RUN time, h
    assert int(newest[6]) == int(before[1]) > 0  # current as monitored, A x 10
    assert int(newest[7]) == int(before[8]) > 0  # voltage as monitored, V x 10
    assert newest[8] == b"00000000"  # power-ON time, h
    assert all(record == [b"00000000"] * 9 for record in rest)


def test_status_shows_the_trip_and_rs_clears_it() -> None:
    bus = running_at_10_hz()
    bus.drives[1].trip(code=1, now=10.0)

    # A 08 on trip, B 02 on tripping, C 01 stop; the output is cut, AL is on
    assert status(bus, 10.0) == b"08020100"
    items = monitor(bus, 10.0)
    assert items[0] == b"00000000"
    assert items[5] == b"00000001"
    # the other drive is untouched
    [other] = exchange(bus, request(b"02", b"04"), 10.0)
    assert reply_data(other) == b"02000100"

    # a run command while tripped is acknowledged and ignored
    assert exchange(bus, request(b"01", b"00", b"1"), 11.0) == [ack(b"01")]
    assert status(bus, 12.0) == b"08020100"

    # RS (rising edge) resets: stopped, and the serial run command was cleared
    assert exchange(bus, request(b"01", b"02", RS), 13.0) == [ack(b"01")]
    assert status(bus, 13.0) == b"02000100"
    assert monitor(bus, 20.0)[0] == b"00000000"
    # the history keeps the trip
    assert history(bus)[0] == [b"00000001"]


def test_a_held_fw_terminal_restarts_the_drive_after_reset() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"01", b"001000"), 0.0)
    exchange(bus, request(b"01", b"02", FW), 0.0)
    bus.drives[1].trip(code=4, now=10.0)
    assert status(bus, 10.0) == b"08020100"
    exchange(bus, request(b"01", b"02", b"0000000000040001"), 11.0)  # RS + FW
    assert status(bus, 11.0) == b"03010900"  # forward start
    assert monitor(bus, 14.0)[0] == b"00000500"


def test_rs_held_does_not_reset_a_later_trip() -> None:
    bus = running_at_10_hz()
    exchange(bus, request(b"01", b"02", RS), 1.0)
    bus.drives[1].trip(code=7, now=2.0)
    exchange(bus, request(b"01", b"02", RS), 3.0)  # no rising edge
    assert status(bus, 3.0) == b"08020100"
    exchange(bus, request(b"01", b"02", NONE), 4.0)
    exchange(bus, request(b"01", b"02", RS), 5.0)
    assert status(bus, 5.0) == b"02000100"


def test_trip_count_increments_and_newest_comes_first() -> None:
    bus = running_at_10_hz()
    drive = bus.drives[1]
    drive.trip(code=7, now=10.0)
    exchange(bus, request(b"01", b"02", RS), 11.0)
    exchange(bus, request(b"01", b"02", NONE), 11.0)
    drive.trip(code=9, now=12.0)
    count, newest, older, *_ = history(bus)
    assert count == [b"00000002"]
    assert newest[0] == b"00000009"
    assert newest[1] == b"00000002"  # stopped when it tripped
    assert newest[2] == b"00000004"  # status B bit 2: under-voltage
    assert newest[3] == b"00000001"  # trip-record status C: on stopping
    assert older[0] == b"00000007"


def test_history_keeps_six_records_and_counts_them_all() -> None:
    bus = SimulatedBus(nodes=[1])
    drive = bus.drives[1]
    for code in range(1, 9):  # E01..E08
        assert drive.trip(code=code, now=float(code))
        drive.reset(now=float(code))
    count, *records = history(bus)
    assert count == [b"00000008"]
    assert [r[0] for r in records] == [b"%08d" % c for c in (8, 7, 6, 5, 4, 3)]


def test_a_trip_while_tripped_is_not_recorded() -> None:
    bus = SimulatedBus(nodes=[1])
    assert bus.drives[1].trip(code=7, now=0.0)
    assert not bus.drives[1].trip(code=1, now=1.0)
    assert history(bus)[0] == [b"00000001"]


@pytest.mark.parametrize(
    ("at", "code"),
    [(0.0, b"00000004"), (3.0, b"00000003"), (10.0, b"00000001")],
)
def test_default_trip_is_the_over_current_of_the_phase(at: float, code: bytes) -> None:
    bus = SimulatedBus(nodes=[1])
    if at:
        exchange(bus, request(b"01", b"01", b"001000"), 0.0)
        exchange(bus, request(b"01", b"00", b"1"), 0.0)
    bus.drives[1].trip(now=at)  # E04 stopped, E03 accelerating, E01 constant speed
    assert history(bus)[1][0] == code


def test_decelerating_over_current_is_e02() -> None:
    bus = running_at_10_hz()
    exchange(bus, request(b"01", b"00", b"0"), 10.0)
    bus.drives[1].trip(now=11.0)
    record = history(bus)[1]
    assert record[0] == b"00000002"
    assert record[3] == b"00000002"  # trip-record status C: on deceleration


def test_ext_terminal_trips_with_e12() -> None:
    bus = running_at_10_hz()
    assert exchange(bus, request(b"01", b"02", EXT), 10.0) == [ack(b"01")]
    assert status(bus, 10.0) == b"08020100"
    assert history(bus)[1][0] == b"00000012"


def test_trip_history_survives_a_power_cycle_but_the_trip_does_not() -> None:
    bus = running_at_10_hz()
    bus.drives[1].trip(code=7, now=10.0)
    bus.drives[1].power_cycle(now=20.0)
    assert status(bus, 20.0) == b"02000100"
    assert history(bus)[0] == [b"00000001"]


@pytest.mark.parametrize(
    ("b084", "cleared", "a001"),
    [
        (b"00000000", True, b"00000003"),
        (b"00000001", False, b"00000001"),
        (b"00000002", True, b"00000001"),
    ],
)
def test_initialization_mode_b084(b084: bytes, cleared: bool, a001: bytes) -> None:
    bus = SimulatedBus(nodes=[1])
    bus.drives[1].trip(code=7, now=0.0)
    exchange(bus, request(b"01", b"02", RS), 1.0)
    exchange(bus, request(b"01", b"07", b"B084" + b084))
    assert exchange(bus, request(b"01", b"08")) == [ack(b"01")]
    assert history(bus)[0] == ([b"00000000"] if cleared else [b"00000001"])
    [reply] = exchange(bus, request(b"01", b"06", b"A001"))
    assert reply_data(reply, header=4) == a001


@pytest.mark.parametrize("code", [0, 100, -1])
def test_trip_factor_must_be_1_to_99(code: int) -> None:
    bus = SimulatedBus(nodes=[1])
    with pytest.raises(LocalProtocolError):
        bus.drives[1].trip(code=code, now=0.0)
    assert bus.drives[1].state(0.0) is RunState.STOPPED
