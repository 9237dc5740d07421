"""ReplyParser: every reply shape, three ways (h11 style), resynchronisation and bad frames.

Frames are built here by hand from the reference (docs: sj300.md, "Frame
layout"), with this module's own BCC, not with the library's encoder.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import reduce
from operator import xor

import pytest

from sj300_async import NakCode
from sj300_async.sj300 import (
    AckDataReply,
    AckReply,
    DataReply,
    NakReply,
    ParserEvent,
    ReplyParser,
    _parser,
    encode_reply,
)
from sj300_async.wire import BadFrame, BadFrameReason, Discarded, DiscardReason

STX = b"\x02"
ACK = b"\x06"
NAK = b"\x15"
CR = b"\r"
#: node(2) + trip history data(440) + BCC(2): the longest legal reply body.
MAX_BODY = 444


def check(body: bytes) -> bytes:
    return b"%02X" % reduce(xor, body, 0)


def frame(body: bytes) -> bytes:
    """STX body BCC CR, with a correct upper-case BCC."""
    return STX + body + check(body) + CR


def frame_with_bcc(body: bytes, bcc_chars: bytes) -> bytes:
    return STX + body + bcc_chars + CR


STATUS = b"03010300"
MONITOR = b"".join(
    (
        b"00005000",  # 1 output frequency 50.00 Hz
        b"00000123",  # 2 output current 12.3 A
        b"00000001",  # 3 forward
        b"00004567",  # 4 PID feedback 45.67 %
        b"00000105",  # 5 input terminals (hex)
        b"0000002A",  # 6 output terminals (hex)
        b"00012345",  # 7 frequency conversion
        b"-0000087",  # 8 torque -87 %
        b"00002000",  # 9 output voltage 200.0 V
        b"00000055",  # 10 power 5.5 kW
        b"00000000",  # 11 reserved
        b"00001234",  # 12 RUN time
        b"00005678",  # 13 power-ON time
    )
)
TRIP_HISTORY = b"00000003" + b"".join(b"%08d" % (i * 7) for i in range(54))
assert len(MONITOR) == 104
assert len(TRIP_HISTORY) == 440

#: Every reply shape of the reference: (id, body between STX and BCC, expected event).
SHAPES: list[tuple[str, bytes, ParserEvent]] = [
    ("ack", b"01" + ACK, AckReply(1)),
    ("ack-node-32", b"32" + ACK, AckReply(32)),
    ("ack+8 (06)", b"05" + ACK + b"00000500", AckDataReply(5, b"00000500")),
    ("ack+8 (06) negative", b"05" + ACK + b"-0000001", AckDataReply(5, b"-0000001")),
    ("ack+2 (09) allowed", b"12" + ACK + b"01", AckDataReply(12, b"01")),
    ("ack+2 (09) not allowed", b"12" + ACK + b"00", AckDataReply(12, b"00")),
    ("data 8 (04)", b"01" + STATUS, DataReply(1, STATUS)),
    ("data 104 (03)", b"17" + MONITOR, DataReply(17, MONITOR)),
    ("data 440 (05)", b"02" + TRIP_HISTORY, DataReply(2, TRIP_HISTORY)),
]
NAK_TABLE = {
    1: "parity error",
    2: "check sum (BCC) error",
    3: "framing error",
    4: "overrun error",
    5: "protocol error",
    6: "ASCII code error",
    7: "receive buffer overrun",
    8: "receive time-out",
    11: "abnormal command code",
    13: "execution disabled",
    16: "abnormal parameter code or value",
}
SHAPES += [
    (f"nak {code:02d}", b"09" + NAK + b"%02d" % code, NakReply(9, NakCode(code)))
    for code in NAK_TABLE
]
SHAPE_IDS = [s[0] for s in SHAPES]


def feed_whole(data: bytes) -> tuple[list[ParserEvent], ReplyParser]:
    parser = ReplyParser()
    return parser.feed(data), parser


def feed_bytewise(data: bytes) -> tuple[list[ParserEvent], ReplyParser]:
    parser = ReplyParser()
    events: list[ParserEvent] = []
    for i in range(len(data)):
        events += parser.feed(data[i : i + 1])
        assert parser.buffered <= MAX_BODY
    return events, parser


def feed_in_chunks(data: bytes, size: int) -> tuple[list[ParserEvent], ReplyParser]:
    parser = ReplyParser()
    events: list[ParserEvent] = []
    for i in range(0, len(data), size):
        events += parser.feed(data[i : i + size])
        assert parser.buffered <= MAX_BODY
    return events, parser


Feeder = Callable[[bytes], tuple[list[ParserEvent], ReplyParser]]
FEEDERS: list[Feeder] = [feed_whole, feed_bytewise, lambda d: feed_in_chunks(d, 7)]
FEEDER_IDS = ["whole", "bytewise", "chunks-of-7"]


def only_discarded_total(events: list[ParserEvent]) -> int:
    return sum(len(e.data) for e in events if isinstance(e, Discarded))


def without_discarded(events: list[ParserEvent]) -> list[ParserEvent]:
    return [e for e in events if not isinstance(e, Discarded)]


# -- every shape, three ways ---------------------------------------------------


@pytest.mark.parametrize(("name", "body", "expected"), SHAPES, ids=SHAPE_IDS)
def test_shape_whole_buffer(name: str, body: bytes, expected: ParserEvent) -> None:
    events, parser = feed_whole(frame(body))
    assert events == [expected]
    assert parser.buffered == 0
    assert parser.stats.frames == 1


@pytest.mark.parametrize(("name", "body", "expected"), SHAPES, ids=SHAPE_IDS)
def test_shape_byte_by_byte(name: str, body: bytes, expected: ParserEvent) -> None:
    data = frame(body)
    parser = ReplyParser()
    for byte in data[:-1]:
        assert parser.feed(bytes([byte])) == []
    assert parser.feed(data[-1:]) == [expected]
    assert parser.buffered == 0


@pytest.mark.parametrize(("name", "body", "expected"), SHAPES, ids=SHAPE_IDS)
def test_shape_with_trailing_partial_frame(name: str, body: bytes, expected: ParserEvent) -> None:
    following = frame(b"04" + ACK)
    split = 4  # STX, "04", ACK: the next frame's first four bytes
    parser = ReplyParser()
    assert parser.feed(frame(body) + following[:split]) == [expected]
    assert parser.buffered > 0  # the partial frame is kept...
    assert parser.feed(following[split:]) == [AckReply(4)]  # ...and completed later
    assert parser.buffered == 0
    assert parser.stats.discarded_bytes == 0


@pytest.mark.parametrize(("name", "body", "expected"), SHAPES, ids=SHAPE_IDS)
def test_shape_with_trailing_garbage(name: str, body: bytes, expected: ParserEvent) -> None:
    garbage = b"\x00\xffxyz\r\n"
    events, parser = feed_whole(frame(body) + garbage)
    assert events == [expected, Discarded(DiscardReason.GARBAGE, garbage)]
    assert parser.buffered == 0
    assert parser.stats.discarded_bytes == len(garbage)


@pytest.mark.parametrize(("name", "body", "expected"), SHAPES, ids=SHAPE_IDS)
@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
def test_shape_back_to_back(name: str, body: bytes, expected: ParserEvent, feeder: Feeder) -> None:
    events, _ = feeder(frame(body) * 3)
    assert events == [expected] * 3


@pytest.mark.parametrize("code", sorted(NAK_TABLE))
def test_nak_codes_have_the_reference_meaning(code: int) -> None:
    (event,) = ReplyParser().feed(frame(b"01" + NAK + b"%02d" % code))
    assert isinstance(event, NakReply)
    assert event.code == code
    assert event.code.known
    assert event.code.description == NAK_TABLE[code]


@pytest.mark.parametrize("code", [0, 9, 10, 12, 42, 99])
def test_unknown_nak_code_is_kept_as_a_number(code: int) -> None:
    (event,) = ReplyParser().feed(frame(b"01" + NAK + b"%02d" % code))
    assert isinstance(event, NakReply)
    assert int(event.code) == code
    assert not event.code.known


@pytest.mark.parametrize(
    ("code", "transmission"), [(1, True), (2, True), (8, True), (11, False), (16, False)]
)
def test_nak_retry_hint(code: int, transmission: bool) -> None:
    assert NakCode(code).is_transmission_error is transmission


# -- resynchronisation ------------------------------------------------------


@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
def test_garbage_before_stx_is_reported(feeder: Feeder) -> None:
    garbage = b"\x00\xff\x06\x15noise\r"
    events, parser = feeder(garbage + frame(b"01" + ACK))
    assert without_discarded(events) == [AckReply(1)]
    assert all(e.reason is DiscardReason.GARBAGE for e in events if isinstance(e, Discarded))
    assert b"".join(e.data for e in events if isinstance(e, Discarded)) == garbage
    assert parser.stats.discarded_bytes == len(garbage)


@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
def test_stx_mid_frame_restarts(feeder: Feeder) -> None:
    lost = STX + b"01" + ACK + b"000"  # cut short by the next STX
    events, parser = feeder(lost + frame(b"02" + ACK))
    assert without_discarded(events) == [AckReply(2)]
    (restart,) = [e for e in events if isinstance(e, Discarded)]
    assert restart.reason is DiscardReason.RESTARTED
    assert b"01" + ACK + b"000" in restart.data
    assert parser.stats.restarted_frames == 1
    assert parser.stats.frames == 1


@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
def test_stx_mid_frame_after_a_partial_split_over_chunks(feeder: Feeder) -> None:
    # The partial frame spans chunks; the restart must still drop it whole.
    lost = STX + b"01" + STATUS[:5]
    events, _ = feeder(lost + frame(b"03" + STATUS))
    assert without_discarded(events) == [DataReply(3, STATUS)]


@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
@pytest.mark.parametrize("extra", [1, 2, 100, 1000])
def test_overlong_frame_is_abandoned(feeder: Feeder, extra: int) -> None:
    overlong = STX + b"01" + b"7" * (MAX_BODY - 2 + extra) + CR
    events, parser = feeder(overlong + frame(b"01" + ACK))
    assert without_discarded(events) == [AckReply(1)]
    reasons = [e.reason for e in events if isinstance(e, Discarded)]
    assert reasons.count(DiscardReason.OVERLONG) == 1
    assert set(reasons) <= {DiscardReason.OVERLONG, DiscardReason.GARBAGE}
    assert parser.stats.overlong_frames == 1
    assert parser.stats.discarded_bytes == only_discarded_total(events)
    assert parser.buffered == 0


@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
def test_overlong_frame_cut_by_stx_is_still_overlong(feeder: Feeder) -> None:
    # 500 bytes after STX exceed every legal reply whatever ends them; how the
    # bytes were chunked must not turn the overlong frame into a "restarted" one.
    events, parser = feeder(STX + b"01" + b"7" * 498 + frame(b"01" + ACK))
    assert without_discarded(events) == [AckReply(1)]
    reasons = [e.reason for e in events if isinstance(e, Discarded)]
    assert reasons.count(DiscardReason.OVERLONG) == 1
    assert DiscardReason.RESTARTED not in reasons
    assert parser.stats.overlong_frames == 1
    assert parser.stats.restarted_frames == 0


def test_overlong_without_cr_never_buffers_more_than_444() -> None:
    parser = ReplyParser()
    parser.feed(STX)
    for _ in range(2000):
        parser.feed(b"5")
        assert parser.buffered <= MAX_BODY
    assert parser.feed(frame(b"01" + ACK))[-1] == AckReply(1)


def test_overlong_in_one_big_chunk_never_buffers_more_than_444() -> None:
    parser = ReplyParser()
    parser.feed(STX + b"5" * 100_000)
    assert parser.buffered <= MAX_BODY


def test_longest_legal_frame_is_not_overlong() -> None:
    body = b"01" + TRIP_HISTORY
    assert len(body) + 2 == MAX_BODY
    for feeder in FEEDERS:
        events, parser = feeder(frame(body))
        assert events == [DataReply(1, TRIP_HISTORY)]
        assert parser.stats.overlong_frames == 0


@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
def test_bad_bcc_is_reported_and_the_stream_continues(feeder: Feeder) -> None:
    body = b"01" + STATUS
    good = check(body)
    wrong = b"%02X" % (int(good, 16) ^ 0x01)
    events, parser = feeder(frame_with_bcc(body, wrong) + frame(b"02" + ACK))
    assert events == [BadFrame(BadFrameReason.BAD_BCC, body + wrong), AckReply(2)]
    assert parser.stats.bad_frames == 1
    assert parser.stats.frames == 1


@pytest.mark.parametrize("bcc_chars", [b"ZZ", b"0G", b" 7", b"7 ", b"\xb07", b"-7"])
def test_bcc_that_is_not_hex_is_a_bad_bcc(bcc_chars: bytes) -> None:
    body = b"01" + ACK
    (event,) = ReplyParser().feed(frame_with_bcc(body, bcc_chars))
    assert event == BadFrame(BadFrameReason.BAD_BCC, body + bcc_chars)


def test_corrupted_data_byte_is_a_bad_bcc() -> None:
    good = frame(b"01" + STATUS)
    corrupt = good.replace(b"0301", b"0302")
    (event,) = ReplyParser().feed(corrupt)
    assert isinstance(event, BadFrame)
    assert event.reason is BadFrameReason.BAD_BCC


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (b"04" + ACK + b"00000509", AckDataReply(4, b"00000509")),  # BCC 0E
        (b"01" + NAK + b"08", NakReply(1, NakCode.RECEIVE_TIMEOUT)),  # BCC 1C
    ],
)
def test_lower_case_bcc_is_accepted(body: bytes, expected: ParserEvent) -> None:
    upper = check(body)
    assert upper != upper.lower(), "the BCC must contain a hex letter for this test"
    assert ReplyParser().feed(frame_with_bcc(body, upper.lower())) == [expected]


# -- characters and fields (with a matching BCC, so only the content is wrong) ---------------


def _replace_field(data: bytes, index: int, field: bytes) -> bytes:
    return data[: index * 8] + field + data[(index + 1) * 8 :]


BAD_CHARACTER_BODIES = [
    ("status letter", b"01" + b"0A010300"),
    ("status space", b"01" + b" 3010300"),
    ("status plus", b"01" + b"+3010300"),
    ("status underscore", b"01" + b"03_10300"),
    ("status minus", b"01" + b"-3010300"),
    ("status non-ascii", b"01" + b"\xb03010300"),
    ("ack+8 letter", b"01" + ACK + b"0000050A"),
    ("ack+8 plus", b"01" + ACK + b"+0000050"),
    ("ack+8 space", b"01" + ACK + b" 0000050"),
    ("ack+8 underscore", b"01" + ACK + b"0000_050"),
    ("ack+8 minus inside", b"01" + ACK + b"0000-050"),
    ("ack+8 non-ascii", b"01" + ACK + b"0000050\xb0"),
    ("ack+2 letter", b"01" + ACK + b"0A"),
    ("nak letter", b"01" + NAK + b"1A"),
    ("nak space", b"01" + NAK + b" 1"),
    ("monitor hex in decimal item 1", b"01" + _replace_field(MONITOR, 0, b"0000500A")),
    ("monitor hex in decimal item 13", b"01" + _replace_field(MONITOR, 12, b"0000567F")),
    ("monitor non-hex in item 5", b"01" + _replace_field(MONITOR, 4, b"0000010G")),
    ("monitor minus in item 6", b"01" + _replace_field(MONITOR, 5, b"-0000001")),
    ("monitor space in item 9", b"01" + _replace_field(MONITOR, 8, b"0000 200")),
    ("trip history letter", b"01" + _replace_field(TRIP_HISTORY, 30, b"0000000E")),
    ("trip history plus", b"01" + _replace_field(TRIP_HISTORY, 54, b"+0000001")),
]


@pytest.mark.parametrize(
    "body", [b for _, b in BAD_CHARACTER_BODIES], ids=[n for n, _ in BAD_CHARACTER_BODIES]
)
def test_wrong_characters_with_matching_bcc_are_bad_characters(body: bytes) -> None:
    (event,) = ReplyParser().feed(frame(body))
    assert event == BadFrame(BadFrameReason.BAD_CHARACTERS, body + check(body), node=1)


def test_lower_case_hex_in_monitor_terminal_items_is_accepted() -> None:
    data = _replace_field(_replace_field(MONITOR, 4, b"0000abcd"), 5, b"0000002a")
    assert ReplyParser().feed(frame(b"01" + data)) == [DataReply(1, data)]


@pytest.mark.parametrize("node", [b"00", b"33", b"99", b"FF", b"0A", b" 1", b"1 ", b"-1"])
def test_bad_node_with_matching_bcc(node: bytes) -> None:
    body = node + ACK
    (event,) = ReplyParser().feed(frame(body))
    assert event == BadFrame(BadFrameReason.BAD_NODE, body + check(body))


@pytest.mark.parametrize(
    "body",
    [
        b"01" + ACK + b"0",
        b"01" + ACK + b"000",
        b"01" + ACK + b"0000000",
        b"01" + ACK + b"000000000",
        b"01" + NAK,
        b"01" + NAK + b"1",
        b"01" + NAK + b"011",
        b"01" + b"0301030",
        b"01" + b"030103000",
        b"01" + MONITOR[:-1],
        b"01" + MONITOR + b"0",
        b"01" + TRIP_HISTORY[:-1],
    ],
)
def test_no_frame_of_this_length(body: bytes) -> None:
    (event,) = ReplyParser().feed(frame(body))
    assert event == BadFrame(BadFrameReason.BAD_LENGTH, body + check(body), node=1)


@pytest.mark.parametrize("body", [b"", b"0", b"01", b"01\x06", b"01\x060"])
def test_too_short(body: bytes) -> None:
    (event,) = ReplyParser().feed(STX + body + CR)
    assert event == BadFrame(BadFrameReason.TOO_SHORT, body)


def test_non_ascii_bytes_never_raise() -> None:
    data = bytes(range(256)) * 3 + frame(b"01" + ACK)
    for feeder in FEEDERS:
        events, parser = feeder(data)
        assert events[-1] == AckReply(1)
        assert parser.stats.discarded_bytes == only_discarded_total(events)


# -- statistics ---------------------------------------------------------------


@pytest.mark.parametrize("feeder", FEEDERS, ids=FEEDER_IDS)
def test_stats_match_the_events(feeder: Feeder) -> None:
    body = b"01" + STATUS
    stream = b"".join(
        (
            b"junk",
            frame(b"01" + ACK),
            STX + b"01" + ACK,  # cut short by the next STX
            frame(b"02" + STATUS),
            frame_with_bcc(body, b"%02X" % (int(check(body), 16) ^ 0x40)),  # bad BCC
            STX + b"9" * 600 + CR,  # overlong
            frame(b"03" + NAK + b"02"),
            b"\r\n",
            frame(b"01" + ACK + b"0A"),  # bad characters
            frame(b"04" + TRIP_HISTORY),
        )
    )
    events, parser = feeder(stream)
    replies = [e for e in events if isinstance(e, AckReply | AckDataReply | DataReply | NakReply)]
    bad = [e for e in events if isinstance(e, BadFrame)]
    discarded = [e for e in events if isinstance(e, Discarded)]
    assert len(replies) == parser.stats.frames == 4
    assert len(bad) == parser.stats.bad_frames == 2
    assert sum(len(e.data) for e in discarded) == parser.stats.discarded_bytes
    assert parser.stats.restarted_frames == 1
    assert parser.stats.overlong_frames == 1
    assert [e.reason for e in discarded].count(DiscardReason.RESTARTED) == 1
    assert [e.reason for e in discarded].count(DiscardReason.OVERLONG) == 1


def _frame_bytes(event: ParserEvent) -> int:
    """How many stream bytes an event stands for (STX and CR included)."""
    if isinstance(event, Discarded):
        return len(event.data)
    if isinstance(event, BadFrame):
        return 1 + len(event.body) + 1
    if isinstance(event, AckReply):
        return 1 + 2 + 1 + 2 + 1
    if isinstance(event, NakReply):
        return 1 + 2 + 1 + 2 + 2 + 1
    if isinstance(event, AckDataReply):
        return 1 + 2 + 1 + len(event.data) + 2 + 1
    return 1 + 2 + len(event.data) + 2 + 1


@pytest.mark.parametrize(
    "stream",
    [
        STX + STX + frame(b"01" + ACK),
        STX + b"01" + ACK + frame(b"01" + ACK),
        STX + b"9" * 600 + CR + frame(b"01" + ACK),
        STX + b"9" * 445 + frame(b"01" + ACK),
    ],
    ids=["stx-stx", "restart", "overlong-cr", "overlong-stx"],
)
def test_every_byte_fed_is_accounted_for(stream: bytes) -> None:
    # Nothing is dropped silently: each byte ends up in a frame, a bad frame or a
    # Discarded event. That includes the STX that opened an abandoned frame.
    for feeder, name in zip(FEEDERS, FEEDER_IDS, strict=True):
        events, parser = feeder(stream)
        assert parser.buffered == 0
        assert sum(_frame_bytes(e) for e in events) == len(stream), name
        assert parser.stats.discarded_bytes == only_discarded_total(events), name
        assert all(e.data for e in events if isinstance(e, Discarded)), f"{name}: empty Discarded"


@pytest.mark.parametrize("partial", [STX, STX + b"01" + ACK], ids=["stx", "stx-node-ack"])
def test_reset_accounts_for_every_byte(partial: bytes) -> None:
    parser = ReplyParser()
    assert parser.feed(partial) == []
    events = parser.reset()
    assert sum(_frame_bytes(e) for e in events) == len(partial)
    assert parser.stats.discarded_bytes == len(partial)


def test_reset_reports_the_partial_frame() -> None:
    parser = ReplyParser()
    assert parser.feed(STX + b"01" + ACK) == []
    (event,) = parser.reset()
    assert isinstance(event, Discarded)
    assert b"01" + ACK in event.data
    assert parser.buffered == 0
    assert parser.feed(frame(b"01" + ACK)) == [AckReply(1)]


def test_short_replies_are_decoded_once_and_shared_parameter_values_are_not_kept() -> None:
    status = encode_reply(DataReply(5, b"00030103"))
    ack = encode_reply(AckReply(5))
    parameter = encode_reply(AckDataReply(5, b"00001234"))
    first, second = ReplyParser(), ReplyParser()
    for frame in (status, ack):
        (a,) = first.feed(frame)
        (b,) = second.feed(frame)
        assert a is b  # one frozen object for every parser
    (a,) = first.feed(parameter)
    (b,) = second.feed(parameter)
    assert a == b == AckDataReply(5, b"00001234")
    assert parameter[1:-1] not in _parser._SHORT_REPLIES
    # A stream of ever-new parameter values leaves the table as it was.
    kept = dict(_parser._SHORT_REPLIES)
    for value in range(3 * _parser._SHORT_REPLIES_KEPT):
        first.feed(encode_reply(AckDataReply(5, b"%08d" % value)))
    assert kept == _parser._SHORT_REPLIES
