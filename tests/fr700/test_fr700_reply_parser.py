"""The reply parser, h11-style: every case fed whole, byte by byte, and with trailing data."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from sj300_async import LocalProtocolError
from sj300_async.fr700 import (
    MAX_FRAME,
    Fr700Ack,
    Fr700Data,
    Fr700Nak,
    Fr700NakCode,
    Fr700ParserEvent,
    Fr700ReplyParser,
)
from sj300_async.wire import BadFrame, BadFrameReason, Discarded, DiscardReason

from .fr700wire import ACK, CR, ETX, LF, NAK, STX, ack, data_reply, nak, ref_sum

TERMINATORS = [b"", CR, CR + LF]


def feed_whole(parser: Fr700ReplyParser, data: bytes) -> list[Fr700ParserEvent]:
    return parser.feed(data)


def feed_bytes(parser: Fr700ReplyParser, data: bytes) -> list[Fr700ParserEvent]:
    events: list[Fr700ParserEvent] = []
    for i in range(len(data)):
        events += parser.feed(data[i : i + 1])
    return events


def merged(events: list[Fr700ParserEvent]) -> list[Fr700ParserEvent]:
    """Runs of Discarded of one reason merged (a byte-by-byte feed splits garbage)."""
    out: list[Fr700ParserEvent] = []
    for event in events:
        if (
            isinstance(event, Discarded)
            and out
            and isinstance(out[-1], Discarded)
            and out[-1].reason is event.reason is DiscardReason.GARBAGE
        ):
            out[-1] = Discarded(event.reason, out[-1].data + event.data)
        else:
            out.append(event)
    return out


Feed = Callable[[Fr700ReplyParser, bytes], list[Fr700ParserEvent]]
FEEDS: list[Feed] = [feed_whole, feed_bytes]


@pytest.mark.parametrize("feed", FEEDS)
@pytest.mark.parametrize("term", TERMINATORS)
def test_every_reply_kind_in_every_terminator_mode(feed: Feed, term: bytes) -> None:
    stream = (
        ack(1, term)
        + nak(2, b"C", term)
        + data_reply(3, b"1770", term)
        + data_reply(4, b"4B", term)
    )
    parser = Fr700ReplyParser(term)
    assert feed(parser, stream) == [
        Fr700Ack(1),
        Fr700Nak(2, Fr700NakCode.DATA_RANGE),
        Fr700Data(3, b"1770"),
        Fr700Data(4, b"4B"),
    ]
    assert parser.buffered == 0
    assert parser.stats.frames == 4


@pytest.mark.parametrize("feed", FEEDS)
@pytest.mark.parametrize("term", TERMINATORS)
def test_trailing_partial_frame_is_held(feed: Feed, term: bytes) -> None:
    frame = data_reply(3, b"1770", term)
    parser = Fr700ReplyParser(term)
    assert feed(parser, frame + frame[:5]) == [Fr700Data(3, b"1770")]
    assert parser.buffered == 5
    assert feed(parser, frame[5:]) == [Fr700Data(3, b"1770")]
    assert parser.buffered == 0


@pytest.mark.parametrize("feed", FEEDS)
def test_data_replies_are_read_by_stx_etx_not_by_width(feed: Feed) -> None:
    for width in (1, 2, 4, 6, 12, 20):
        data = b"7" * width
        assert feed(Fr700ReplyParser(), data_reply(0, data)) == [Fr700Data(0, data)]
        assert feed(Fr700ReplyParser(b""), data_reply(0, data, b"")) == [Fr700Data(0, data)]


@pytest.mark.parametrize("feed", FEEDS)
def test_garbage_between_frames_is_discarded_and_counted(feed: Feed) -> None:
    parser = Fr700ReplyParser()
    events = merged(feed(parser, b"xyz" + ack(1) + b"\r\n" + ack(2)))
    assert events == [
        Discarded(DiscardReason.GARBAGE, b"xyz"),
        Fr700Ack(1),
        Discarded(DiscardReason.GARBAGE, b"\r\n"),
        Fr700Ack(2),
    ]
    assert parser.stats.discarded_bytes == 5


@pytest.mark.parametrize("feed", FEEDS)
def test_crlf_line_consumes_the_lf_and_tolerates_its_absence(feed: Feed) -> None:
    parser = Fr700ReplyParser(CR + LF)
    stream = ack(1, CR + LF) + ack(2, CR) + ack(3, CR + LF) + LF
    events = feed(parser, stream)
    assert events == [
        Fr700Ack(1),
        Fr700Ack(2),
        Fr700Ack(3),
        Discarded(DiscardReason.GARBAGE, LF),
    ]


@pytest.mark.parametrize("feed", FEEDS)
def test_a_start_byte_inside_a_frame_restarts(feed: Feed) -> None:
    parser = Fr700ReplyParser()
    stream = STX + b"0117" + ACK + b"05" + CR
    assert feed(parser, stream) == [
        Discarded(DiscardReason.RESTARTED, STX + b"0117"),
        Fr700Ack(5),
    ]
    assert parser.stats.restarted_frames == 1


@pytest.mark.parametrize("feed", FEEDS)
def test_a_start_byte_inside_a_fixed_length_frame_restarts(feed: Feed) -> None:
    parser = Fr700ReplyParser(b"")
    stream = NAK + b"0" + STX + b"011770" + ETX + b"30"
    assert feed(parser, stream) == [
        Discarded(DiscardReason.RESTARTED, NAK + b"0"),
        Fr700Data(1, b"1770"),
    ]


@pytest.mark.parametrize("feed", FEEDS)
@pytest.mark.parametrize("term", TERMINATORS)
def test_overlong_frames_are_cut_at_the_limit(feed: Feed, term: bytes) -> None:
    parser = Fr700ReplyParser(term)
    stream = STX + b"01" + b"7" * 40 + ETX + b"00" + term + ack(1, term)
    events = feed(parser, stream)
    assert isinstance(events[0], Discarded)
    assert events[0].reason is DiscardReason.OVERLONG
    assert events[-1] == Fr700Ack(1)
    assert parser.stats.overlong_frames == 1
    assert parser.buffered == 0


def test_buffer_never_exceeds_the_longest_frame() -> None:
    for term in TERMINATORS:
        parser = Fr700ReplyParser(term)
        for _ in range(200):
            parser.feed(STX + b"7")
            assert parser.buffered <= MAX_FRAME
        parser.feed(STX + b"7" * 1000)
        assert parser.buffered <= MAX_FRAME


@pytest.mark.parametrize(
    ("wire", "reason", "station"),
    [
        (STX + b"011770" + ETX + b"31" + CR, BadFrameReason.BAD_BCC, 1),
        (STX + b"011770" + ETX + b"3G" + CR, BadFrameReason.BAD_BCC, 1),
        (STX + b"201770" + ETX + ref_sum(b"201770") + CR, BadFrameReason.BAD_NODE, None),
        (STX + b"01\x7f\x7f" + ETX + ref_sum(b"01\x7f\x7f") + CR, BadFrameReason.BAD_CHARACTERS, 1),
        (STX + b"011770" + b"30" + CR, BadFrameReason.BAD_LENGTH, 1),  # no ETX
        (STX + b"01" + ETX + b"31" + CR, BadFrameReason.TOO_SHORT, 1),  # no data
        (ACK + b"0" + CR, BadFrameReason.BAD_LENGTH, None),
        (ACK + b"012" + CR, BadFrameReason.BAD_LENGTH, 1),
        (ACK + b"2G" + CR, BadFrameReason.BAD_NODE, None),
        (NAK + b"01" + CR, BadFrameReason.BAD_LENGTH, 1),
        (NAK + b"01" + b"Z" + CR, BadFrameReason.BAD_CHARACTERS, 1),
        (NAK + b"01" + b"a" + CR, BadFrameReason.BAD_CHARACTERS, 1),  # upper case only
        (ACK + b"0a" + CR, BadFrameReason.BAD_NODE, None),
        (STX + b"0a1770" + ETX + ref_sum(b"0a1770") + CR, BadFrameReason.BAD_NODE, None),
    ],
)
def test_bad_frames_are_events_never_exceptions(
    wire: bytes, reason: BadFrameReason, station: int | None
) -> None:
    parser = Fr700ReplyParser()
    (event,) = parser.feed(wire)
    assert event == BadFrame(reason, wire[:-1], station)
    assert parser.stats.bad_frames == 1


def test_a_sum_is_accepted_in_either_case() -> None:
    body = b"01ABCD"
    assert Fr700ReplyParser().feed(STX + body + ETX + ref_sum(body).lower() + CR) == [
        Fr700Data(1, b"ABCD")
    ]


def test_reset_discards_a_partial_frame() -> None:
    parser = Fr700ReplyParser()
    assert parser.feed(STX + b"0117") == []
    assert parser.reset() == [Discarded(DiscardReason.RESTARTED, STX + b"0117")]
    assert parser.buffered == 0
    assert parser.reset() == []
    assert parser.feed(ack(1)) == [Fr700Ack(1)]


def test_unknown_nak_codes_are_kept() -> None:
    (event,) = Fr700ReplyParser().feed(nak(1, b"E"))
    assert isinstance(event, Fr700Nak)
    assert event.code == 0xE
    assert event.code.name == "UNKNOWN_14"


def test_parser_rejects_a_bad_terminator() -> None:
    with pytest.raises(LocalProtocolError, match="terminator"):
        Fr700ReplyParser(b"\n")
