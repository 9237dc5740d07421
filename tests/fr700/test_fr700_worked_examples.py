"""The manual's examples and every frame format, byte by byte from the reference."""

from __future__ import annotations

import pytest

from sj300_async.fr700 import (
    Fr700Ack,
    Fr700Data,
    Fr700LineOptions,
    Fr700MultiReceive,
    Fr700Nak,
    Fr700NakCode,
    Fr700Reply,
    Fr700ReplyParser,
    encode_ack,
    encode_data_reply,
    encode_host_ack,
    encode_nak,
    encode_reoutput_request,
    encode_request,
    requests,
    sum_check,
)
from sj300_async.fr700._codes import Fr700Instruction as I
from sj300_async.wire import BadFrame, BadFrameReason

from .fr700wire import ACK, CR, ENQ, ETX, LF, NAK, STX, data_reply, nak, ref_sum, request

WAIT_1 = Fr700LineOptions(wait_time_digit=1)


# -- the manual's sum-check examples ---------------------------------------------------------


def test_manual_request_example_sums_to_f4() -> None:
    # ENQ 01 E1 1 07AD -> 0x30+0x31+0x45+0x31+0x31+0x30+0x37+0x41+0x44 = 0x1F4 -> "F4"
    assert sum(b"01E1107AD") == 0x1F4
    assert sum_check(b"01E1107AD") == b"F4"
    assert encode_request(1, 0xE1, b"07AD", options=WAIT_1) == b"\x0501E1107ADF4\r"


def test_manual_reply_example_sums_to_30() -> None:
    # STX 01 1770 ETX -> sum of "011770" = 0x130 -> "30"
    assert sum(b"011770") == 0x130
    assert sum_check(b"011770") == b"30"
    assert encode_data_reply(1, b"1770") == b"\x02011770\x0330\r"
    assert Fr700ReplyParser().feed(b"\x02011770\x0330\r") == [Fr700Data(1, b"1770")]


def test_manual_reply_example_decodes_as_60_hz() -> None:
    assert int(b"1770", 16) / 100 == 60.0


# -- requests, format by format ------------------------------------------------------------------


def test_format_b_read() -> None:
    frame = requests.read(5, I.STATUS).frame
    assert frame == ENQ + b"057A0" + ref_sum(b"057A0") + CR
    assert frame == request(5, 0x7A)


def test_format_a_write_four_digits() -> None:
    frame = requests.set_frequency(31, 60.0).frame
    assert frame == ENQ + b"1FED0" + b"1770" + ref_sum(b"1FED01770") + CR
    assert frame == request(31, 0xED, b"1770")


def test_format_a1_write_two_digits() -> None:
    frame = requests.run(0, 1).frame  # forward
    assert frame == ENQ + b"00FA0" + b"02" + ref_sum(b"00FA002") + CR


def test_format_a2_multi_command() -> None:
    frame = requests.multi_command(2, 0x0002, 50.0, receive=Fr700MultiReceive.OUTPUT_CURRENT).frame
    body = b"02F0" + b"0" + b"0" + b"1" + b"0002" + b"1388"
    assert frame == ENQ + body + ref_sum(body) + CR
    assert len(frame) == 1 + 2 + 2 + 1 + 1 + 1 + 4 + 4 + 2 + 1


def test_inverter_reset_carries_9696() -> None:
    request_ = requests.reset(3)
    assert request_.frame == request(3, 0xFD, b"9696")
    assert not request_.expects_reply


@pytest.mark.parametrize(
    ("options", "suffix"),
    [
        (Fr700LineOptions(terminator=b""), b""),
        (Fr700LineOptions(terminator=b"\r"), CR),
        (Fr700LineOptions(terminator=b"\r\n"), CR + LF),
    ],
)
def test_terminator_is_a_line_option(options: Fr700LineOptions, suffix: bytes) -> None:
    frame = requests.read(1, I.OUTPUT_FREQUENCY, options=options).frame
    assert frame == ENQ + b"016F0" + ref_sum(b"016F0") + suffix


def test_without_the_waiting_time_field_a_request_is_one_character_shorter() -> None:
    with_field = requests.read(1, I.STATUS).frame
    without = requests.read(1, I.STATUS, options=Fr700LineOptions(wait_field=False)).frame
    assert without == ENQ + b"017A" + ref_sum(b"017A") + CR
    assert len(without) == len(with_field) - 1


def test_waiting_time_digit_is_hex() -> None:
    options = Fr700LineOptions(wait_time_digit=15)
    assert requests.read(1, I.STATUS, options=options).frame == request(1, 0x7A, wait=b"F")


# -- replies, format by format ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("wire", "event"),
    [
        (ACK + b"07" + CR, Fr700Ack(7)),  # C
        (NAK + b"1F" + b"A" + CR, Fr700Nak(31, Fr700NakCode.MODE)),  # D
        (data_reply(3, b"1770"), Fr700Data(3, b"1770")),  # E
        (data_reply(3, b"4B"), Fr700Data(3, b"4B")),  # E1
        (data_reply(3, b"012345"), Fr700Data(3, b"012345")),  # E2
        (data_reply(3, b"FR-A740-0.4K-NA     "), Fr700Data(3, b"FR-A740-0.4K-NA     ")),  # E3
        (data_reply(3, b"01FF004B0BB8"), Fr700Data(3, b"01FF004B0BB8")),  # C1
    ],
)
def test_reply_formats_parse(wire: bytes, event: Fr700Reply) -> None:
    assert Fr700ReplyParser().feed(wire) == [event]


def test_reply_encoders_match_the_reference() -> None:
    assert encode_ack(7) == ACK + b"07" + CR
    assert encode_nak(31, Fr700NakCode.DATA_RANGE) == NAK + b"1FC" + CR
    assert encode_data_reply(0, b"4B", b"") == STX + b"004B" + ETX + ref_sum(b"004B")
    assert encode_host_ack(2, b"\r\n") == ACK + b"02" + CR + LF  # format C from the host
    assert encode_reoutput_request(2) == NAK + b"02" + CR  # format F


@pytest.mark.parametrize("code", list("0123457ABCF"))
def test_every_listed_nak_code_parses(code: str) -> None:
    (event,) = Fr700ReplyParser().feed(nak(4, code.encode()))
    assert event == Fr700Nak(4, Fr700NakCode(int(code, 16)))
    assert isinstance(event, Fr700Nak)
    assert event.code.known


def test_nak_codes_say_what_they_mean() -> None:
    assert Fr700NakCode.SUM_CHECK.description == "sum check error"
    assert Fr700NakCode(0x6).name == "UNKNOWN_6"
    transmission = {c for c in Fr700NakCode if c.is_transmission_error}
    assert transmission == {
        Fr700NakCode.PARITY,
        Fr700NakCode.SUM_CHECK,
        Fr700NakCode.PROTOCOL,
        Fr700NakCode.FRAMING,
        Fr700NakCode.OVERRUN,
        Fr700NakCode.CHARACTER,
    }


def test_a_reply_with_a_wrong_sum_is_a_bad_frame_naming_its_station() -> None:
    (event,) = Fr700ReplyParser().feed(STX + b"011770" + ETX + b"31" + CR)
    assert event == BadFrame(BadFrameReason.BAD_BCC, STX + b"011770" + ETX + b"31", 1)
