"""Payload decoders and encoders against hand-built data from the reference tables.

docs: sj300.md, "03 — monitor block", "04 — status", "05 — trip history",
"06 / 07 — parameters".
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async import (
    Direction,
    InputMonitor,
    InverterStatus,
    LocalProtocolError,
    MonitorData,
    OutputTerminal,
    RemoteProtocolError,
    StatusA,
    StatusB,
    StatusC,
    TripHistory,
    TripRecord,
    TripStatusB,
    TripStatusC,
)
from sj300_async.sj300 import (
    decode_can_store,
    decode_monitor,
    decode_parameter_value,
    decode_status,
    decode_trip_history,
    encode_monitor,
    encode_status,
    encode_trip_history,
)

PROPERTY = settings(max_examples=200, deadline=None)


def field(value: int) -> bytes:
    """One 8-character decimal field as the reference describes it (leading '-' if negative)."""
    return b"-%07d" % -value if value < 0 else b"%08d" % value


def fields(*values: int) -> bytes:
    return b"".join(field(v) for v in values)


# -- command 04: status ---------------------------------------------------------

STATUS_A = {
    0: "INITIAL",  # initial status
    2: "STOPPING",  # on stopping
    3: "RUNNING",  # on running
    4: "FREE_RUN_STOP",  # on free-run stop
    5: "JOGGING",  # on jog
    6: "DYNAMIC_BRAKING",  # on dynamic braking
    7: "RETRY",  # on retry
    8: "TRIP",  # on trip
    9: "UNDER_VOLTAGE",  # on under-voltage
}
STATUS_B = {0: "STOPPED", 1: "RUNNING", 2: "TRIPPED"}
STATUS_C = {
    1: "STOP",
    2: "DECELERATING",
    3: "CONSTANT_SPEED",
    4: "ACCELERATING",
    5: "FORWARD",
    6: "REVERSE",
    7: "REVERSE_FROM_FORWARD",
    8: "FORWARD_FROM_REVERSE",
    9: "FORWARD_START",
    10: "REVERSE_START",
}


@pytest.mark.parametrize(
    ("enum", "table"), [(StatusA, STATUS_A), (StatusB, STATUS_B), (StatusC, STATUS_C)]
)
def test_status_tables(enum: Any, table: dict[int, str]) -> None:
    for code in range(100):
        member = enum(code)
        assert int(member) == code
        if code in table:
            assert member.name == table[code]
            assert member.known
        else:
            assert not member.known, f"{enum.__name__} {code:02d} is '—' in the reference"


def test_decode_status() -> None:
    status = decode_status(b"03010300")
    assert status == InverterStatus(StatusA.RUNNING, StatusB.RUNNING, StatusC.CONSTANT_SPEED)
    assert not status.tripped


@pytest.mark.parametrize(
    ("data", "tripped"),
    [(b"08020100", True), (b"00020100", True), (b"08000100", True), (b"03010300", False)],
)
def test_decode_status_tripped(data: bytes, tripped: bool) -> None:
    assert decode_status(data).tripped is tripped


@pytest.mark.parametrize(("a", "b", "c"), [(42, 99, 0), (1, 3, 11), (10, 50, 99)])
def test_unknown_status_codes_are_kept(a: int, b: int, c: int) -> None:
    status = decode_status(b"%02d%02d%02d00" % (a, b, c))
    assert (int(status.a), int(status.b), int(status.c)) == (a, b, c)
    assert not status.a.known
    assert not status.b.known
    assert not status.c.known


def test_unknown_status_enum_values_do_not_raise() -> None:
    assert int(StatusA(42)) == 42
    assert not StatusA(42).known
    assert StatusA(42) == StatusA(42)


def test_encode_status_layout() -> None:
    status = InverterStatus(StatusA.TRIP, StatusB.TRIPPED, StatusC.STOP)
    assert encode_status(status) == b"08020100"


# -- command 03: monitor ----------------------------------------------------------

MONITOR = fields(
    5000,  # 1 output frequency, x 100 -> 50.00 Hz
    123,  # 2 output current, x 10 -> 12.3 A
    1,  # 3 direction: forward
    4567,  # 4 PID feedback, x 100 -> 45.67 %
    0,  # 5 placeholder, replaced below (hex)
    0,  # 6 placeholder, replaced below (hex)
    12345,  # 7 frequency conversion, x 100 -> 123.45
    87,  # 8 output torque, x 1 -> 87 %
    2003,  # 9 output voltage, x 10 -> 200.3 V
    55,  # 10 electric power, x 10 -> 5.5 kW
    0,  # 11 reserved
    1234,  # 12 RUN time, h
    56789,  # 13 power-ON time, h
)
MONITOR = MONITOR[:32] + b"00000105" + b"0000002A" + MONITOR[48:]


def test_decode_monitor_reference_scales() -> None:
    m = decode_monitor(MONITOR)
    assert m.output_frequency_hz == pytest.approx(50.00)
    assert m.output_current_a == pytest.approx(12.3)
    assert m.direction is Direction.FORWARD
    assert m.pid_feedback_percent == pytest.approx(45.67)
    # item 5 read as hex: FW = 1, terminal 1 = 2, 2 = 4, ... 8 = 0x100
    assert m.input_terminals == InputMonitor.FW | InputMonitor.IN2 | InputMonitor.IN8
    assert int(m.input_terminals) == 0x105
    # item 6 read as hex: AL = 1, 11 = 2, 12 = 4, 13 = 8, 14 = 0x10, 15 = 0x20
    assert m.output_terminals == OutputTerminal.OUT11 | OutputTerminal.OUT13 | OutputTerminal.OUT15
    assert int(m.output_terminals) == 0x2A
    assert m.frequency_conversion == pytest.approx(123.45)
    assert m.output_torque_percent == 87
    assert m.output_voltage_v == pytest.approx(200.3)
    assert m.power_kw == pytest.approx(5.5)
    assert m.run_time_h == 1234
    assert m.power_on_time_h == 56789


def test_monitor_terminal_bits_match_the_reference() -> None:
    assert [int(t) for t in InputMonitor] == [1 << i for i in range(9)]
    assert int(InputMonitor.FW) == 1
    assert int(InputMonitor.IN8) == 0x100
    assert int(OutputTerminal.AL) == 1
    assert [OutputTerminal.OUT11, OutputTerminal.OUT12, OutputTerminal.OUT13] == [2, 4, 8]
    assert [OutputTerminal.OUT14, OutputTerminal.OUT15] == [0x10, 0x20]


@pytest.mark.parametrize(("code", "direction"), [(0, "STOP"), (1, "FORWARD"), (2, "REVERSE")])
def test_decode_monitor_direction(code: int, direction: str) -> None:
    m = decode_monitor(MONITOR[:16] + field(code) + MONITOR[24:])
    assert m.direction.name == direction


def test_decode_monitor_unknown_direction_is_kept() -> None:
    m = decode_monitor(MONITOR[:16] + field(7) + MONITOR[24:])
    assert int(m.direction) == 7
    assert not m.direction.known


def test_decode_monitor_lower_case_hex_terminals() -> None:
    m = decode_monitor(MONITOR[:32] + b"000001ff" + b"0000003f" + MONITOR[48:])
    assert int(m.input_terminals) == 0x1FF
    assert int(m.output_terminals) == 0x3F


def test_decode_monitor_negative_values() -> None:
    data = (
        field(-1250)  # frequency -12.50 Hz
        + MONITOR[8:24]
        + field(-333)  # PID -3.33 %
        + MONITOR[32:56]
        + field(-150)  # torque -150 %
        + MONITOR[64:72]
        + field(-22)  # power -2.2 kW (regenerating)
        + MONITOR[80:]
    )
    assert data[:8] == b"-0001250"
    m = decode_monitor(data)
    assert m.output_frequency_hz == pytest.approx(-12.5)
    assert m.pid_feedback_percent == pytest.approx(-3.33)
    assert m.output_torque_percent == -150
    assert m.power_kw == pytest.approx(-2.2)


def test_encode_monitor_reproduces_the_reference_block() -> None:
    assert encode_monitor(decode_monitor(MONITOR)) == MONITOR


# -- command 05: trip history ---------------------------------------------------------


def record(*nine: int) -> bytes:
    assert len(nine) == 9
    return fields(*nine)


TRIP_HISTORY = (
    field(3)  # total trips
    # factor, status A, status B bits, status C, Hz x10, RUN h, A x10, V x10, power-on h
    + record(7, 8, 0b0000_1000, 2, 500, 1234, 123, 3456, 5678)
    + record(14, 3, 0b0001_0001, 6, 601, 10, 5, 2000, 20)
    + record(99, 42, 0x100, 9, 0, 0, 0, 0, 0)
    + record(0, 0, 0, 0, 0, 0, 0, 0, 0) * 3
)


def test_decode_trip_history_reference_fields() -> None:
    assert len(TRIP_HISTORY) == 8 + 6 * 72 == 440
    history = decode_trip_history(TRIP_HISTORY)
    assert history.total_count == 3
    assert len(history.records) == 6
    newest = history.records[0]
    assert newest.trip_factor == 7
    assert newest.error_code == "E07"
    assert newest.status_a is StatusA.TRIP
    assert newest.status_b == TripStatusB.OVER_VOLTAGE
    assert newest.status_c is TripStatusC.DECELERATING
    assert newest.output_frequency_hz == pytest.approx(50.0)
    assert newest.run_time_h == 1234
    assert newest.output_current_a == pytest.approx(12.3)
    assert newest.output_voltage_v == pytest.approx(345.6)
    assert newest.power_on_time_h == 5678
    second = history.records[1]
    assert second.error_code == "E14"
    assert second.status_a is StatusA.RUNNING
    assert second.status_b == TripStatusB.GROUND_FAULT | TripStatusB.THERMAL
    assert second.status_c is TripStatusC.RUNNING
    assert second.output_frequency_hz == pytest.approx(60.1)
    assert second.output_current_a == pytest.approx(0.5)
    assert second.output_voltage_v == pytest.approx(200.0)


def test_trip_history_unknown_codes_are_kept() -> None:
    third = decode_trip_history(TRIP_HISTORY).records[2]
    assert third.trip_factor == 99
    assert third.error_code == "E99"
    assert int(third.status_a) == 42
    assert not third.status_a.known
    assert int(third.status_b) == 0x100
    assert int(third.status_c) == 9
    assert not third.status_c.known


def test_trip_history_empty_slots() -> None:
    history = decode_trip_history(TRIP_HISTORY)
    assert [r.is_empty for r in history.records] == [False, False, False, True, True, True]
    assert history.trips == history.records[:3]


def test_trip_status_b_bits_match_the_reference() -> None:
    expected = {
        0: "GROUND_FAULT",  # E14
        1: "IGBT_U",  # E30
        2: "UNDER_VOLTAGE",  # E09
        3: "OVER_VOLTAGE",  # E07
        4: "THERMAL",  # E21
        5: "IGBT_V",  # E30
        6: "IGBT_W",  # E30
        7: "GATE_ARRAY",  # E23
    }
    assert {m.value.bit_length() - 1: m.name for m in TripStatusB} == expected


def test_trip_status_c_table_matches_the_reference() -> None:
    expected = [
        "RESET",
        "STOPPING",
        "DECELERATING",
        "CONSTANT_SPEED",
        "ACCELERATING",
        "ZERO_HZ_RUN",
        "RUNNING",
        "DYNAMIC_BRAKING",
        "OVERLOAD_RESTRICTION",
    ]
    assert [TripStatusC(code).name for code in range(9)] == expected
    assert not TripStatusC(9).known


def test_negative_trip_status_b_is_not_turned_into_other_bits() -> None:
    # A bit field has no sign. "-0000001" must not decode as "every fault bit set"
    # (Python's IntFlag maps -1 to ~0): either the decoder refuses it, or it keeps -1.
    data = TRIP_HISTORY[:24] + field(-1) + TRIP_HISTORY[32:]
    try:
        history = decode_trip_history(data)
    except RemoteProtocolError:
        return
    assert int(history.records[0].status_b) == -1


def test_encode_trip_history_reproduces_the_reference_block() -> None:
    assert encode_trip_history(decode_trip_history(TRIP_HISTORY)) == TRIP_HISTORY


@pytest.mark.parametrize("count", [0, 5, 7])
def test_encode_trip_history_needs_six_records(count: int) -> None:
    history = decode_trip_history(TRIP_HISTORY)
    with pytest.raises(LocalProtocolError):
        encode_trip_history(TripHistory(3, (history.records[0],) * count))


# -- commands 06 and 09 ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("data", "value"),
    [
        (b"00000000", 0),
        (b"00000500", 500),
        (b"99999999", 99_999_999),
        (b"-0000001", -1),
        (b"-9999999", -9_999_999),
    ],
)
def test_decode_parameter_value(data: bytes, value: int) -> None:
    assert decode_parameter_value(data) == value


@pytest.mark.parametrize(("data", "allowed"), [(b"01", True), (b"00", False)])
def test_decode_can_store(data: bytes, allowed: bool) -> None:
    assert decode_can_store(data) is allowed


# -- malformed data: RemoteProtocolError, never a value int() would make up -------------

MALFORMED: list[tuple[Callable[[bytes], object], bytes]] = [
    (decode_status, b""),
    (decode_status, b"0301030"),
    (decode_status, b"030103000"),
    (decode_status, b"0A010300"),
    (decode_status, b" 3010300"),
    (decode_status, b"0301030 "),
    (decode_status, b"+3010300"),
    (decode_status, b"-3010300"),
    (decode_status, b"03_10300"),
    (decode_status, b"0301030\n"),
    (decode_status, b"\xb3010300"),
    (decode_monitor, MONITOR[:-1]),
    (decode_monitor, MONITOR + b"0"),
    (decode_monitor, b"0000500A" + MONITOR[8:]),
    (decode_monitor, b"+0005000" + MONITOR[8:]),
    (decode_monitor, b"0000_500" + MONITOR[8:]),
    (decode_monitor, b"   05000" + MONITOR[8:]),
    (decode_monitor, MONITOR[:32] + b"0x000105" + MONITOR[40:]),
    (decode_monitor, MONITOR[:32] + b"-0000105" + MONITOR[40:]),
    (decode_monitor, MONITOR[:32] + b"0000_105" + MONITOR[40:]),
    (decode_monitor, MONITOR[:32] + b" 0000105" + MONITOR[40:]),
    (decode_monitor, MONITOR[:40] + b"0000002G" + MONITOR[48:]),
    (decode_monitor, MONITOR[:96] + b"0005678\t"),
    (decode_trip_history, TRIP_HISTORY[:-1]),
    (decode_trip_history, TRIP_HISTORY + b"0"),
    (decode_trip_history, b"0000000A" + TRIP_HISTORY[8:]),
    (decode_trip_history, TRIP_HISTORY[:8] + b"+0000007" + TRIP_HISTORY[16:]),
    (decode_trip_history, TRIP_HISTORY[:8] + b"0000_007" + TRIP_HISTORY[16:]),
    (decode_trip_history, TRIP_HISTORY[:8] + b" 0000007" + TRIP_HISTORY[16:]),
    (decode_trip_history, TRIP_HISTORY[:432] + b"0000000\x00"),
    (decode_parameter_value, b""),
    (decode_parameter_value, b"0000050"),
    (decode_parameter_value, b"000005000"),
    (decode_parameter_value, b"0000050A"),
    (decode_parameter_value, b"+0000500"),
    (decode_parameter_value, b"0000_500"),
    (decode_parameter_value, b" 0000500"),
    (decode_parameter_value, b"0000500 "),
    (decode_parameter_value, b"0000-500"),
    (decode_parameter_value, b"--000500"),
    (decode_parameter_value, b"0000500\n"),
    (decode_can_store, b""),
    (decode_can_store, b"0"),
    (decode_can_store, b"1"),
    (decode_can_store, b"02"),
    (decode_can_store, b"10"),
    (decode_can_store, b"001"),
    (decode_can_store, b" 1"),
    (decode_can_store, b"+1"),
]


@pytest.mark.parametrize(
    ("decoder", "data"),
    MALFORMED,
    ids=[f"{d.__name__}-{i}" for i, (d, _) in enumerate(MALFORMED)],
)
def test_malformed_data_raises_remote_protocol_error(
    decoder: Callable[[bytes], object], data: bytes
) -> None:
    with pytest.raises(RemoteProtocolError):
        decoder(data)


# -- encoders are exact inverses --------------------------------------------------------

decimal_values = st.integers(min_value=-9_999_999, max_value=99_999_999)
unsigned_values = st.integers(min_value=0, max_value=99_999_999)
two_digits = st.integers(min_value=0, max_value=99)
hex32 = st.integers(min_value=0, max_value=0xFFFF_FFFF)


@PROPERTY
@given(two_digits, two_digits, two_digits)
def test_status_round_trip(a: int, b: int, c: int) -> None:
    status = InverterStatus(StatusA(a), StatusB(b), StatusC(c))
    data = encode_status(status)
    assert data == b"%02d%02d%02d00" % (a, b, c)
    assert decode_status(data) == status


@PROPERTY
@given(st.lists(decimal_values, min_size=11, max_size=11), hex32, hex32)
def test_monitor_data_round_trip(values: list[int], inputs: int, outputs: int) -> None:
    freq, current, direction, pid, conv, torque, volt, power, _, run_h, on_h = values
    data = fields(freq, current, direction, pid)
    data += b"%08X%08X" % (inputs, outputs)
    data += fields(conv, torque, volt, power, 0, run_h, on_h)
    assert encode_monitor(decode_monitor(data)) == data


@PROPERTY
@given(st.lists(decimal_values, min_size=11, max_size=11), hex32, hex32)
def test_monitor_object_round_trip(values: list[int], inputs: int, outputs: int) -> None:
    freq, current, direction, pid, conv, torque, volt, power, _, run_h, on_h = values
    m = MonitorData(
        output_frequency_hz=freq / 100,
        output_current_a=current / 10,
        direction=Direction(direction),
        pid_feedback_percent=pid / 100,
        input_terminals=InputMonitor(inputs),
        output_terminals=OutputTerminal(outputs),
        frequency_conversion=conv / 100,
        output_torque_percent=torque,
        output_voltage_v=volt / 10,
        power_kw=power / 10,
        run_time_h=run_h,
        power_on_time_h=on_h,
    )
    assert decode_monitor(encode_monitor(m)) == m


@PROPERTY
@given(st.lists(decimal_values, min_size=55, max_size=55))
def test_trip_history_data_round_trip(values: list[int]) -> None:
    # Every field the parser accepts as a decimal field; the decoder either
    # refuses the block or gives values that encode back to the same bytes.
    data = fields(*values)
    try:
        history = decode_trip_history(data)
    except RemoteProtocolError:
        return
    assert encode_trip_history(history) == data


trip_records = st.builds(
    lambda f, a, b, c, hz, run_h, amps, volts, on_h: TripRecord(
        trip_factor=f,
        status_a=StatusA(a),
        status_b=TripStatusB(b),
        status_c=TripStatusC(c),
        output_frequency_hz=hz / 10,
        run_time_h=run_h,
        output_current_a=amps / 10,
        output_voltage_v=volts / 10,
        power_on_time_h=on_h,
    ),
    unsigned_values,
    decimal_values,
    unsigned_values,
    decimal_values,
    decimal_values,
    decimal_values,
    decimal_values,
    decimal_values,
    decimal_values,
)


@PROPERTY
@given(unsigned_values, st.lists(trip_records, min_size=6, max_size=6))
def test_trip_history_object_round_trip(total: int, records: list[TripRecord]) -> None:
    history = TripHistory(total, tuple(records))
    assert decode_trip_history(encode_trip_history(history)) == history


@PROPERTY
@given(decimal_values)
def test_parameter_value_round_trip(value: int) -> None:
    assert decode_parameter_value(field(value)) == value
