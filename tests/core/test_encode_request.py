"""encode_request and the typed builders: what the reference allows, and everything it does not.

Rules under test (docs: sj300.md, "Frame layout" and "Commands"): nodes 01..32
or FF; FF only for 00/01/02/07/08/0A; commands 00..0B; each command's data
shape; command 02 refuses the unassigned bits 10, 19, 25, 30 and 49..63.
"""

from __future__ import annotations

import math
from functools import reduce
from operator import xor
from typing import Any

import pytest

from sj300_async import Direction, InputTerminal, LocalProtocolError
from sj300_async.sj300 import (
    BROADCAST,
    PARAMETERS,
    Command,
    encode_request,
    motor_capacity_kw,
    requests,
)

STX = b"\x02"
CR = b"\r"


def reference_bcc(body: bytes) -> bytes:
    return b"%02X" % reduce(xor, body, 0)


def reference_frame(node: bytes, command: bytes, data: bytes) -> bytes:
    body = node + command + data
    return STX + body + reference_bcc(body) + CR


def assert_refused(node: Any, command: Any, data: Any = b"") -> None:
    with pytest.raises(LocalProtocolError) as info:
        encode_request(node, command, data)
    assert isinstance(info.value, ValueError)


#: A valid data field for every command.
VALID_DATA: dict[int, bytes] = {
    0x00: b"1",
    0x01: b"000500",
    0x02: b"000000000000000D",
    0x03: b"",
    0x04: b"",
    0x05: b"",
    0x06: b"A004",
    0x07: b"A00400000500",
    0x08: b"",
    0x09: b"",
    0x0A: b"",
    0x0B: b"",
}
BROADCASTABLE = (0x00, 0x01, 0x02, 0x07, 0x08, 0x0A)
NOT_BROADCASTABLE = (0x03, 0x04, 0x05, 0x06, 0x09, 0x0B)
UNASSIGNED_TERMINAL_BITS = (10, 19, 25, 30, *range(49, 64))
ASSIGNED_TERMINAL_BITS = tuple(b for b in range(49) if b not in UNASSIGNED_TERMINAL_BITS)


# -- nodes ------------------------------------------------------------------


@pytest.mark.parametrize(
    "node", [0, 33, -1, 99, 0xFE, 0x100, True, False, "1", "01", b"01", 1.0, None]
)
def test_refuses_bad_node(node: Any) -> None:
    assert_refused(node, Command.RUN, b"1")


@pytest.mark.parametrize("node", range(1, 33))
def test_accepts_every_unicast_node(node: int) -> None:
    frame = encode_request(node, Command.READ_STATUS)
    assert frame == reference_frame(b"%02d" % node, b"04", b"")


@pytest.mark.parametrize("command", NOT_BROADCASTABLE)
def test_refuses_broadcast_of_commands_that_get_a_reply(command: int) -> None:
    assert BROADCAST == 0xFF
    assert_refused(BROADCAST, command, VALID_DATA[command])


@pytest.mark.parametrize("command", BROADCASTABLE)
def test_accepts_broadcast(command: int) -> None:
    frame = encode_request(BROADCAST, command, VALID_DATA[command])
    assert frame == reference_frame(b"FF", b"%02X" % command, VALID_DATA[command])


# -- commands ---------------------------------------------------------------


@pytest.mark.parametrize("command", [0x0C, 0x0F, 0x10, 0x30, -1, 255, "00", b"00", None])
def test_refuses_unknown_command(command: Any) -> None:
    assert_refused(1, command)


@pytest.mark.parametrize("command", [True, False, 1.0, 0.0])
def test_refuses_command_that_is_not_an_int(command: Any) -> None:
    # True == 1 and 1.0 == 1 in Python; neither is the command number 01. The node
    # is refused for the same reason (see test_refuses_bad_node).
    assert_refused(1, command, b"000500" if command else b"1")


@pytest.mark.parametrize("command", sorted(VALID_DATA))
def test_frame_structure_of_every_command(command: int) -> None:
    data = VALID_DATA[command]
    frame = encode_request(7, command, data)
    assert frame[:1] == STX
    assert frame[1:3] == b"07"
    assert frame[3:5] == b"%02X" % command
    assert frame[5 : 5 + len(data)] == data
    assert frame[5 + len(data) : -1] == reference_bcc(frame[1 : 5 + len(data)])
    assert frame[-1:] == CR
    assert len(frame) == 1 + 2 + 2 + len(data) + 2 + 1


def test_command_0a_and_0b_are_sent_as_upper_case_hex() -> None:
    assert encode_request(1, Command.STORE)[3:5] == b"0A"
    assert encode_request(1, Command.RECALCULATE)[3:5] == b"0B"


# -- data shapes ------------------------------------------------------------

BAD_DATA: list[tuple[int, Any]] = [
    # 00: one character 0, 1 or 2
    (0x00, b""),
    (0x00, b"3"),
    (0x00, b"9"),
    (0x00, b"01"),
    (0x00, b"a"),
    (0x00, b" "),
    (0x00, b"1\n"),
    (0x00, "1"),
    (0x00, 1),
    # 01: six decimal digits
    (0x01, b""),
    (0x01, b"00500"),
    (0x01, b"0005000"),
    (0x01, b"00050A"),
    (0x01, b"+00500"),
    (0x01, b"-00500"),
    (0x01, b" 00500"),
    (0x01, b"0005.0"),
    (0x01, b"000_50"),
    (0x01, b"\xb0\xb0\xb0\xb5\xb0\xb0"),
    (0x01, "000500"),
    # 02: sixteen hex digits
    (0x02, b""),
    (0x02, b"00000000000000D"),
    (0x02, b"0000000000000000D"),
    (0x02, b"000000000000000G"),
    (0x02, b"0x0000000000000D"),
    (0x02, b" 000000000000000"),
    (0x02, b"000000000000_00D"),
    # 06: a parameter code, letter F/A/B/C/H/P and three digits
    (0x06, b""),
    (0x06, b"A04"),
    (0x06, b"A0044"),
    (0x06, b"G004"),
    (0x06, b"D004"),
    (0x06, b"0004"),
    (0x06, b"AA04"),
    (0x06, b"A00X"),
    (0x06, b"A 04"),
    (0x06, b"\xc1004"),
    (0x06, "A004"),
    # 07: code and eight decimal digits
    (0x07, b""),
    (0x07, b"A004"),
    (0x07, b"A0040000050"),
    (0x07, b"A004000005000"),
    (0x07, b"A004-0000050"),
    (0x07, b"A004+0000050"),
    (0x07, b"A00400000 50"),
    (0x07, b"A0040000005A"),
    (0x07, b"G00400000500"),
    (0x07, b"A0A400000500"),
    (0x07, b"00000500A004"),
    # no data for the others
    *((c, b"0") for c in (0x03, 0x04, 0x05, 0x08, 0x09, 0x0A, 0x0B)),
    *((c, b"00") for c in (0x03, 0x04, 0x05, 0x08, 0x09, 0x0A, 0x0B)),
]


@pytest.mark.parametrize(("command", "data"), BAD_DATA)
def test_refuses_bad_data(command: int, data: Any) -> None:
    assert_refused(1, command, data)


@pytest.mark.parametrize("data", [b"0", b"1", b"2"])
def test_run_accepts_exactly_0_1_2(data: bytes) -> None:
    assert encode_request(1, 0x00, data) == reference_frame(b"01", b"00", data)


@pytest.mark.parametrize("data", [b"000000", b"000500", b"040000", b"999999"])
def test_set_frequency_accepts_six_digits(data: bytes) -> None:
    assert encode_request(1, 0x01, data) == reference_frame(b"01", b"01", data)


@pytest.mark.parametrize("bit", UNASSIGNED_TERMINAL_BITS)
def test_set_terminals_refuses_unassigned_bit(bit: int) -> None:
    assert_refused(1, 0x02, b"%016X" % (1 << bit))
    # also hidden among assigned bits
    assert_refused(1, 0x02, b"%016X" % ((1 << bit) | 0xD))


@pytest.mark.parametrize("bit", ASSIGNED_TERMINAL_BITS)
def test_set_terminals_accepts_assigned_bit(bit: int) -> None:
    data = b"%016X" % (1 << bit)
    assert encode_request(1, 0x02, data) == reference_frame(b"01", b"02", data)


def test_set_terminals_accepts_every_assigned_bit_at_once() -> None:
    mask = sum(1 << b for b in ASSIGNED_TERMINAL_BITS)
    data = b"%016X" % mask
    assert encode_request(1, 0x02, data) == reference_frame(b"01", b"02", data)


def test_set_terminals_lower_case_hex_is_sent_upper_case() -> None:
    frame = encode_request(1, 0x02, b"000000000000000d")
    assert frame == reference_frame(b"01", b"02", b"000000000000000D")


@pytest.mark.parametrize("group", "FABCHP")
def test_read_parameter_accepts_every_group_letter(group: str) -> None:
    code = group.encode() + b"001"
    assert encode_request(1, 0x06, code) == reference_frame(b"01", b"06", code)


@pytest.mark.parametrize("group", "fabchp")
def test_lower_case_parameter_code_is_sent_upper_case(group: str) -> None:
    code = group.encode() + b"084"
    upper = code.upper()
    assert encode_request(1, 0x06, code) == reference_frame(b"01", b"06", upper)
    assert encode_request(1, 0x07, code + b"00000001") == reference_frame(
        b"01", b"07", upper + b"00000001"
    )


def test_b084_lower_case_via_builders() -> None:
    assert requests.read_parameter(1, "b084").data == b"B084"
    assert requests.write_parameter_raw(1, "b084", 1).data == b"B08400000001"
    assert requests.write_parameter(1, "b084", 2).frame == reference_frame(
        b"01", b"07", b"B08400000002"
    )


def test_bytearray_data_is_accepted() -> None:
    data = bytearray(b"000500")  # typed as bytes; a bytearray is accepted at run time
    assert encode_request(1, 0x01, data) == encode_request(1, 0x01, b"000500")  # type: ignore[arg-type]


# -- typed builders: run ----------------------------------------------------


@pytest.mark.parametrize(
    ("direction", "data"),
    [(Direction.STOP, b"0"), (Direction.FORWARD, b"1"), (Direction.REVERSE, b"2"), (2, b"2")],
)
def test_run_builder(direction: int, data: bytes) -> None:
    request = requests.run(3, direction)
    assert request.command is Command.RUN
    assert request.frame == reference_frame(b"03", b"00", data)


@pytest.mark.parametrize("direction", [3, -1, 10, "1", None])
def test_run_builder_refuses_unknown_direction(direction: Any) -> None:
    with pytest.raises(LocalProtocolError):
        requests.run(1, direction)


# -- typed builders: set_frequency ------------------------------------------


@pytest.mark.parametrize(
    ("hz", "data"),
    [
        (0, b"000000"),
        (0.0, b"000000"),
        (0.01, b"000001"),
        (5.0, b"000500"),
        (50.01, b"005001"),
        (60, b"006000"),
        (123.45, b"012345"),
        (399.99, b"039999"),
        (400.0, b"040000"),
        (9999.99, b"999999"),
    ],
)
def test_set_frequency_scales_hz_by_100(hz: float, data: bytes) -> None:
    request = requests.set_frequency(1, hz)
    assert request.command is Command.SET_FREQUENCY
    assert request.frame == reference_frame(b"01", b"01", data)


@pytest.mark.parametrize(
    "hz",
    [
        -0.01,
        -1,
        10000.0,
        9999.995,
        5.001,
        0.005,
        123.456,
        math.nan,
        math.inf,
        -math.inf,
        True,
        False,
        "5",
        None,
    ],
)
def test_set_frequency_refuses(hz: Any) -> None:
    with pytest.raises(LocalProtocolError):
        requests.set_frequency(1, hz)


def test_set_frequency_max_hz_limit() -> None:
    assert requests.set_frequency(1, 60.0, max_hz=60.0).data == b"006000"
    with pytest.raises(LocalProtocolError):
        requests.set_frequency(1, 60.01, max_hz=60.0)


def test_set_frequency_broadcast() -> None:
    assert requests.set_frequency(BROADCAST, 5.0).frame == reference_frame(b"FF", b"01", b"000500")


# -- typed builders: set_terminals ------------------------------------------


def test_set_terminals_builder() -> None:
    assert requests.set_terminals(1, 0).data == b"0" * 16
    assert requests.set_terminals(1, InputTerminal.STAT).data == b"0001000000000000"
    assert requests.set_terminals(1, InputTerminal.OPE | InputTerminal.RS).data == (
        b"0000000080040000"
    )


@pytest.mark.parametrize("mask", [1 << 10, 1 << 19, 1 << 63, 1 << 64, -1, True, "1", 1.0])
def test_set_terminals_builder_refuses(mask: Any) -> None:
    with pytest.raises(LocalProtocolError):
        requests.set_terminals(1, mask)


# -- typed builders: the argument-less reads and actions ---------------------


@pytest.mark.parametrize(
    ("builder", "command"),
    [
        (requests.read_monitor, b"03"),
        (requests.read_status, b"04"),
        (requests.read_trip_history, b"05"),
        (requests.initialize, b"08"),
        (requests.can_store, b"09"),
        (requests.store, b"0A"),
        (requests.recalculate, b"0B"),
    ],
)
def test_no_data_builders(builder: Any, command: bytes) -> None:
    assert builder(12).frame == reference_frame(b"12", command, b"")


@pytest.mark.parametrize(
    "builder",
    [
        requests.read_monitor,
        requests.read_status,
        requests.read_trip_history,
        requests.can_store,
        requests.recalculate,
    ],
)
def test_no_data_builders_refuse_broadcast(builder: Any) -> None:
    with pytest.raises(LocalProtocolError):
        builder(BROADCAST)


@pytest.mark.parametrize("builder", [requests.initialize, requests.store])
def test_no_data_builders_allow_broadcast(builder: Any) -> None:
    request = builder(BROADCAST)
    assert request.is_broadcast
    assert request.frame[1:3] == b"FF"


def test_read_parameter_refuses_broadcast() -> None:
    with pytest.raises(LocalProtocolError):
        requests.read_parameter(BROADCAST, "A004")


@pytest.mark.parametrize(
    "code", ["", "A04", "A0044", "G004", "a0x4", " A004", "A004 ", "\u0660\u0660\u0660\u0660"]
)
def test_read_parameter_refuses_bad_code(code: str) -> None:
    with pytest.raises(LocalProtocolError):
        requests.read_parameter(1, code)


# -- typed builders: write_parameter ----------------------------------------


@pytest.mark.parametrize(
    ("code", "value", "data"),
    [
        ("F002", 10.0, b"F00200001000"),  # x 100 (SJ700: F002 = 30.00 s -> 3000)
        ("F002", 30.00, b"F00200003000"),
        ("A004", 50.0, b"A00400000500"),  # x 10
        ("A999", 1.5, b"A99900000015"),  # unknown code: default x 10
        ("P123", 0, b"P12300000000"),
        ("h999", 123.4, b"H99900001234"),
    ],
)
def test_write_parameter_scales_per_catalogue(code: str, value: float, data: bytes) -> None:
    request = requests.write_parameter(1, code, value)
    assert request.command is Command.WRITE_PARAMETER
    assert request.frame == reference_frame(b"01", b"07", data)


@pytest.mark.parametrize("code", sorted(PARAMETERS))
def test_write_parameter_uses_the_catalogue_scale(code: str) -> None:
    info = PARAMETERS[code]
    value = info.maximum
    raw = round(value * info.scale)
    assert requests.write_parameter(1, code, value) == requests.write_parameter_raw(1, code, raw)


@pytest.mark.parametrize(
    ("code", "value"),
    [
        ("F002", 10.001),  # finer than 0.01 s
        ("A004", 50.05),  # finer than 0.1 Hz
        ("A004", 500.0),  # above the catalogue's maximum
        ("A999", 1.55),  # unknown code: finer than x 10 allows
        ("A999", -1),
        ("A999", 10_000_000.0),  # x 10 no longer fits eight digits
        ("A999", math.nan),
        ("A999", math.inf),
        ("A999", True),
        ("A999", "1"),
        ("X004", 1),
    ],
)
def test_write_parameter_refuses(code: str, value: Any) -> None:
    with pytest.raises(LocalProtocolError):
        requests.write_parameter(1, code, value)


@pytest.mark.parametrize(("raw", "digits"), [(0, b"00000000"), (99_999_999, b"99999999")])
def test_write_parameter_raw_range_ends(raw: int, digits: bytes) -> None:
    assert requests.write_parameter_raw(1, "C078", raw).data == b"C078" + digits


@pytest.mark.parametrize("raw", [-1, 100_000_000, 1.0, True, "1", None])
def test_write_parameter_raw_refuses(raw: Any) -> None:
    with pytest.raises(LocalProtocolError):
        requests.write_parameter_raw(1, "C078", raw)


def test_write_parameter_broadcast() -> None:
    request = requests.write_parameter_raw(BROADCAST, "B084", 1)
    assert request.frame == reference_frame(b"FF", b"07", b"B08400000001")


# -- motor capacity codes (H003 / H203) ---------------------------------------

_US = {0: 0.2, 2: 0.4, 4: 0.75, 6: 1.5, 7: 2.2, 9: 3.7}
_EU = {0: 0.2, 1: 0.37, 3: 0.55, 4: 0.75, 5: 1.1, 6: 1.5, 7: 2.2, 8: 3.0, 10: 4.0}
_BOTH = dict(zip(range(11, 22), (5.5, 7.5, 11, 15, 18.5, 22, 30, 37, 45, 55, 75), strict=True))


@pytest.mark.parametrize("country", [0, 1, 2])
@pytest.mark.parametrize("code", range(22))
def test_motor_capacity_table(code: int, country: int) -> None:
    table = (_EU if country == 1 else _US) | _BOTH
    assert motor_capacity_kw(code, country) == table.get(code)


@pytest.mark.parametrize("code", [-1, 22, 99])
def test_motor_capacity_unknown_code(code: int) -> None:
    assert motor_capacity_kw(code) is None
