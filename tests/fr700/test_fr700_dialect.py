"""The FR-700 dialect: which reply answers which request, refusals, retries, timing, answers."""

from __future__ import annotations

import pickle

import pytest

from sj300_async import LocalProtocolError, NakError, RemoteProtocolError, ReplyTimeoutError
from sj300_async.fr700 import (
    Fr700Ack,
    Fr700Data,
    Fr700Dialect,
    Fr700Nak,
    Fr700NakCode,
    Fr700Reply,
    Fr700Request,
    requests,
)
from sj300_async.sj300._dialect import SJ300_DIALECT
from sj300_async.wire import BadFrame, BadFrameReason

DIALECT = Fr700Dialect()
READ_STATUS = requests.read(3, 0x7A)  # 2-digit reply
READ_RAW = requests.read(3, 0x7C)  # unknown width
WRITE = requests.set_frequency(3, 50)
MULTI = requests.multi_command(3, 2, 50, receive=1)


@pytest.mark.parametrize(
    ("request_", "event", "answers"),
    [
        (READ_STATUS, Fr700Data(3, b"4B"), True),
        (READ_STATUS, Fr700Data(3, b"004B"), False),  # wrong width for H7A
        (READ_STATUS, Fr700Data(4, b"4B"), False),  # another station
        (READ_STATUS, Fr700Ack(3), False),  # a read is not answered by ACK
        (READ_STATUS, Fr700Nak(3, Fr700NakCode.SUM_CHECK), True),
        (READ_RAW, Fr700Data(3, b"FR-A740-0.4K-NA     "), True),  # any width
        (WRITE, Fr700Ack(3), True),
        (WRITE, Fr700Ack(2), False),
        (WRITE, Fr700Data(3, b"1388"), False),
        (WRITE, Fr700Nak(3, Fr700NakCode.DATA_RANGE), True),
        (MULTI, Fr700Data(3, b"01FF004B0BB8"), True),
        (MULTI, Fr700Data(3, b"00FF004B0BB8"), False),  # other receive type: not ours
        (MULTI, Fr700Data(3, b"01FF004B"), False),
        (MULTI, Fr700Ack(3), False),
    ],
)
def test_answers(request_: Fr700Request, event: Fr700Reply, answers: bool) -> None:
    assert DIALECT.answers(request_, event) is answers


def test_a_nak_is_a_typed_refusal() -> None:
    with pytest.raises(NakError) as refused:
        DIALECT.accept(WRITE, Fr700Nak(3, Fr700NakCode.MODE))
    error = refused.value
    assert (error.node, error.code) == (3, Fr700NakCode.MODE)
    assert str(error) == "station 03 answered NAK A (mode error)"
    copy = pickle.loads(pickle.dumps(error))
    assert (copy.node, copy.code, str(copy)) == (3, Fr700NakCode.MODE, str(error))


def test_a_positive_reply_gives_its_data() -> None:
    assert DIALECT.accept(WRITE, Fr700Ack(3)) == b""
    assert DIALECT.accept(READ_STATUS, Fr700Data(3, b"4B")) == b"4B"


@pytest.mark.parametrize(
    ("code", "retry"),
    [
        (0x0, False),
        (0x1, True),
        (0x2, True),
        (0x3, True),
        (0x4, True),
        (0x5, True),
        (0x7, True),
        (0xA, False),
        (0xB, False),
        (0xC, False),
    ],
)
def test_transmission_errors_are_retried_verdicts_are_not(code: int, retry: bool) -> None:
    assert DIALECT.retryable(NakError(1, Fr700NakCode(code))) is retry


def test_other_errors_are_retried() -> None:
    assert DIALECT.retryable(ReplyTimeoutError("x"))
    assert DIALECT.retryable(RemoteProtocolError("x"))


def test_processing_time_per_the_reference() -> None:
    assert DIALECT.processing_s(READ_STATUS) == pytest.approx(0.012)
    assert DIALECT.processing_s(requests.read_parameter(1, 7)) == pytest.approx(0.030)
    assert DIALECT.processing_s(requests.set_frequency(1, 5, eeprom=True)) == pytest.approx(0.030)
    assert DIALECT.processing_s(requests.write(1, 0xFC, 0x9696)) == pytest.approx(5.0)
    waiting = Fr700Dialect(wait_time_digit=3)
    assert waiting.processing_s(READ_STATUS) == pytest.approx(0.042)


def test_reply_lengths_cover_the_longest_answer() -> None:
    assert DIALECT.reply_frame_length(READ_STATUS) == len(b"\x0203" + b"4B" + b"\x03XX\r")
    assert DIALECT.reply_frame_length(WRITE) == len(b"\x1503A\r")  # a NAK is longer than ACK
    assert DIALECT.reply_frame_length(READ_RAW) == 1 + 2 + 20 + 1 + 2 + 1
    assert Fr700Dialect(terminator="\r\n").reply_frame_length(MULTI) == 1 + 2 + 12 + 1 + 2 + 2


def test_acknowledgement_only_when_configured_and_only_after_data() -> None:
    assert DIALECT.acknowledgement(READ_STATUS, Fr700Data(3, b"4B")) is None
    acking = Fr700Dialect(send_ack=True, terminator="")
    assert acking.acknowledgement(READ_STATUS, Fr700Data(3, b"4B")) == b"\x0603"
    assert acking.acknowledgement(WRITE, Fr700Ack(3)) is None
    assert acking.answer_delay_s() == acking.rest_after_acknowledgement_s() == 0.010


def test_reoutput_request_for_a_damaged_data_reply() -> None:
    bad = BadFrame(BadFrameReason.BAD_BCC, b"\x020311\x0300", 3)
    assert DIALECT.reoutput_request(READ_STATUS, bad) == b"\x1503\r"
    assert DIALECT.reoutput_request(MULTI, bad) == b"\x1503\r"
    unreadable = BadFrame(BadFrameReason.BAD_BCC, b"\x02xx11\x0300", None)
    assert DIALECT.reoutput_request(READ_STATUS, unreadable) == b"\x1503\r"
    # not for a write, another station, an ACK/NAK frame, or when switched off
    assert DIALECT.reoutput_request(WRITE, bad) is None
    assert (
        DIALECT.reoutput_request(READ_STATUS, BadFrame(BadFrameReason.BAD_BCC, b"\x02", 4)) is None
    )
    assert (
        DIALECT.reoutput_request(READ_STATUS, BadFrame(BadFrameReason.BAD_NODE, b"\x06p3")) is None
    )
    assert Fr700Dialect(request_reoutput=False).reoutput_request(READ_STATUS, bad) is None


def test_sj300_dialect_has_no_host_answers() -> None:
    assert SJ300_DIALECT.answer_delay_s() == 0.0
    # any request at all: the SJ300 never asks for a reply again
    anything = object()
    bad = BadFrame(BadFrameReason.BAD_BCC, b"")
    assert SJ300_DIALECT.reoutput_request(anything, bad) is None  # type: ignore[arg-type]


def test_replies_are_described_for_traces() -> None:
    assert DIALECT.describe(Fr700Ack(3)) == "station 03 ACK"
    assert DIALECT.describe(Fr700Nak(3, Fr700NakCode.MODE)) == "station 03 NAK A (mode error)"
    assert DIALECT.describe(Fr700Data(3, b"1770")) == "station 03 data 1770"


def test_options_are_validated() -> None:
    with pytest.raises(LocalProtocolError):
        Fr700Dialect(terminator="\n")
    with pytest.raises(LocalProtocolError):
        Fr700Dialect(wait_time_digit=16)
    assert "send_ack=True" in repr(Fr700Dialect(send_ack=True))
