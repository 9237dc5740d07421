"""Validation: every encoder refuses what the protocol does not allow, before producing a byte."""

from __future__ import annotations

import math

import pytest

from sj300_async import Direction, LocalProtocolError
from sj300_async.fr700 import (
    Fr700LineOptions,
    Fr700MultiReceive,
    Fr700OperationMode,
    Fr700RequestKind,
    encode_data_reply,
    encode_nak,
    encode_request,
    requests,
)
from sj300_async.fr700._codes import Fr700Instruction as I


@pytest.mark.parametrize("station", [-1, 32, 255, True, 1.0, "1", None])
def test_station_must_be_0_to_31(station: object) -> None:
    with pytest.raises(LocalProtocolError, match="station"):
        encode_request(station, 0x7A)  # type: ignore[arg-type]


@pytest.mark.parametrize("station", [0, 31])
def test_station_limits_are_allowed(station: int) -> None:
    assert encode_request(station, 0x7A)[1:3] == b"%02X" % station


@pytest.mark.parametrize("code", [-1, 256, True, "7A", 1.5])
def test_instruction_must_be_two_hex_characters(code: object) -> None:
    with pytest.raises(LocalProtocolError, match="instruction"):
        encode_request(1, code)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("code", "data"),
    [
        (0x7A, b"00"),  # a read takes no data
        (0xED, b""),  # a write takes data
        (0xED, b"123"),  # 2 or 4 digits
        (0xED, b"12345"),
        (0xED, b"17a0"),  # upper case only
        (0xED, b"17G0"),
        (0xF0, b"0000020000"[:-1]),  # A2 is exactly 10
        (0xED, "1770"),  # bytes, not str
    ],
)
def test_data_widths_and_characters(code: int, data: object) -> None:
    with pytest.raises(LocalProtocolError):
        encode_request(1, code, data)  # type: ignore[arg-type]


def test_line_options_are_checked() -> None:
    with pytest.raises(LocalProtocolError, match="terminator"):
        Fr700LineOptions(terminator=b"\n")
    with pytest.raises(LocalProtocolError, match="wait_time_digit"):
        Fr700LineOptions(wait_time_digit=16)
    with pytest.raises(LocalProtocolError, match="wait_field"):
        Fr700LineOptions(wait_field=1)  # type: ignore[arg-type]
    assert Fr700LineOptions(terminator="\r\n").terminator == b"\r\n"  # type: ignore[arg-type]
    assert Fr700LineOptions(wait_time_digit=12).wait_s == pytest.approx(0.12)
    assert Fr700LineOptions(wait_field=False, wait_time_digit=12).wait_s == 0.0


def test_reads_and_writes_are_told_apart_by_the_code() -> None:
    with pytest.raises(LocalProtocolError, match="write code"):
        requests.read(1, 0xED)
    with pytest.raises(LocalProtocolError, match="read code"):
        requests.write(1, 0x6D, 0)
    with pytest.raises(LocalProtocolError, match="multi_command"):
        requests.write(1, 0xF0, 0)


@pytest.mark.parametrize(("text", "code"), [("H7A", 0x7A), ("7a", 0x7A), ("0xED", 0xED)])
def test_instruction_codes_as_text(text: str, code: int) -> None:
    assert requests.parse_instruction(text) == code


@pytest.mark.parametrize("text", ["7", "H7AA", "XY", "", "H"])
def test_bad_instruction_text(text: str) -> None:
    with pytest.raises(LocalProtocolError):
        requests.parse_instruction(text)


def test_write_widths_follow_the_instruction() -> None:
    assert requests.write(1, I.RUN_COMMAND, 2).data == b"02"  # A1
    assert requests.write(1, I.WRITE_LINK_EXTENSION, 1).data == b"01"  # A1
    assert requests.write(1, I.WRITE_OPERATION_MODE, 0).data == b"0000"  # A
    assert requests.write(1, 0xE5, 0x1234).data == b"1234"  # unknown: A
    assert requests.write(1, 0xE5, 0x12, digits=2).data == b"12"
    with pytest.raises(LocalProtocolError, match="2 hex digits"):
        requests.write(1, I.RUN_COMMAND, 0x100)
    with pytest.raises(LocalProtocolError, match="4 hex digits"):
        requests.write(1, 0xED, 0x10000)
    with pytest.raises(LocalProtocolError):
        requests.write(1, 0xED, -1)
    with pytest.raises(LocalProtocolError):
        requests.write(1, 0xED, 1, digits=3)
    with pytest.raises(LocalProtocolError):
        requests.write(1, 0xED, 1.0)  # type: ignore[arg-type]


def test_reset_is_a_request_without_reply() -> None:
    reset = requests.write(1, I.INVERTER_RESET, 0x9696)
    assert reset.kind is Fr700RequestKind.RESET
    assert not reset.expects_reply
    assert reset.mutating


@pytest.mark.parametrize("hz", [-0.01, 655.36, math.nan, math.inf, 1.001, True, "50"])
def test_frequency_is_checked(hz: object) -> None:
    with pytest.raises(LocalProtocolError, match="frequency"):
        requests.set_frequency(1, hz)  # type: ignore[arg-type]


def test_frequency_limits() -> None:
    assert requests.set_frequency(1, 0).data == b"0000"
    assert requests.set_frequency(1, 655.35).data == b"FFFF"
    assert requests.set_frequency(1, 60, eeprom=True).instruction == I.WRITE_SET_FREQUENCY_EEPROM


def test_run_directions() -> None:
    assert [requests.run(1, d).data for d in Direction] == [b"00", b"02", b"04"]
    with pytest.raises(LocalProtocolError, match="direction"):
        requests.run(1, 3)


def test_operation_mode_values() -> None:
    assert requests.write_operation_mode(1, Fr700OperationMode.PU).data == b"0002"
    with pytest.raises(LocalProtocolError, match="NETWORK"):
        requests.write_operation_mode(1, 7)
    with pytest.raises(LocalProtocolError):
        requests.write_operation_mode(1, "PU")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("number", "bank", "offset"),
    [
        (0, 0, 0),
        (99, 0, 99),
        (100, 1, 0),
        (123, 1, 23),
        (999, 9, 99),
        ("Pr.7", 0, 7),
        ("pr 340", 3, 40),
    ],
)
def test_parameter_bank_and_offset(number: int | str, bank: int, offset: int) -> None:
    assert requests.parameter_bank(number) == (bank, offset)


@pytest.mark.parametrize("number", [-1, 1000, "Pr.x", "", True, 7.0])
def test_bad_parameter_numbers(number: object) -> None:
    with pytest.raises(LocalProtocolError):
        requests.parameter_bank(number)  # type: ignore[arg-type]


def test_parameter_requests_address_the_offset() -> None:
    assert requests.read_parameter(1, 123).instruction == 23
    assert requests.write_parameter(1, 123, 5).instruction == 0x80 + 23
    assert requests.read_parameter(1, 123).reply_width == 4
    with pytest.raises(LocalProtocolError):
        requests.link_extension(1, 10)


def test_bank_switch_for_a_read_does_not_count_as_changing_the_drive() -> None:
    assert not requests.link_extension(1, 2, changes_drive=False).mutating
    assert requests.link_extension(1, 2).mutating
    assert not requests.read(1, 0x7A).mutating


def test_multi_command_is_checked() -> None:
    with pytest.raises(LocalProtocolError, match="run_bits"):
        requests.multi_command(1, 0x10000, 10)
    with pytest.raises(LocalProtocolError, match="receive"):
        requests.multi_command(1, 2, 10, receive=4)
    request = requests.multi_command(
        1, 2, 10, eeprom=True, receive=Fr700MultiReceive.SPECIAL_MONITOR
    )
    assert request.data == b"13" + b"0002" + b"03E8"
    assert request.reply_width == 12


def test_read_width_override_is_checked() -> None:
    assert requests.read(1, 0x7A).reply_width == 2
    assert requests.read(1, 0x7C).reply_width is None  # unknown: any width
    assert requests.read(1, 0x7C, reply_width=20).reply_width == 20
    for width in (0, 21, True):
        with pytest.raises(LocalProtocolError):
            requests.read(1, 0x7C, reply_width=width)


def test_reply_encoders_are_checked() -> None:
    with pytest.raises(LocalProtocolError):
        encode_data_reply(1, b"")
    with pytest.raises(LocalProtocolError):
        encode_data_reply(1, b"0" * 21)
    with pytest.raises(LocalProtocolError):
        encode_data_reply(1, b"\x03")
    with pytest.raises(LocalProtocolError):
        encode_nak(1, 16)


def test_request_labels_and_nodes() -> None:
    request = requests.read(9, 0x6F)
    assert (request.node, request.label, request.expects_reply) == (9, "instruction H6F", True)
