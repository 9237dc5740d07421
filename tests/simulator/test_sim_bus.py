"""The simulated line: routing, chunking, reply timing, fault hooks and counters."""

from __future__ import annotations

import logging

import pytest

from sj300_async import LocalProtocolError
from sj300_async.simulator import LinePacing, Transmission
from sj300_async.simulator.sj300 import DEFAULT_PROCESSING_S, SimulatedBus

from .simwire import ack, ack_data, data_reply, exchange, nak, request, xor_bcc


def test_each_node_answers_for_itself() -> None:
    bus = SimulatedBus(nodes=range(1, 33))
    for node in range(1, 33):
        wire = b"%02d" % node
        assert exchange(bus, request(wire, b"06", b"C072")) == [ack_data(wire, b"%08d" % node)]


@pytest.mark.parametrize("chunk", [1, 2, 5, 7, 1000])
def test_any_chunking_gives_the_same_replies(chunk: int) -> None:
    stream = (
        request(b"01", b"04")
        + request(b"02", b"06", b"A004")
        + request(b"01", b"02", b"0000000000000000")
        + request(b"02", b"0B")
    )
    bus = SimulatedBus(nodes=[1, 2])
    out: list[bytes] = []
    for i in range(0, len(stream), chunk):
        out += exchange(bus, stream[i : i + chunk])
    assert out == [
        data_reply(b"01", b"02000100"),
        ack_data(b"02", b"00000500"),
        ack(b"01"),
        ack(b"02"),
    ]


def test_garbage_between_frames_is_counted_and_skipped(caplog: pytest.LogCaptureFixture) -> None:
    bus = SimulatedBus(nodes=[1])
    with caplog.at_level(logging.DEBUG, logger="sj300_async"):
        out = exchange(bus, b"\xff\x00junk" + request(b"01", b"0B") + b"\r\r")
    assert out == [ack(b"01")]
    assert bus.stats.discarded_bytes == 8
    assert "ff 00 6a 75 6e 6b" in caplog.text  # logged with hex


def test_reply_delay_is_c078_plus_processing_time() -> None:
    bus = SimulatedBus(nodes=[1, 2], wait_ms=40)
    [t] = bus.receive(request(b"01", b"04"), 0.0)
    assert t.delay_s == pytest.approx(0.040 + DEFAULT_PROCESSING_S)
    # C078 written over the line takes effect for the next reply
    exchange(bus, request(b"02", b"07", b"C07800000100"))
    [t] = bus.receive(request(b"02", b"04"), 0.0)
    assert t.delay_s == pytest.approx(0.100 + DEFAULT_PROCESSING_S)


def test_processing_time_is_configurable() -> None:
    bus = SimulatedBus(nodes=[1], processing_s=0.0)
    assert bus.receive(request(b"01", b"0B"), 0.0) == [Transmission(0.0, ack(b"01"))]


def test_line_settings_are_written_into_the_drives() -> None:
    bus = SimulatedBus(nodes=[1], line=LinePacing(9600, 7, "E", 2))
    assert {c: bus.drives[1].parameters[c] for c in ("C071", "C073", "C074", "C075")} == {
        "C071": 5,
        "C073": 7,
        "C074": 1,
        "C075": 2,
    }


# -- faults -------------------------------------------------------------------------


def test_drop_next_loses_the_reply_but_the_request_is_executed() -> None:
    bus = SimulatedBus(nodes=[1, 2])
    bus.faults.drop_next(1)
    assert exchange(bus, request(b"01", b"07", b"F00200001000")) == []
    assert bus.drives[1].parameters["F002"] == 1000
    assert bus.stats.dropped_replies == 1
    # only one reply, only node 1
    assert exchange(bus, request(b"02", b"0B")) == [ack(b"02")]
    assert exchange(bus, request(b"01", b"0B")) == [ack(b"01")]


def test_drop_next_with_a_count() -> None:
    bus = SimulatedBus(nodes=[1])
    bus.faults.drop_next(1, count=2)
    assert exchange(bus, request(b"01", b"0B")) == []
    assert exchange(bus, request(b"01", b"0B")) == []
    assert exchange(bus, request(b"01", b"0B")) == [ack(b"01")]


def test_delay_next_adds_to_one_reply() -> None:
    bus = SimulatedBus(nodes=[1], processing_s=0.0)
    bus.faults.delay_next(1, 0.5)
    assert bus.receive(request(b"01", b"0B"), 0.0) == [Transmission(0.5, ack(b"01"))]
    assert bus.receive(request(b"01", b"0B"), 1.0) == [Transmission(0.0, ack(b"01"))]
    assert bus.stats.delayed_replies == 1


def test_a_drive_answers_in_order_behind_a_held_reply() -> None:
    bus = SimulatedBus(nodes=[1, 2], processing_s=0.0)
    bus.faults.delay_next(1, 0.5)
    assert bus.receive(request(b"01", b"0B"), 0.0) == [Transmission(0.5, ack(b"01"))]
    # Asked again while its first answer is held, the drive answers after it...
    assert bus.receive(request(b"01", b"0B"), 0.2) == [Transmission(0.3, ack(b"01"))]
    assert bus.faults.held_until() == 0.5
    # ...another drive is not held...
    assert bus.receive(request(b"02", b"0B"), 0.2) == [Transmission(0.0, ack(b"02"))]
    # ...and once the held reply is out, the node is in order again.
    assert bus.receive(request(b"01", b"0B"), 0.6) == [Transmission(0.0, ack(b"01"))]
    assert not bus.faults.pending(1)
    assert bus.faults.held_until() == float("-inf")
    assert bus.stats.delayed_replies == 1  # held is not delayed: only the one fault counts


def test_clear_keeps_replies_already_held_in_order() -> None:
    bus = SimulatedBus(nodes=[1], processing_s=0.0)
    bus.faults.delay_next(1, 0.5)
    bus.receive(request(b"01", b"0B"), 0.0)
    bus.faults.clear()
    assert bus.receive(request(b"01", b"0B"), 0.1) == [Transmission(0.4, ack(b"01"))]


def test_late_node_is_late_until_cleared() -> None:
    bus = SimulatedBus(nodes=[1, 2], processing_s=0.0)
    bus.faults.late(2, 0.3)
    for _ in range(3):
        assert bus.receive(request(b"02", b"0B"), 0.0) == [Transmission(0.3, ack(b"02"))]
    assert bus.receive(request(b"01", b"0B"), 0.0) == [Transmission(0.0, ack(b"01"))]
    bus.faults.late(2, 0)
    assert bus.receive(request(b"02", b"0B"), 1.0) == [Transmission(0.0, ack(b"02"))]


def test_corrupt_next_makes_the_bcc_fail() -> None:
    bus = SimulatedBus(nodes=[1])
    bus.faults.corrupt_next(1)
    [bad] = exchange(bus, request(b"01", b"04"))
    good = data_reply(b"01", b"02000100")
    assert len(bad) == len(good)
    assert bad != good
    # still one frame: STX first, CR last, neither anywhere else
    assert bad[:1] == b"\x02"
    assert bad[-1:] == b"\r"
    assert b"\x02" not in bad[1:]
    assert b"\r" not in bad[:-1]
    assert xor_bcc(bad[1:-3]) != bad[-3:-1]  # the reference's check fails
    assert bad[1:3] == b"01"  # from the same node
    assert exchange(bus, request(b"01", b"04")) == [good]
    assert bus.stats.corrupted_replies == 1


@pytest.mark.parametrize("command", [b"0B", b"09", b"06A004", b"0C"])
def test_corruption_fails_the_bcc_for_every_reply_shape(command: bytes) -> None:
    bus = SimulatedBus(nodes=[1])
    bus.faults.corrupt_next(1)
    [bad] = exchange(bus, request(b"01", command[:2], command[2:]))
    assert xor_bcc(bad[1:-3]) != bad[-3:-1]


def test_silenced_node_hears_and_answers_nothing() -> None:
    bus = SimulatedBus(nodes=[1, 2])
    bus.faults.silence(1)
    assert exchange(bus, request(b"01", b"07", b"F00200001000")) == []
    assert bus.drives[1].parameters["F002"] == 3000
    exchange(bus, request(b"FF", b"07", b"F00200002000"))
    assert bus.drives[1].parameters["F002"] == 3000
    assert bus.drives[2].parameters["F002"] == 2000
    # nor a bad frame addressed to it
    assert exchange(bus, b"\x020104XX\r") == []
    bus.faults.silence(1, False)
    assert exchange(bus, request(b"01", b"0B")) == [ack(b"01")]
    assert bus.stats.absent == 1


def test_faults_apply_to_negative_replies_too() -> None:
    bus = SimulatedBus(nodes=[1])
    bus.faults.drop_next(1)
    assert exchange(bus, request(b"01", b"0C")) == []
    assert exchange(bus, request(b"01", b"0C")) == [nak(b"01", b"11")]


def test_clear_removes_every_fault() -> None:
    bus = SimulatedBus(nodes=[1])
    bus.faults.drop_next(1)
    bus.faults.silence(1)
    bus.faults.late(1, 1.0)
    bus.faults.clear()
    assert bus.receive(request(b"01", b"0B"), 0.0)[0].delay_s == DEFAULT_PROCESSING_S


@pytest.mark.parametrize(
    "call",
    [
        lambda f: f.drop_next(0),
        lambda f: f.drop_next(33),
        lambda f: f.drop_next(1, count=0),
        lambda f: f.delay_next(1, -1.0),
        lambda f: f.late(1, float("nan")),
    ],
)
def test_fault_arguments_are_checked(call: object) -> None:
    bus = SimulatedBus(nodes=[1])
    with pytest.raises(LocalProtocolError):
        call(bus.faults)  # type: ignore[operator]


def test_stats_count_everything() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"0B"))
    exchange(bus, request(b"FF", b"0A"))
    exchange(bus, request(b"FF", b"04"))
    exchange(bus, request(b"09", b"04"))
    exchange(bus, b"\x020104ZZ\r")
    exchange(bus, b"noise")
    s = bus.stats
    assert (s.requests, s.replies, s.broadcasts, s.ignored_broadcasts, s.absent) == (4, 2, 1, 1, 1)
    assert s.bad_frames == 1
    assert s.discarded_bytes == 5
    assert {int(k): v for k, v in s.naks.items()} == {2: 1}
    assert "requests=4" in repr(s)
