"""The FR-700 simulator, raw bytes in and out, checked against frames written from the reference."""

from __future__ import annotations

import pytest

from sj300_async import LocalProtocolError
from sj300_async.fr700 import Fr700NakCode
from sj300_async.simulator.fr700 import Fr700SimulatedBus

from .fr700wire import (
    ACK,
    CR,
    ENQ,
    ETX,
    LF,
    NAK,
    STX,
    ack,
    data_reply,
    nak,
    ref_sum,
    reoutput,
    request,
)


def exchange(bus: Fr700SimulatedBus, raw: bytes, now: float = 0.0) -> list[bytes]:
    return [t.data for t in bus.receive(raw, now)]


@pytest.fixture
def bus() -> Fr700SimulatedBus:
    return Fr700SimulatedBus(stations=range(4))


def test_factory_line_reads_status(bus: Fr700SimulatedBus) -> None:
    assert exchange(bus, request(1, 0x7A)) == [data_reply(1, b"00")]


def test_manual_style_write_then_read_back(bus: Fr700SimulatedBus) -> None:
    assert exchange(bus, request(1, 0xED, b"1770")) == [ack(1)]
    assert exchange(bus, request(1, 0x6D)) == [data_reply(1, b"1770")]  # the manual's reply
    assert data_reply(1, b"1770") == STX + b"011770" + ETX + b"30" + CR


def test_any_chunking_gives_the_same_replies(bus: Fr700SimulatedBus) -> None:
    raw = request(2, 0xED, b"0BB8") + request(2, 0x6D)
    replies: list[bytes] = []
    for i in range(len(raw)):
        replies += exchange(bus, raw[i : i + 1])
    assert replies == [ack(2), data_reply(2, b"0BB8")]


def test_run_ramp_and_status_bits(bus: Fr700SimulatedBus) -> None:
    assert exchange(bus, request(0, 0x87, b"0000"), 0.0) == [ack(0)]  # Pr.7 = 0 s
    exchange(bus, request(0, 0xED, b"1388"), 0.0)  # 50 Hz
    assert exchange(bus, request(0, 0xFA, b"02"), 0.0) == [ack(0)]  # forward
    # RUN | FORWARD | SU | FU = 0x4B
    assert exchange(bus, request(0, 0x7A), 0.1) == [data_reply(0, b"4B")]
    assert exchange(bus, request(0, 0x79), 0.1) == [data_reply(0, b"004B")]
    assert exchange(bus, request(0, 0x6F), 0.1) == [data_reply(0, b"1388")]
    assert exchange(bus, request(0, 0xFA, b"00"), 0.2) == [ack(0)]
    assert exchange(bus, request(0, 0x7A), 5.0) == [data_reply(0, b"00")]


def test_a_tripped_drive_shows_abc_and_the_fault_bit(bus: Fr700SimulatedBus) -> None:
    bus.drives[3].trip(now=0.0)
    assert exchange(bus, request(3, 0x7A)) == [data_reply(3, b"80")]
    assert exchange(bus, request(3, 0x79)) == [data_reply(3, b"8080")]
    assert exchange(bus, request(3, 0x74)) == [data_reply(3, b"0012")]  # E.OC3 while stopped
    assert exchange(bus, request(3, 0xFD, b"9696")) == []  # the reset is never answered
    assert exchange(bus, request(3, 0x7A)) == [data_reply(3, b"00")]
    assert bus.stats.resets == 1


# -- NAK codes as a drive gives them --------------------------------------------------------------


def test_nak_2_for_a_wrong_sum(bus: Fr700SimulatedBus) -> None:
    frame = request(1, 0x7A)
    assert exchange(bus, frame[:-3] + b"00" + CR) == [nak(1, b"2")]


def test_nak_3_for_a_missing_waiting_time_field(bus: Fr700SimulatedBus) -> None:
    body = b"017A"
    assert exchange(bus, ENQ + body + ref_sum(body) + CR) == [nak(1, b"3")]


def test_nak_3_for_a_frame_cut_short_by_the_next(bus: Fr700SimulatedBus) -> None:
    assert exchange(bus, request(1, 0x7A)[:5] + request(2, 0x7A)) == [
        nak(1, b"3"),
        data_reply(2, b"00"),
    ]


def test_nak_7_for_a_character_that_is_not_hex(bus: Fr700SimulatedBus) -> None:
    body = b"01ed01770"
    assert exchange(bus, ENQ + body + ref_sum(body) + CR) == [nak(1, b"7")]


def test_nak_a_outside_network_mode() -> None:
    bus = Fr700SimulatedBus(stations=[0], factory_defaults=True)
    assert exchange(bus, request(0, 0x7B)) == [data_reply(0, b"0001")]  # external
    assert exchange(bus, request(0, 0xFA, b"02")) == [nak(0, b"A")]
    assert exchange(bus, request(0, 0xED, b"0100")) == [nak(0, b"A")]
    assert exchange(bus, request(0, 0xFB, b"0000")) == [ack(0)]
    assert exchange(bus, request(0, 0xFA, b"02")) == [ack(0)]


def test_nak_a_for_a_mode_change_while_running(bus: Fr700SimulatedBus) -> None:
    exchange(bus, request(0, 0xED, b"0100"))
    exchange(bus, request(0, 0xFA, b"02"))
    assert exchange(bus, request(0, 0xFB, b"0001"), 0.1) == [nak(0, b"A")]


@pytest.mark.parametrize("code", [0x78, 0x7C, 0xE5, 0xF8])
def test_nak_b_for_an_instruction_that_does_not_exist(bus: Fr700SimulatedBus, code: int) -> None:
    data = b"" if code < 0x80 else b"0000"
    assert exchange(bus, request(1, code, data)) == [nak(1, b"B")]


def test_nak_b_for_a_parameter_that_does_not_exist(bus: Fr700SimulatedBus) -> None:
    assert exchange(bus, request(1, 0x0A)) == [nak(1, b"B")]  # Pr.10


@pytest.mark.parametrize(
    ("code", "data"),
    [
        (0xED, b"2EE1"),  # 120.01 Hz > Pr.1
        (0xFB, b"0003"),  # no such operation mode
        (0xFF, b"0A"),  # bank 10
        (0xFD, b"1234"),  # reset needs H9696
        (0x87, b"8CA1"),  # Pr.7 = 3600.1 s
        (0xF3, b"04"),  # special monitor 4
    ],
)
def test_nak_c_for_data_out_of_range(bus: Fr700SimulatedBus, code: int, data: bytes) -> None:
    assert exchange(bus, request(1, code, data)) == [nak(1, b"C")]
    assert bus.stats.naks == {Fr700NakCode.DATA_RANGE: 1}


# -- addressing, line options, timing -----------------------------------------------------------


def test_absent_stations_and_unreadable_stations_get_nothing(bus: Fr700SimulatedBus) -> None:
    assert exchange(bus, request(9, 0x7A)) == []
    body = b"ZZ7A0"
    assert exchange(bus, ENQ + body + ref_sum(body) + CR) == []
    assert bus.stats.absent == 1


def test_no_terminator_line() -> None:
    bus = Fr700SimulatedBus(stations=[5], terminator="")
    assert exchange(bus, request(5, 0x7A, term=b"")) == [data_reply(5, b"00", b"")]
    assert exchange(bus, request(5, 0xFA, b"00", term=b"")) == [ack(5, b"")]
    assert exchange(bus, request(5, 0xE5, b"0000", term=b"")) == [nak(5, b"B", b"")]


def test_crlf_line() -> None:
    bus = Fr700SimulatedBus(stations=[5], terminator="\r\n")
    assert exchange(bus, request(5, 0x7A, term=CR + LF)) == [data_reply(5, b"00", CR + LF)]
    assert exchange(bus, request(5, 0x7A, term=CR)) == [data_reply(5, b"00", CR + LF)]


def test_line_without_the_waiting_time_field() -> None:
    bus = Fr700SimulatedBus(stations=[5], wait_field=False)
    assert exchange(bus, request(5, 0x7A, wait=b"")) == [data_reply(5, b"00")]
    assert exchange(bus, request(5, 0x7A)) == [nak(5, b"3")]  # one character too many
    assert exchange(bus, request(5, 0x7B, wait=b"")) == [data_reply(5, b"0000")]
    assert exchange(bus, request(5, 0x17, wait=b"")) == [nak(5, b"B")]  # Pr.23 (bank 0)


def test_the_waiting_time_delays_the_reply(bus: Fr700SimulatedBus) -> None:
    (fast,) = bus.receive(request(1, 0x7A, wait=b"0"), 0.0)
    (slow,) = bus.receive(request(1, 0x7A, wait=b"F"), 0.0)
    assert slow.delay_s - fast.delay_s == pytest.approx(0.150)


def test_a_fixed_waiting_time_without_the_field() -> None:
    bus = Fr700SimulatedBus(stations=[1], wait_field=False, processing_s=0.0)
    bus.drives[1].set_wait_ms(40)
    (reply,) = bus.receive(request(1, 0x7A, wait=b""), 0.0)
    assert reply.delay_s == pytest.approx(0.040)
    assert exchange(bus, request(1, 0xFF, b"01", wait=b"")) == [ack(1)]
    assert exchange(bus, request(1, 0x17, wait=b"")) == [data_reply(1, b"0028")]  # Pr.123 = 40
    with pytest.raises(LocalProtocolError):
        Fr700SimulatedBus(stations=[1]).drives[1].set_wait_ms(40)  # the field is in use


def test_a_drive_restarting_after_a_reset_hears_nothing() -> None:
    bus = Fr700SimulatedBus(stations=[1], reset_s=0.5)
    assert exchange(bus, request(1, 0xFD, b"9696"), 1.0) == []
    assert exchange(bus, request(1, 0x7A), 1.4) == []
    assert exchange(bus, request(1, 0x7A), 1.5) == [data_reply(1, b"00")]


# -- the host's answers ---------------------------------------------------------------------------


def test_host_nak_makes_the_drive_send_its_reply_again(bus: Fr700SimulatedBus) -> None:
    exchange(bus, request(2, 0xED, b"0BB8"))
    assert exchange(bus, request(2, 0x6D)) == [data_reply(2, b"0BB8")]
    assert exchange(bus, reoutput(2)) == [data_reply(2, b"0BB8")]
    assert exchange(bus, reoutput(2)) == [data_reply(2, b"0BB8")]
    assert bus.stats.reoutputs == 2
    assert exchange(bus, ack(2)) == []  # format C: the host got it
    assert bus.stats.host_acks == 1
    assert exchange(bus, reoutput(2)) == []  # nothing left to send again


def test_host_nak_after_a_write_has_nothing_to_resend(bus: Fr700SimulatedBus) -> None:
    exchange(bus, request(2, 0xED, b"0BB8"))
    assert exchange(bus, NAK + b"02" + CR) == []


def test_corrupt_next_breaks_the_sum_and_keeps_the_shape(bus: Fr700SimulatedBus) -> None:
    bus.faults.corrupt_next(1)
    (damaged,) = exchange(bus, request(1, 0x7A))
    good = data_reply(1, b"00")
    assert len(damaged) == len(good)
    assert damaged != good
    assert damaged[-3:-1] == good[-3:-1]  # the sum of the original data
    bus.faults.corrupt_next(1)
    (damaged_ack,) = exchange(bus, request(1, 0xFA, b"00"))
    assert damaged_ack == ACK + b"p1" + CR
    assert bus.stats.corrupted_replies == 2


def test_drop_and_silence(bus: Fr700SimulatedBus) -> None:
    bus.faults.drop_next(0)
    assert exchange(bus, request(0, 0x7A)) == []
    assert exchange(bus, request(0, 0x7A)) == [data_reply(0, b"00")]
    bus.faults.silence(0)
    assert exchange(bus, request(0, 0xFA, b"02")) == []
    bus.faults.silence(0, False)
    assert exchange(bus, request(0, 0x7A)) == [data_reply(0, b"00")]  # it heard nothing
    with pytest.raises(LocalProtocolError, match=r"0\.\.31"):
        bus.faults.drop_next(32)


def test_multi_command_reply_c1(bus: Fr700SimulatedBus) -> None:
    exchange(bus, request(1, 0x87, b"0000"))
    # send type 0, receive type 1 (current), forward, 30 Hz
    (reply,) = exchange(bus, request(1, 0xF0, b"01" + b"0002" + b"0BB8"))
    assert reply[:1] == STX
    assert reply[-4:-3] == ETX
    data = reply[3:-4]
    assert data[:4] == b"01FF"  # types echoed, no errors
    assert data[4:8] == b"004B"
    assert reply == data_reply(1, data)
    (refused,) = exchange(bus, request(1, 0xF0, b"10" + b"0004" + b"FFFF"))
    assert refused[3:-4][:4] == b"10FC"  # the frequency half out of range
    assert exchange(bus, request(1, 0xF0, b"24" + b"0000" + b"0000")) == [nak(1, b"3")]


def test_simulator_arguments_are_checked() -> None:
    with pytest.raises(LocalProtocolError):
        Fr700SimulatedBus(stations=[32])
    with pytest.raises(LocalProtocolError, match="twice"):
        Fr700SimulatedBus(stations=[1, 1])
    with pytest.raises(LocalProtocolError):
        Fr700SimulatedBus(terminator="\n")


def test_a_station_answers_in_order_behind_a_held_reply(bus: Fr700SimulatedBus) -> None:
    bus.faults.delay_next(1, 0.5)
    [first] = bus.receive(request(1, 0x7A), 0.0)
    [second] = bus.receive(request(1, 0x7A), 0.2)
    [other] = bus.receive(request(2, 0x7A), 0.2)
    assert first.delay_s == pytest.approx(0.5 + bus.drives[1].processing_s, abs=0.01)
    assert 0.2 + second.delay_s == pytest.approx(first.delay_s)  # not before the held one
    assert other.delay_s < 0.1
    [later] = bus.receive(request(1, 0x7A), 1.0)
    assert later.delay_s < 0.1
