"""Every command and every negative reply, byte for byte against the protocol reference.

Requests and expected replies are written out here (see ``simwire``); the
simulator's answer must equal them exactly. The drives start as the
simulator's default: European factory values (A004 = 50.0 Hz, F002 = F003 =
30.00 s, C078 = 0) configured for serial control (A001 = A002 = 03).
"""

from __future__ import annotations

import pytest

from sj300_async.simulator.sj300 import SimulatedBus

from .simwire import (
    ACK,
    CR,
    NAK,
    STX,
    ack,
    ack_data,
    data_reply,
    exchange,
    fields,
    frame,
    nak,
    reply_data,
    request,
    xor_bcc,
)


@pytest.fixture
def bus() -> SimulatedBus:
    return SimulatedBus(nodes=[1, 2])


# -- the reference's worked examples ---------------------------------------------


def test_bcc_helper_reproduces_the_reference_examples() -> None:
    assert xor_bcc(b"01001") == b"30"
    assert xor_bcc(b"0101000500") == b"05"
    assert xor_bcc(b"01\x06") == b"07"
    assert xor_bcc(b"0102000000000000000D") == b"77"


def test_00_run_forward_worked_example(bus: SimulatedBus) -> None:
    raw = bytes.fromhex("02 30 31 30 30 31 33 30 0D")
    assert exchange(bus, raw) == [bytes.fromhex("02 30 31 06 30 37 0D")]
    # running forward at the 0 Hz setpoint: A running, B running, C forward
    assert exchange(bus, request(b"01", b"04")) == [data_reply(b"01", b"03010500")]


def test_01_set_frequency_worked_example(bus: SimulatedBus) -> None:
    raw = bytes.fromhex("02 30 31 30 31 30 30 30 35 30 30 30 35 0D")
    assert exchange(bus, raw) == [ack(b"01")]
    # F001 holds the setpoint, Hz x 100
    assert exchange(bus, request(b"01", b"06", b"F001")) == [ack_data(b"01", b"00000500")]


def test_02_terminals_fw_cf1_cf2(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"02", b"000000000000000D")) == [ack(b"01")]
    # FW runs the drive: status shows it running forward
    assert exchange(bus, request(b"01", b"04")) == [data_reply(b"01", b"03010500")]


def test_positive_reply_of_node_02(bus: SimulatedBus) -> None:
    # 0x30 ^ 0x32 ^ 0x06 = 0x04
    assert exchange(bus, request(b"02", b"00", b"0")) == [b"\x0202\x0604\r"]


# -- the read commands ------------------------------------------------------------


def test_03_monitor_of_a_stopped_drive_is_all_zeros(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"03")) == [data_reply(b"01", b"0" * 104)]


def test_03_monitor_of_a_running_drive(bus: SimulatedBus) -> None:
    exchange(bus, request(b"01", b"01", b"001000"), now=0.0)  # 10.00 Hz
    exchange(bus, request(b"01", b"00", b"1"), now=0.0)  # forward
    [reply] = exchange(bus, request(b"01", b"03"), now=60.0)
    data = reply_data(reply)
    assert len(data) == 104
    items = fields(data)
    assert items[0] == b"00001000"  # 10.00 Hz
    assert int(items[1]) > 0  # some current, A x 10
    assert items[2] == b"00000001"  # forward
    assert items[3] == b"00000000"  # PID feedback
    assert items[4] == b"00000000"  # no input terminal set
    assert items[5] == b"00000006"  # outputs 11 (RUN) and 12 (frequency arrival)
    assert items[6] == b"00001000"  # frequency conversion, factor 1
    assert int(items[7]) > 0  # torque %
    assert items[8] == b"00000800"  # 400 V x 10 Hz / 50 Hz = 80.0 V, x 10
    assert items[10] == b"00000000"  # reserved


def test_03_monitor_shows_terminals_where_c001_c008_assign_them(bus: SimulatedBus) -> None:
    # FW (own terminal, bit 0) and RV, which the factory assigns to input 8 (C008 = 01)
    exchange(bus, request(b"01", b"02", b"0000000000000003"))
    [reply] = exchange(bus, request(b"01", b"03"))
    assert fields(reply_data(reply))[4] == b"00000101"


def test_04_status_of_a_stopped_drive(bus: SimulatedBus) -> None:
    # A 02 on stopping, B 00 on stopping, C 01 stop, reserved 00
    assert exchange(bus, request(b"01", b"04")) == [data_reply(b"01", b"02000100")]


def test_05_trip_history_of_a_new_drive_is_all_zeros(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"05")) == [data_reply(b"01", b"0" * 440)]


@pytest.mark.parametrize(
    ("code", "value"),
    [
        (b"A004", b"00000500"),  # 50.0 Hz, x 10
        (b"A003", b"00000500"),
        (b"F002", b"00003000"),  # 30.00 s, x 100
        (b"F003", b"00003000"),
        (b"A001", b"00000003"),  # serial frequency source
        (b"A002", b"00000003"),  # serial run source
        (b"b084", b"00000000"),  # the manuals' lower-case b is accepted
        (b"B085", b"00000001"),  # Europe
        (b"C072", b"00000001"),  # its own node address
        (b"C078", b"00000000"),
        (b"H003", b"00000011"),  # 5.5 kW
    ],
)
def test_06_read_parameter(bus: SimulatedBus, code: bytes, value: bytes) -> None:
    assert exchange(bus, request(b"01", b"06", code)) == [ack_data(b"01", value)]


def test_07_write_then_06_reads_it_back(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"07", b"F00200001000")) == [ack(b"01")]
    assert exchange(bus, request(b"01", b"06", b"F002")) == [ack_data(b"01", b"00001000")]
    # the other drive is untouched
    assert exchange(bus, request(b"02", b"06", b"F002")) == [ack_data(b"02", b"00003000")]


def test_08_initializes_parameters_when_b084_is_01(bus: SimulatedBus) -> None:
    exchange(bus, request(b"01", b"07", b"F00200001000"))
    exchange(bus, request(b"01", b"07", b"B08400000001"))
    assert exchange(bus, request(b"01", b"08")) == [ack(b"01")]
    assert exchange(bus, request(b"01", b"06", b"F002")) == [ack_data(b"01", b"00003000")]
    # true factory values: the terminals, not the serial port, run the drive
    assert exchange(bus, request(b"01", b"06", b"A002")) == [ack_data(b"01", b"00000001")]
    assert exchange(bus, request(b"01", b"00", b"1")) == [nak(b"01", b"13")]


def test_08_country_b085_selects_60_hz(bus: SimulatedBus) -> None:
    exchange(bus, request(b"01", b"07", b"B08500000002"))  # USA
    exchange(bus, request(b"01", b"07", b"B08400000001"))
    assert exchange(bus, request(b"01", b"08")) == [ack(b"01")]
    assert exchange(bus, request(b"01", b"06", b"A004")) == [ack_data(b"01", b"00000600")]
    assert exchange(bus, request(b"01", b"06", b"A003")) == [ack_data(b"01", b"00000600")]
    assert exchange(bus, request(b"01", b"06", b"B085")) == [ack_data(b"01", b"00000002")]


def test_09_allows_storing_when_idle(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"09")) == [ack_data(b"01", b"01")]


def test_0a_store_is_acknowledged(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"0A")) == [ack(b"01")]


def test_0b_recalculate_is_acknowledged(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"0B")) == [ack(b"01")]
    assert bus.drives[1].recalculations == 1


# -- broadcasts and silence ---------------------------------------------------------


@pytest.mark.parametrize(
    ("command", "data"),
    [
        (b"00", b"1"),
        (b"01", b"000500"),
        (b"02", b"0000000000000000"),
        (b"07", b"F00200001000"),
        (b"08", b""),
        (b"0A", b""),
    ],
)
def test_broadcast_gets_no_reply(bus: SimulatedBus, command: bytes, data: bytes) -> None:
    assert exchange(bus, request(b"FF", command, data)) == []
    assert bus.stats.broadcasts == 1


def test_broadcast_is_executed_by_every_drive(bus: SimulatedBus) -> None:
    exchange(bus, request(b"FF", b"07", b"F00200001000"))
    for node in (b"01", b"02"):
        assert exchange(bus, request(node, b"06", b"F002")) == [ack_data(node, b"00001000")]


@pytest.mark.parametrize("command", [b"03", b"04", b"05", b"09", b"0B"])
def test_broadcast_of_a_read_command_is_ignored(bus: SimulatedBus, command: bytes) -> None:
    assert exchange(bus, request(b"FF", command)) == []
    assert bus.stats.ignored_broadcasts == 1
    assert bus.drives[1].recalculations == 0


def test_absent_node_stays_silent(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"03", b"04")) == []
    assert bus.stats.absent == 1


# -- negative replies ---------------------------------------------------------------


def test_bad_bcc_gets_nak_02(bus: SimulatedBus) -> None:
    good = request(b"01", b"04")
    bad = good[:-3] + (b"00" if good[-3:-1] != b"00" else b"11") + CR
    assert exchange(bus, bad) == [nak(b"01", b"02")]
    assert bus.stats.bad_frames == 1


def test_bad_bcc_may_be_answered_by_silence() -> None:
    bus = SimulatedBus(nodes=[1], nak_bad_bcc=False)
    assert exchange(bus, STX + b"0104" + b"FF" + CR) == []
    assert bus.stats.bad_frames == 1


def test_lower_case_bcc_is_accepted(bus: SimulatedBus) -> None:
    # 0x30^0x31^0x30^0x36^0x43^0x30^0x37^0x38 = 0x7B: sent as "7b"
    assert exchange(bus, STX + b"0106C078" + b"7b" + CR) == [ack_data(b"01", b"00000000")]


@pytest.mark.parametrize("command", [b"0C", b"0F", b"10", b"99"])
def test_unknown_command_gets_nak_11(bus: SimulatedBus, command: bytes) -> None:
    assert exchange(bus, request(b"01", command)) == [nak(b"01", b"11")]


@pytest.mark.parametrize("code", [b"A999", b"Z001", b"P099", b"F009"])
def test_06_unknown_parameter_gets_nak_16(bus: SimulatedBus, code: bytes) -> None:
    assert exchange(bus, request(b"01", b"06", code)) == [nak(b"01", b"16")]


@pytest.mark.parametrize(
    "data",
    [
        b"A99900000001",  # no such parameter
        b"A00400004010",  # 401.0 Hz: above the 400 Hz limit
        b"A00400000290",  # 29.0 Hz: below the 30 Hz limit
        b"A00300000600",  # base frequency 60 Hz above maximum 50 Hz
        b"F00200000000",  # 0.00 s acceleration
        b"C07800001001",  # wait time above 1000 ms
    ],
)
def test_07_unknown_parameter_or_value_out_of_range_gets_nak_16(
    bus: SimulatedBus, data: bytes
) -> None:
    assert exchange(bus, request(b"01", b"07", data)) == [nak(b"01", b"16")]


def test_07_motor_capacity_code_must_exist_in_the_country_table(bus: SimulatedBus) -> None:
    # code 02 (0.4 kW) is only in the US table; 01 (0.37 kW) only in the EU one
    assert exchange(bus, request(b"01", b"07", b"H00300000002")) == [nak(b"01", b"16")]
    assert exchange(bus, request(b"01", b"07", b"H00300000001")) == [ack(b"01")]


def test_01_above_maximum_frequency_gets_nak_16(bus: SimulatedBus) -> None:
    # A004 = 50.0 Hz
    assert exchange(bus, request(b"01", b"01", b"005001")) == [nak(b"01", b"16")]
    assert exchange(bus, request(b"01", b"01", b"005000")) == [ack(b"01")]


def test_00_run_mode_other_than_0_1_2_gets_nak_16(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"00", b"3")) == [nak(b"01", b"16")]


def test_02_unassigned_terminal_bit_gets_nak_16(bus: SimulatedBus) -> None:
    # bit 10 is unassigned
    assert exchange(bus, request(b"01", b"02", b"0000000000000400")) == [nak(b"01", b"16")]


@pytest.mark.parametrize(
    ("command", "data"),
    [
        (b"04", b"1"),  # 04 takes no data
        (b"00", b"11"),  # 00 takes one character
        (b"01", b"00500"),  # 01 takes six digits
        (b"02", b"000000000000001"),  # 02 takes sixteen hex digits
        (b"06", b"A0041"),  # 06 takes a 4-character code
        (b"07", b"A004500"),  # 07 takes a code and eight digits
    ],
)
def test_wrong_data_length_gets_nak_05(bus: SimulatedBus, command: bytes, data: bytes) -> None:
    assert exchange(bus, request(b"01", command, data)) == [nak(b"01", b"05")]


def test_frame_too_short_to_hold_a_command_gets_nak_05(bus: SimulatedBus) -> None:
    assert exchange(bus, STX + b"01" + CR) == [nak(b"01", b"05")]


@pytest.mark.parametrize(
    ("command", "data"),
    [
        (b"00", b"F"),
        (b"01", b"00050A"),
        (b"02", b"000000000000000G"),
        (b"06", b"A0X4"),
        (b"07", b"A004000005.0"),
    ],
)
def test_wrong_characters_get_nak_06(bus: SimulatedBus, command: bytes, data: bytes) -> None:
    assert exchange(bus, request(b"01", command, data)) == [nak(b"01", b"06")]


def test_run_refused_with_nak_13_unless_a002_selects_serial(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"07", b"A00200000001")) == [ack(b"01")]  # terminals
    assert exchange(bus, request(b"01", b"00", b"1")) == [nak(b"01", b"13")]
    assert exchange(bus, request(b"01", b"04")) == [data_reply(b"01", b"02000100")]


def test_frequency_refused_with_nak_13_unless_a001_selects_serial(bus: SimulatedBus) -> None:
    assert exchange(bus, request(b"01", b"07", b"A00100000002")) == [ack(b"01")]  # operator
    assert exchange(bus, request(b"01", b"01", b"000500")) == [nak(b"01", b"13")]
    assert exchange(bus, request(b"01", b"06", b"F001")) == [ack_data(b"01", b"00000000")]


def test_factory_defaults_refuse_serial_run_and_frequency() -> None:
    bus = SimulatedBus(nodes=[1], factory_defaults=True)
    assert exchange(bus, request(b"01", b"00", b"1")) == [nak(b"01", b"13")]
    assert exchange(bus, request(b"01", b"01", b"000500")) == [nak(b"01", b"13")]
    # the rest of the line works
    assert exchange(bus, request(b"01", b"06", b"A001")) == [ack_data(b"01", b"00000001")]


def test_08_while_running_gets_nak_13(bus: SimulatedBus) -> None:
    exchange(bus, request(b"01", b"01", b"001000"))
    exchange(bus, request(b"01", b"00", b"1"))
    assert exchange(bus, request(b"01", b"08"), now=1.0) == [nak(b"01", b"13")]


def test_unreadable_node_gets_no_reply(bus: SimulatedBus) -> None:
    assert exchange(bus, frame(b"0A04")) == []
    assert exchange(bus, frame(b"3304")) == []  # 33 is beyond the 32 nodes
    assert bus.stats.bad_frames == 2


def test_nak_is_counted_by_code(bus: SimulatedBus) -> None:
    exchange(bus, request(b"01", b"0C"))
    exchange(bus, request(b"01", b"06", b"A999"))
    exchange(bus, request(b"02", b"06", b"A999"))
    assert {int(code): n for code, n in bus.stats.naks.items()} == {11: 1, 16: 2}


def test_reply_frames_have_the_reference_shape(bus: SimulatedBus) -> None:
    # ACK replies: STX node ACK BCC CR; NAK: STX node NAK code BCC CR
    [positive] = exchange(bus, request(b"01", b"0B"))
    [negative] = exchange(bus, request(b"01", b"0C"))
    assert (positive[:1], positive[3:4], len(positive)) == (STX, ACK, 7)
    assert (negative[:1], negative[3:4], len(negative)) == (STX, NAK, 9)
