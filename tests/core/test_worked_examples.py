"""The worked examples of the protocol reference (docs: sj300.md, "Frame layout"), byte for byte."""

from __future__ import annotations

import re

import pytest

from sj300_async import InputTerminal
from sj300_async.sj300 import (
    AckReply,
    Command,
    ReplyParser,
    bcc,
    encode_reply,
    encode_request,
    requests,
)


def hex_bytes(spaced: str) -> bytes:
    """``"02 30 31"`` -> ``b"\\x02\\x30\\x31"``, as the reference writes frames."""
    return bytes.fromhex(spaced)


def test_run_forward_node_01() -> None:
    # `01` `00` `1` -> XOR = 0x30 -> BCC `30`
    assert bcc(b"01001") == b"30"
    assert encode_request(1, Command.RUN, b"1") == hex_bytes("02 30 31 30 30 31 33 30 0D")


def test_run_forward_via_builder() -> None:
    assert requests.run(1, 1).frame == hex_bytes("02 30 31 30 30 31 33 30 0D")


def test_set_frequency_5_hz_node_01() -> None:
    # `01` `01` `000500` -> BCC `05`
    assert bcc(b"0101000500") == b"05"
    expected = hex_bytes("02 30 31 30 31 30 30 30 35 30 30 30 35 0D")
    assert encode_request(1, Command.SET_FREQUENCY, b"000500") == expected
    assert encode_request(1, 0x01, b"000500") == expected


def test_set_frequency_5_hz_via_builder() -> None:
    request = requests.set_frequency(1, 5.00)
    assert request.frame == hex_bytes("02 30 31 30 31 30 30 30 35 30 30 30 35 0D")
    assert request.data == b"000500"


def test_positive_reply_node_01_encodes() -> None:
    # 0x30 ^ 0x31 ^ 0x06 = 0x07
    assert bcc(b"01\x06") == b"07"
    assert encode_reply(AckReply(1)) == hex_bytes("02 30 31 06 30 37 0D")


def test_positive_reply_node_01_parses() -> None:
    parser = ReplyParser()
    assert parser.feed(hex_bytes("02 30 31 06 30 37 0D")) == [AckReply(1)]
    assert parser.buffered == 0


def test_set_terminals_fw_cf1_cf2() -> None:
    # `01` `02` `000000000000000D` (FW + CF1 + CF2) -> BCC `77`
    assert bcc(b"0102000000000000000D") == b"77"
    expected = b"\x02" + b"0102" + b"000000000000000D" + b"77" + b"\r"
    assert encode_request(1, Command.SET_TERMINALS, b"000000000000000D") == expected


def test_set_terminals_fw_cf1_cf2_via_builder() -> None:
    flags = InputTerminal.FW | InputTerminal.CF1 | InputTerminal.CF2
    assert int(flags) == 0xD
    request = requests.set_terminals(1, flags)
    assert request.data == b"000000000000000D"
    assert request.frame == b"\x020102000000000000000D77\r"


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (b"", b"00"),
        (b"\x0a", b"0A"),
        (b"\xff", b"FF"),
        (b"\x0f\xf0", b"FF"),
        (b"\xab", b"AB"),
        (b"01\x15", b"14"),
        (b"A004", b"75"),
    ],
)
def test_bcc_is_two_upper_case_hex_characters(body: bytes, expected: bytes) -> None:
    result = bcc(body)
    assert result == expected
    assert re.fullmatch(rb"[0-9A-F]{2}", result)
