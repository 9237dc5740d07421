"""Property tests of the codec and the parsers (hypothesis).

- every reply shape survives encode -> parse;
- the events do not depend on how the byte stream is cut into chunks;
- garbage never raises, never makes the parser buffer more than 444 bytes,
  and never costs a frame it does not overlap;
- the drive-side RequestParser reads back every request the builders make.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Sequence
from functools import reduce
from operator import xor

from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async import NakCode
from sj300_async.sj300 import (
    BROADCAST,
    PARAMETERS,
    AckDataReply,
    AckReply,
    DataReply,
    NakReply,
    Reply,
    ReplyParser,
    Request,
    RequestParser,
    bcc,
    encode_reply,
    requests,
)
from sj300_async.wire import BadFrame, Discarded

PROPERTY = settings(max_examples=250, deadline=None)
STX = b"\x02"
CR = b"\r"
MAX_BODY = 444
REPLY_TYPES = (AckReply, AckDataReply, DataReply, NakReply)


def reference_frame(body: bytes) -> bytes:
    return STX + body + b"%02X" % reduce(xor, body, 0) + CR


def reference_reply_frame(reply: Reply) -> bytes:
    node = b"%02d" % reply.node
    if isinstance(reply, AckReply):
        return reference_frame(node + b"\x06")
    if isinstance(reply, AckDataReply):
        return reference_frame(node + b"\x06" + reply.data)
    if isinstance(reply, NakReply):
        return reference_frame(node + b"\x15" + b"%02d" % reply.code)
    return reference_frame(node + reply.data)


# -- strategies -------------------------------------------------------------------

nodes = st.integers(min_value=1, max_value=32)
digits = st.sampled_from(b"0123456789")


def digit_string(n: int) -> st.SearchStrategy[bytes]:
    return st.lists(digits, min_size=n, max_size=n).map(bytes)


decimal_fields = st.one_of(
    st.integers(min_value=0, max_value=99_999_999).map(lambda v: b"%08d" % v),
    st.integers(min_value=0, max_value=9_999_999).map(lambda v: b"-%07d" % v),
)
hex_fields = st.lists(st.sampled_from(b"0123456789abcdefABCDEF"), min_size=8, max_size=8).map(bytes)


def concat(*parts: st.SearchStrategy[bytes]) -> st.SearchStrategy[bytes]:
    return st.tuples(*parts).map(b"".join)


status_data = digit_string(8)
monitor_data = concat(*[decimal_fields] * 4, hex_fields, hex_fields, *[decimal_fields] * 7)
trip_data = st.lists(decimal_fields, min_size=55, max_size=55).map(b"".join)

ack_replies = st.builds(AckReply, nodes)
ack_data_replies = st.builds(AckDataReply, nodes, st.one_of(decimal_fields, digit_string(2)))
data_replies = st.builds(DataReply, nodes, st.one_of(status_data, monitor_data, trip_data))
nak_replies = st.builds(NakReply, nodes, st.integers(min_value=0, max_value=99).map(NakCode))
replies: st.SearchStrategy[Reply] = st.one_of(
    ack_replies, ack_data_replies, data_replies, nak_replies
)

#: Garbage that cannot start or end a frame.
quiet_garbage = st.binary(min_size=1, max_size=40).map(
    lambda b: b.replace(STX, b"").replace(CR, b"") or b"\x00"
)
#: Anything at all, biased toward the protocol's control bytes.
noisy_byte = st.one_of(st.sampled_from(b"\x02\x06\x15\r0123456789ABF"), st.integers(0, 255))
noisy_garbage = st.one_of(
    st.binary(max_size=60),
    st.lists(noisy_byte, max_size=60).map(bytes),
    st.integers(min_value=440, max_value=700).map(lambda n: STX + b"7" * n),
)


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


def feed_chunks(parser: ReplyParser | RequestParser, chunks: list[bytes]) -> list[object]:
    events: list[object] = []
    for chunk in chunks:
        events += parser.feed(chunk)
        assert parser.buffered <= MAX_BODY
    return events


def kept(events: Sequence[object]) -> list[object]:
    return [e for e in events if not isinstance(e, Discarded)]


def discarded_total(events: Sequence[object]) -> int:
    return sum(len(e.data) for e in events if isinstance(e, Discarded))


# -- bcc ----------------------------------------------------------------------------------


@PROPERTY
@given(st.binary(max_size=600))
def test_bcc_is_the_xor_of_every_byte(body: bytes) -> None:
    assert bcc(body) == b"%02X" % reduce(xor, body, 0)


# -- replies: encode -> parse ------------------------------------------------------------


@PROPERTY
@given(replies)
def test_reply_round_trip(reply: Reply) -> None:
    frame = encode_reply(reply)
    assert frame == reference_reply_frame(reply)
    parser = ReplyParser()
    assert parser.feed(frame) == [reply]
    assert parser.buffered == 0
    assert parser.stats.frames == 1


@PROPERTY
@given(replies, st.data())
def test_reply_round_trip_in_any_chunks(reply: Reply, data: st.DataObject) -> None:
    frame = encode_reply(reply)
    cuts = data.draw(st.lists(st.integers(min_value=0, max_value=len(frame)), max_size=8))
    assert feed_chunks(ReplyParser(), split(frame, cuts)) == [reply]


# -- independence from the split -------------------------------------------------------------

stream_parts = st.lists(
    st.one_of(
        replies.map(encode_reply),
        noisy_garbage,
        # a frame with one byte changed
        st.tuples(replies.map(encode_reply), st.integers(0, 10_000), st.integers(0, 255)).map(
            lambda t: t[0][: t[1] % len(t[0])] + bytes([t[2]]) + t[0][t[1] % len(t[0]) + 1 :]
        ),
    ),
    max_size=12,
)


@PROPERTY
@given(stream_parts, st.lists(st.integers(min_value=0), max_size=30))
def test_events_do_not_depend_on_the_split(parts: list[bytes], cuts: list[int]) -> None:
    stream = b"".join(parts)
    whole = ReplyParser()
    reference = whole.feed(stream)
    chunked = ReplyParser()
    events = feed_chunks(chunked, split(stream, cuts))
    assert kept(events) == kept(reference)
    assert discarded_total(events) == discarded_total(reference)
    assert chunked.buffered == whole.buffered


@PROPERTY
@given(stream_parts)
def test_byte_by_byte_equals_whole(parts: list[bytes]) -> None:
    stream = b"".join(parts)
    reference = ReplyParser().feed(stream)
    events = feed_chunks(ReplyParser(), [stream[i : i + 1] for i in range(len(stream))])
    assert kept(events) == kept(reference)
    assert discarded_total(events) == discarded_total(reference)


@PROPERTY
@given(stream_parts, st.lists(st.integers(min_value=0), max_size=30))
def test_stats_do_not_depend_on_the_split(parts: list[bytes], cuts: list[int]) -> None:
    # The counters feed the bus statistics: the OS's read sizes must not change them.
    stream = b"".join(parts)
    whole = ReplyParser()
    whole.feed(stream)
    chunked = ReplyParser()
    feed_chunks(chunked, split(stream, cuts))
    assert repr(chunked.stats) == repr(whole.stats)


# -- garbage ------------------------------------------------------------------------------------


@PROPERTY
@given(
    st.lists(st.tuples(quiet_garbage, replies), max_size=8),
    quiet_garbage,
    st.lists(st.integers(min_value=0), max_size=20),
)
def test_quiet_garbage_between_frames_loses_nothing(
    pairs: list[tuple[bytes, Reply]], tail: bytes, cuts: list[int]
) -> None:
    stream = b"".join(g + encode_reply(r) for g, r in pairs) + tail
    parser = ReplyParser()
    events = feed_chunks(parser, split(stream, cuts))
    assert kept(events) == [r for _, r in pairs]
    garbage = sum(len(g) for g, _ in pairs) + len(tail)
    assert discarded_total(events) == garbage == parser.stats.discarded_bytes


@PROPERTY
@given(
    st.lists(st.one_of(noisy_garbage, replies.map(encode_reply)), max_size=12),
    st.lists(st.integers(min_value=0), max_size=30),
)
def test_arbitrary_garbage_never_raises_and_stays_bounded(
    parts: list[bytes], cuts: list[int]
) -> None:
    stream = b"".join(parts)
    parser = ReplyParser()
    events = feed_chunks(parser, split(stream, cuts))  # checks buffered <= 444 after each chunk
    for event in events:
        assert isinstance(event, (*REPLY_TYPES, BadFrame, Discarded))
    assert discarded_total(events) == parser.stats.discarded_bytes
    assert sum(isinstance(e, REPLY_TYPES) for e in events) == parser.stats.frames
    assert sum(isinstance(e, BadFrame) for e in events) == parser.stats.bad_frames
    for event in events:
        if isinstance(event, REPLY_TYPES):
            # never a value the line did not carry
            body = encode_reply(event)[:-3]
            pattern = re.escape(body) + rb"(?i:" + re.escape(bcc(body[1:])) + rb")\r"
            assert re.search(pattern, stream)


@PROPERTY
@given(
    st.lists(st.one_of(noisy_garbage, replies.map(encode_reply)), max_size=12),
    st.lists(st.integers(min_value=0), max_size=30),
)
def test_every_byte_is_accounted_for(parts: list[bytes], cuts: list[int]) -> None:
    # Nothing is dropped silently: once the stream is closed with a CR, every
    # byte fed is in a reply, a bad frame or a Discarded event, STX and CR included.
    stream = b"".join(parts) + CR
    parser = ReplyParser()
    events = feed_chunks(parser, split(stream, cuts))
    assert parser.buffered == 0
    accounted = 0
    for event in events:
        if isinstance(event, Discarded):
            accounted += len(event.data)
        elif isinstance(event, BadFrame):
            accounted += len(event.body) + 2
        else:
            assert isinstance(event, (AckReply, AckDataReply, DataReply, NakReply))
            accounted += len(encode_reply(event))
    assert accounted == len(stream)


@PROPERTY
@given(
    replies,
    st.integers(min_value=0),
    st.integers(min_value=0, max_value=255).filter(lambda b: b not in (0x02, 0x0D)),
)
def test_one_changed_byte_never_yields_a_wrong_reply(reply: Reply, where: int, new: int) -> None:
    # A single changed byte (that does not move the frame's bounds) is caught by
    # the BCC: the parser yields a BadFrame, or nothing, never a different value.
    frame = encode_reply(reply)
    where %= len(frame)
    corrupted = frame[:where] + bytes([new]) + frame[where + 1 :]
    events = ReplyParser().feed(corrupted)
    for event in events:
        if isinstance(event, REPLY_TYPES):
            # only a case change of a BCC hex letter keeps the frame valid
            assert event == reply
            assert corrupted[-3:-1].upper() == frame[-3:-1]
    if 0 < where < len(frame) - 1:  # STX and CR intact: exactly one frame comes out
        assert len(events) == 1
        assert isinstance(events[0], BadFrame) or events[0] == reply


# -- requests: builders -> RequestParser --------------------------------------------------------

any_node = st.one_of(nodes, st.just(BROADCAST))
codes = st.tuples(st.sampled_from("FABCHPfabchp"), st.integers(0, 999)).map(
    lambda t: f"{t[0]}{t[1]:03d}"
)
assigned_masks = st.lists(
    st.sampled_from([b for b in range(49) if b not in (10, 19, 25, 30)]), max_size=10
).map(lambda bits: sum({1 << b for b in bits}))


@st.composite
def catalogue_writes(draw: st.DrawFn) -> Request:
    info = PARAMETERS[draw(st.sampled_from(sorted(PARAMETERS)))]
    low = math.ceil(info.minimum * info.scale - 1e-9)
    high = math.floor(info.maximum * info.scale + 1e-9)
    raw = draw(st.integers(low, high))
    return requests.write_parameter(draw(any_node), info.code, raw / info.scale)


built_requests: st.SearchStrategy[Request] = st.one_of(
    st.builds(requests.run, any_node, st.integers(0, 2)),
    st.builds(requests.set_frequency, any_node, st.integers(0, 999_999).map(lambda c: c / 100)),
    st.builds(requests.set_terminals, any_node, assigned_masks),
    st.builds(requests.read_monitor, nodes),
    st.builds(requests.read_status, nodes),
    st.builds(requests.read_trip_history, nodes),
    st.builds(requests.read_parameter, nodes, codes),
    st.builds(requests.write_parameter_raw, any_node, codes, st.integers(0, 99_999_999)),
    catalogue_writes(),
    st.builds(requests.initialize, any_node),
    st.builds(requests.can_store, nodes),
    st.builds(requests.store, any_node),
    st.builds(requests.recalculate, nodes),
)


@PROPERTY
@given(built_requests)
def test_request_parser_reads_back_every_built_request(request: Request) -> None:
    parser = RequestParser()
    assert parser.feed(request.frame) == [request]
    assert parser.buffered == 0
    assert parser.stats.frames == 1


@PROPERTY
@given(st.lists(built_requests, max_size=10), st.lists(st.integers(min_value=0), max_size=20))
def test_request_stream_in_any_chunks(batch: list[Request], cuts: list[int]) -> None:
    stream = b"".join(r.frame for r in batch)
    assert feed_chunks(RequestParser(), split(stream, cuts)) == batch


@PROPERTY
@given(
    st.lists(st.tuples(quiet_garbage, built_requests), max_size=6),
    st.lists(st.integers(min_value=0), max_size=20),
)
def test_request_parser_skips_quiet_garbage(
    pairs: list[tuple[bytes, Request]], cuts: list[int]
) -> None:
    stream = b"".join(g + r.frame for g, r in pairs)
    events = feed_chunks(RequestParser(), split(stream, cuts))
    assert kept(events) == [r for _, r in pairs]


def test_strategies_cover_every_reply_shape() -> None:
    # Guard against a strategy silently losing a shape: draw until each kind was seen.
    seen: set[tuple[type, int]] = set()

    @settings(max_examples=300, deadline=None, database=None)
    @given(replies)
    def collect(reply: Reply) -> None:
        length = len(reply.data) if isinstance(reply, AckDataReply | DataReply) else 0
        seen.add((type(reply), length))

    collect()
    assert seen >= {
        (AckReply, 0),
        (AckDataReply, 8),
        (AckDataReply, 2),
        (DataReply, 8),
        (DataReply, 104),
        (DataReply, 440),
        (NakReply, 0),
    }
