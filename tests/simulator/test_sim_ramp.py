"""The run state machine with an injected clock: ramps, direction and status codes at each phase.

Everything goes over the wire as bytes. Drives use the European factory
values: maximum frequency A004 = 50.0 Hz, F002 = F003 = 30.00 s, so the
output ramps at 50 / 30 Hz per second both ways.
"""

from __future__ import annotations

import pytest

from sj300_async.simulator import RunState
from sj300_async.simulator.sj300 import SimulatedBus

from .simwire import ack, exchange, fields, reply_data, request

RATE_HZ_PER_S = 50.0 / 30.0


def monitor(bus: SimulatedBus, now: float) -> tuple[int, int]:
    """(output frequency in 0.01 Hz, direction) from a command 03 reply at *now*."""
    [reply] = exchange(bus, request(b"01", b"03"), now)
    items = fields(reply_data(reply))
    return int(items[0]), int(items[2])


def status(bus: SimulatedBus, now: float) -> bytes:
    """The 8 data characters of a command 04 reply at *now*."""
    [reply] = exchange(bus, request(b"01", b"04"), now)
    return reply_data(reply)


def start(bus: SimulatedBus, centi_hz: bytes, run_mode: bytes, now: float) -> None:
    assert exchange(bus, request(b"01", b"01", centi_hz), now) == [ack(b"01")]
    assert exchange(bus, request(b"01", b"00", run_mode), now) == [ack(b"01")]


def test_ramp_up_settle_and_stop() -> None:
    bus = SimulatedBus(nodes=[1])
    start(bus, b"001000", b"1", now=100.0)

    # the instant of the run command: 0 Hz, forward start (C 09)
    assert monitor(bus, 100.0) == (0, 1)
    assert status(bus, 100.0) == b"03010900"

    # accelerating at the rate F002 implies, sampled every 0.5 s
    for step in range(1, 12):
        t = step * 0.5
        assert monitor(bus, 100.0 + t) == (round(RATE_HZ_PER_S * t * 100), 1), t
        assert status(bus, 100.0 + t) == b"03010400"  # running, accelerating

    # 10 Hz is reached after 10 / (50/30) = 6 s and held exactly
    assert monitor(bus, 106.0) == (1000, 1)
    assert status(bus, 106.0) == b"03010300"  # constant speed
    assert monitor(bus, 160.0) == (1000, 1)

    # stop: decelerating at the rate F003 implies, still turning forward
    assert exchange(bus, request(b"01", b"00", b"0"), 160.0) == [ack(b"01")]
    assert status(bus, 160.0) == b"03010200"
    assert monitor(bus, 163.0) == (500, 1)
    assert status(bus, 163.0) == b"03010200"

    # back at 0 Hz after 6 s: stopped, no direction
    assert monitor(bus, 166.0) == (0, 0)
    assert status(bus, 166.0) == b"02000100"
    assert bus.drives[1].state(166.0) is RunState.STOPPED


def test_one_long_step_equals_many_short_ones() -> None:
    stepped, jumped = SimulatedBus(nodes=[1]), SimulatedBus(nodes=[1])
    for bus in (stepped, jumped):
        start(bus, b"002000", b"1", now=0.0)
    for i in range(1, 71):
        monitor(stepped, i * 0.1)
    assert monitor(stepped, 7.0) == monitor(jumped, 7.0) == (round(RATE_HZ_PER_S * 7 * 100), 1)


def test_acceleration_time_f002_sets_the_rate() -> None:
    bus = SimulatedBus(nodes=[1])
    # F002 = 10.00 s from 0 to 50 Hz: 5 Hz per second
    assert exchange(bus, request(b"01", b"07", b"F00200001000")) == [ack(b"01")]
    start(bus, b"001000", b"1", now=0.0)
    assert monitor(bus, 1.0) == (500, 1)
    assert monitor(bus, 2.0) == (1000, 1)


def test_maximum_frequency_a004_sets_the_rate() -> None:
    bus = SimulatedBus(nodes=[1])
    # A004 = 100.0 Hz: F002 = 30 s now means 100 / 30 Hz per second
    assert exchange(bus, request(b"01", b"07", b"A00400001000")) == [ack(b"01")]
    start(bus, b"001000", b"1", now=0.0)
    assert monitor(bus, 1.5) == (500, 1)


def test_reversing_ramps_down_through_zero_then_up() -> None:
    bus = SimulatedBus(nodes=[1])
    start(bus, b"001000", b"1", now=0.0)
    assert monitor(bus, 10.0) == (1000, 1)

    assert exchange(bus, request(b"01", b"00", b"2"), 10.0) == [ack(b"01")]
    # decelerating while still turning forward: C 07 reverse from forward
    assert status(bus, 10.0) == b"03010700"
    assert monitor(bus, 13.0) == (500, 1)
    # through 0 Hz after 6 s; reverse start at that instant
    assert monitor(bus, 16.0) == (0, 2)
    assert status(bus, 16.0) == b"03011000"
    # then accelerating in reverse
    assert monitor(bus, 19.0) == (500, 2)
    assert status(bus, 19.0) == b"03010400"
    assert monitor(bus, 22.0) == (1000, 2)
    assert status(bus, 22.0) == b"03010300"

    # and back: C 08 forward from reverse
    assert exchange(bus, request(b"01", b"00", b"1"), 22.0) == [ack(b"01")]
    assert status(bus, 22.0) == b"03010800"


def test_lower_setpoint_decelerates_without_stopping() -> None:
    bus = SimulatedBus(nodes=[1])
    start(bus, b"002000", b"1", now=0.0)
    assert monitor(bus, 20.0) == (2000, 1)
    assert exchange(bus, request(b"01", b"01", b"001000"), 20.0) == [ack(b"01")]
    assert status(bus, 20.0) == b"03010200"
    assert monitor(bus, 23.0) == (1500, 1)
    assert monitor(bus, 26.0) == (1000, 1)
    assert status(bus, 26.0) == b"03010300"


def test_fw_terminal_runs_and_releasing_it_stops() -> None:
    bus = SimulatedBus(nodes=[1])
    assert exchange(bus, request(b"01", b"01", b"001000")) == [ack(b"01")]
    assert exchange(bus, request(b"01", b"02", b"0000000000000001"), 0.0) == [ack(b"01")]
    assert monitor(bus, 6.0) == (1000, 1)
    assert exchange(bus, request(b"01", b"02", b"0000000000000000"), 6.0) == [ack(b"01")]
    assert monitor(bus, 9.0) == (500, 1)
    assert monitor(bus, 12.0) == (0, 0)


@pytest.mark.parametrize("a002", [b"00000001", b"00000003"])
def test_fw_and_rv_together_mean_stop(a002: bytes) -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"07", b"A002" + a002))
    exchange(bus, request(b"01", b"01", b"001000"))
    exchange(bus, request(b"01", b"02", b"0000000000000003"), 0.0)
    assert monitor(bus, 5.0) == (0, 0)
    assert status(bus, 5.0) == b"02000100"


def test_rv_terminal_runs_reverse_when_a002_selects_terminals() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"07", b"A00200000001"))
    exchange(bus, request(b"01", b"01", b"001000"))
    exchange(bus, request(b"01", b"02", b"0000000000000002"), 0.0)
    assert monitor(bus, 6.0) == (1000, 2)


def test_free_run_cuts_the_output_and_restarts_from_zero() -> None:
    bus = SimulatedBus(nodes=[1])
    start(bus, b"001000", b"1", now=0.0)
    assert monitor(bus, 10.0) == (1000, 1)
    # FRS (bit 11): output cut at once, on free-run stop (A 04)
    assert exchange(bus, request(b"01", b"02", b"0000000000000800"), 10.0) == [ack(b"01")]
    assert monitor(bus, 10.0) == (0, 0)
    assert status(bus, 10.0) == b"04000100"
    # released while the run command holds: starts again from 0 Hz
    assert exchange(bus, request(b"01", b"02", b"0000000000000000"), 20.0) == [ack(b"01")]
    assert status(bus, 20.0) == b"03010900"
    assert monitor(bus, 23.0) == (500, 1)


def test_lowering_a004_pulls_the_setpoint_down() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"07", b"A00400001000"))  # 100 Hz
    exchange(bus, request(b"01", b"01", b"008000"))  # 80 Hz
    exchange(bus, request(b"01", b"07", b"A00400000500"))  # back to 50 Hz
    [reply] = exchange(bus, request(b"01", b"06", b"F001"))
    assert reply_data(reply, header=4) == b"00005000"


def test_time_never_runs_backwards() -> None:
    bus = SimulatedBus(nodes=[1])
    start(bus, b"001000", b"1", now=10.0)
    assert monitor(bus, 13.0) == (500, 1)
    # an earlier clock reading changes nothing
    assert monitor(bus, 11.0) == (500, 1)
    assert monitor(bus, 14.5) == (round(RATE_HZ_PER_S * 4.5 * 100), 1)


def test_hour_counters_count_power_on_and_run_time() -> None:
    bus = SimulatedBus(nodes=[1])
    monitor(bus, 0.0)  # the drive's clock starts at its first request
    start(bus, b"001000", b"1", now=3600.0)
    [reply] = exchange(bus, request(b"01", b"03"), 3 * 3600.0 + 1)
    items = fields(reply_data(reply))
    assert int(items[11]) == 2  # RUN time, h
    assert int(items[12]) == 3  # power-ON time, h
