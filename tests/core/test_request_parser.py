"""RequestParser (the drive's side): reads requests back, and reports bad ones as a drive would."""

from __future__ import annotations

from functools import reduce
from operator import xor

import pytest

from sj300_async import InputTerminal, NakCode
from sj300_async.sj300 import (
    BROADCAST,
    NAK_FOR_BAD_REQUEST,
    Command,
    Request,
    RequestParser,
    requests,
)
from sj300_async.wire import BadFrame, BadFrameReason

STX = b"\x02"
CR = b"\r"


def check(body: bytes) -> bytes:
    return b"%02X" % reduce(xor, body, 0)


def frame(body: bytes) -> bytes:
    return STX + body + check(body) + CR


EXAMPLES = [
    requests.run(1, 1),
    requests.run(BROADCAST, 0),
    requests.set_frequency(1, 5.0),
    requests.set_terminals(1, InputTerminal.FW | InputTerminal.CF1 | InputTerminal.CF2),
    requests.set_terminals(BROADCAST, InputTerminal.STAT | InputTerminal.FW),
    requests.read_monitor(2),
    requests.read_status(3),
    requests.read_trip_history(4),
    requests.read_parameter(5, "A004"),
    requests.write_parameter_raw(6, "C078", 40),
    requests.write_parameter(BROADCAST, "F002", 30.0),
    requests.initialize(7),
    requests.can_store(8),
    requests.store(9),
    requests.recalculate(32),
]


@pytest.mark.parametrize(
    "request_", EXAMPLES, ids=[f"{r.command.name}-{r.node:02X}" for r in EXAMPLES]
)
def test_reads_back_every_command(request_: Request) -> None:
    parser = RequestParser()
    assert parser.feed(request_.frame) == [request_]
    assert parser.buffered == 0


def test_reads_back_the_worked_examples() -> None:
    stream = (
        bytes.fromhex("02 30 31 30 30 31 33 30 0D")
        + bytes.fromhex("02 30 31 30 31 30 30 30 35 30 30 30 35 0D")
        + b"\x020102000000000000000D77\r"
    )
    events = RequestParser().feed(stream)
    assert [(r.node, r.command, r.data) for r in events if isinstance(r, Request)] == [
        (1, Command.RUN, b"1"),
        (1, Command.SET_FREQUENCY, b"000500"),
        (1, Command.SET_TERMINALS, b"000000000000000D"),
    ]


def test_longest_requests_fit() -> None:
    # 02 carries 16 data characters, 07 twelve: both must fit the parser's frame limit.
    for body in (b"0102" + b"0001FFFFFFFFFFFF", b"0107" + b"A00400000500"):
        events = RequestParser().feed(frame(body))
        assert [type(e) for e in events] == [Request], events


def test_lower_case_bcc_is_accepted() -> None:
    body = b"0101000509"
    upper = check(body)
    assert upper == b"0C"
    (event,) = RequestParser().feed(STX + body + upper.lower() + CR)
    assert event == Request(1, Command.SET_FREQUENCY, b"000509", STX + body + upper.lower() + CR)


def test_bad_bcc_gets_nak_02() -> None:
    body = b"0104"
    (event,) = RequestParser().feed(STX + body + b"00" + CR)
    assert event == BadFrame(BadFrameReason.BAD_BCC, body + b"00", node=1)
    assert NAK_FOR_BAD_REQUEST[BadFrameReason.BAD_BCC] is NakCode.CHECKSUM


@pytest.mark.parametrize("command", [b"0C", b"0F", b"10", b"99", b"0a", b"XX"])
def test_unknown_command_gets_nak_11(command: bytes) -> None:
    body = b"01" + command
    (event,) = RequestParser().feed(frame(body))
    assert event == BadFrame(BadFrameReason.BAD_COMMAND, body + check(body), node=1)
    assert NAK_FOR_BAD_REQUEST[BadFrameReason.BAD_COMMAND] is NakCode.ABNORMAL_COMMAND


@pytest.mark.parametrize("node", [b"00", b"33", b"0A", b"ff", b"  "])
def test_unreadable_node_gets_no_answer(node: bytes) -> None:
    body = node + b"04"
    (event,) = RequestParser().feed(frame(body))
    assert isinstance(event, BadFrame)
    assert event.reason is BadFrameReason.BAD_NODE
    assert NAK_FOR_BAD_REQUEST[BadFrameReason.BAD_NODE] is None


def test_broadcast_node_is_read() -> None:
    (event,) = RequestParser().feed(frame(b"FF08"))
    assert isinstance(event, Request)
    assert event.node == BROADCAST
    assert event.is_broadcast


@pytest.mark.parametrize(
    "body", [b"0100", b"010012", b"010100050", b"0104" + b"0", b"0106A04", b"0107A0040000050"]
)
def test_wrong_data_length(body: bytes) -> None:
    (event,) = RequestParser().feed(frame(body))
    assert event == BadFrame(BadFrameReason.BAD_LENGTH, body + check(body), node=1)
    assert NAK_FOR_BAD_REQUEST[BadFrameReason.BAD_LENGTH] is not None


@pytest.mark.parametrize("body", [b"0100A", b"01010005A0", b"01020000000000000G0D", b"01060A04"])
def test_wrong_characters(body: bytes) -> None:
    (event,) = RequestParser().feed(frame(body))
    assert event == BadFrame(BadFrameReason.BAD_CHARACTERS, body + check(body), node=1)
    assert NAK_FOR_BAD_REQUEST[BadFrameReason.BAD_CHARACTERS] is not None
