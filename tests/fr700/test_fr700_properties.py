"""Property tests of the FR-700 codec and parsers (hypothesis), as for SJ300.

- every reply survives encode -> parse, in every terminator mode;
- the events and counters do not depend on how the stream is cut into chunks;
- garbage never raises, never makes the parser buffer more than MAX_FRAME
  bytes, and never yields a reply the line did not carry;
- the simulator's request parser reads back every request the builders make.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async.fr700 import (
    MAX_FRAME,
    Fr700Ack,
    Fr700Data,
    Fr700LineOptions,
    Fr700Nak,
    Fr700NakCode,
    Fr700Reply,
    Fr700ReplyParser,
    Fr700Request,
    encode_ack,
    encode_data_reply,
    encode_nak,
    requests,
    sum_check,
)
from sj300_async.simulator.fr700 import HostRequest, RequestParser
from sj300_async.wire import BadFrame, Discarded

from .fr700wire import ref_sum

PROPERTY = settings(max_examples=250, deadline=None)
TERMINATORS = (b"", b"\r", b"\r\n")
REPLY_TYPES = (Fr700Ack, Fr700Nak, Fr700Data)

stations = st.integers(min_value=0, max_value=31)
terminators = st.sampled_from(TERMINATORS)
hex_data = st.lists(st.sampled_from(b"0123456789ABCDEF"), min_size=1, max_size=20).map(bytes)
text_data = st.binary(min_size=1, max_size=20).map(
    lambda b: bytes(0x20 + x % 0x5F for x in b)
)  # printable ASCII (E3 model names)
replies: st.SearchStrategy[Fr700Reply] = st.one_of(
    st.builds(Fr700Ack, stations),
    st.builds(Fr700Nak, stations, st.integers(0, 15).map(Fr700NakCode)),
    st.builds(Fr700Data, stations, st.one_of(hex_data, text_data)),
)


def encode(reply: Fr700Reply, term: bytes) -> bytes:
    if isinstance(reply, Fr700Ack):
        return encode_ack(reply.station, term)
    if isinstance(reply, Fr700Nak):
        return encode_nak(reply.station, reply.code, term)
    return encode_data_reply(reply.station, reply.data, term)


def reference(reply: Fr700Reply, term: bytes) -> bytes:
    station = b"%02X" % reply.station
    if isinstance(reply, Fr700Ack):
        return b"\x06" + station + term
    if isinstance(reply, Fr700Nak):
        return b"\x15" + station + b"%X" % reply.code + term
    return b"\x02" + station + reply.data + b"\x03" + ref_sum(station + reply.data) + term


noisy_byte = st.one_of(
    st.sampled_from(b"\x02\x03\x05\x06\x15\r\n0123456789ABCDEF"), st.integers(0, 255)
)
noisy_garbage = st.one_of(
    st.binary(max_size=40),
    st.lists(noisy_byte, max_size=40).map(bytes),
    st.integers(min_value=20, max_value=80).map(lambda n: b"\x02" + b"7" * n),
)


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


def feed_chunks(parser: Fr700ReplyParser, chunks: list[bytes]) -> list[object]:
    events: list[object] = []
    for chunk in chunks:
        events += parser.feed(chunk)
        assert parser.buffered <= MAX_FRAME
    return events


def kept(events: Sequence[object]) -> list[object]:
    return [e for e in events if not isinstance(e, Discarded)]


def discarded_total(events: Sequence[object]) -> int:
    return sum(len(e.data) for e in events if isinstance(e, Discarded))


# -- sum check -------------------------------------------------------------------------------


@PROPERTY
@given(st.binary(max_size=100))
def test_sum_check_is_the_low_byte_of_the_sum(chars: bytes) -> None:
    assert sum_check(chars) == ref_sum(chars)


# -- replies: encode -> parse ----------------------------------------------------------------


@PROPERTY
@given(replies, terminators)
def test_reply_round_trip(reply: Fr700Reply, term: bytes) -> None:
    frame = encode(reply, term)
    assert frame == reference(reply, term)
    parser = Fr700ReplyParser(term)
    assert parser.feed(frame) == [reply]
    assert parser.buffered == 0
    assert parser.stats.frames == 1


@PROPERTY
@given(st.lists(replies, max_size=10), terminators, st.lists(st.integers(min_value=0), max_size=12))
def test_reply_stream_in_any_chunks(batch: list[Fr700Reply], term: bytes, cuts: list[int]) -> None:
    stream = b"".join(encode(r, term) for r in batch)
    assert feed_chunks(Fr700ReplyParser(term), split(stream, cuts)) == batch


# -- independence from the split -----------------------------------------------------------------


@st.composite
def streams(draw: st.DrawFn) -> tuple[bytes, bytes]:
    term = draw(terminators)
    parts = draw(
        st.lists(
            st.one_of(
                replies.map(lambda r: encode(r, term)),
                noisy_garbage,
                st.tuples(replies, st.integers(0, 100), st.integers(0, 255)).map(
                    lambda t: _changed(encode(t[0], term), t[1], t[2])
                ),
            ),
            max_size=12,
        )
    )
    return term, b"".join(parts)


def _changed(frame: bytes, where: int, new: int) -> bytes:
    where %= len(frame)
    return frame[:where] + bytes([new]) + frame[where + 1 :]


@PROPERTY
@given(streams(), st.lists(st.integers(min_value=0), max_size=30))
def test_events_and_stats_do_not_depend_on_the_split(
    stream: tuple[bytes, bytes], cuts: list[int]
) -> None:
    term, data = stream
    whole = Fr700ReplyParser(term)
    reference_events = whole.feed(data)
    chunked = Fr700ReplyParser(term)
    events = feed_chunks(chunked, split(data, cuts))
    assert kept(events) == kept(reference_events)
    assert discarded_total(events) == discarded_total(reference_events)
    assert chunked.buffered == whole.buffered
    assert repr(chunked.stats) == repr(whole.stats)


@PROPERTY
@given(streams())
def test_byte_by_byte_equals_whole(stream: tuple[bytes, bytes]) -> None:
    term, data = stream
    reference_events = Fr700ReplyParser(term).feed(data)
    events = feed_chunks(Fr700ReplyParser(term), [data[i : i + 1] for i in range(len(data))])
    assert kept(events) == kept(reference_events)
    assert discarded_total(events) == discarded_total(reference_events)


# -- garbage ---------------------------------------------------------------------------------------


@PROPERTY
@given(streams(), st.lists(st.integers(min_value=0), max_size=30))
def test_garbage_never_raises_stays_bounded_and_never_invents_a_reply(
    stream: tuple[bytes, bytes], cuts: list[int]
) -> None:
    term, data = stream
    parser = Fr700ReplyParser(term)
    events = feed_chunks(parser, split(data, cuts))  # checks buffered <= MAX_FRAME
    for event in events:
        assert isinstance(event, (*REPLY_TYPES, BadFrame, Discarded))
        if isinstance(event, REPLY_TYPES):
            # never a value the line did not carry (the sum may be in either case)
            wire = encode(event, b"")
            assert wire in data or (
                isinstance(event, Fr700Data) and wire[:-2] + wire[-2:].lower() in data
            )
    assert discarded_total(events) == parser.stats.discarded_bytes
    assert sum(isinstance(e, REPLY_TYPES) for e in events) == parser.stats.frames
    assert sum(isinstance(e, BadFrame) for e in events) == parser.stats.bad_frames


@PROPERTY
@given(st.lists(st.one_of(noisy_garbage, replies.map(lambda r: encode(r, b"\r"))), max_size=12))
def test_every_byte_is_accounted_for(parts: list[bytes]) -> None:
    # With a CR line, once the stream ends with a CR every byte fed is in a
    # reply, a bad frame (+ its CR) or a Discarded event.
    stream = b"".join(parts) + b"\r"
    parser = Fr700ReplyParser(b"\r")
    events = parser.feed(stream)
    assert parser.buffered == 0
    accounted = 0
    for event in events:
        if isinstance(event, Discarded):
            accounted += len(event.data)
        elif isinstance(event, BadFrame):
            accounted += len(event.body) + 1
        else:
            accounted += len(encode(event, b"\r"))
    assert accounted == len(stream)


@PROPERTY
@given(
    st.builds(Fr700Data, stations, hex_data),
    terminators,
    st.integers(min_value=0),
    st.integers(min_value=0, max_value=255).filter(
        lambda b: b not in (0x02, 0x03, 0x06, 0x15, 0x0D)
    ),
)
def test_one_changed_byte_of_a_data_reply_never_yields_a_wrong_value(
    reply: Fr700Data, term: bytes, where: int, new: int
) -> None:
    frame = encode(reply, term)
    body_end = len(frame) - len(term)
    where %= body_end
    corrupted = frame[:where] + bytes([new]) + frame[where + 1 :]
    for event in Fr700ReplyParser(term).feed(corrupted):
        if isinstance(event, REPLY_TYPES):
            # only a case change of a sum letter keeps the frame valid
            assert event == reply


# -- requests: builders -> the simulator's request parser ------------------------------------------

options = st.builds(
    Fr700LineOptions,
    wait_field=st.booleans(),
    wait_time_digit=st.integers(0, 15),
    terminator=terminators,
)


@st.composite
def built_requests(draw: st.DrawFn) -> tuple[Fr700LineOptions, Fr700Request]:
    opts = draw(options)
    station = draw(stations)
    builders: list[Callable[[], Fr700Request]] = [
        lambda: requests.read(station, draw(st.integers(0, 0x7F)), options=opts),
        lambda: requests.write(
            station,
            draw(st.sampled_from([0xED, 0xEE, 0xFB, 0xFD, 0x85])),
            draw(st.integers(0, 0xFFFF)),
            options=opts,
        ),
        lambda: requests.run(station, draw(st.integers(0, 2)), options=opts),
        lambda: requests.link_extension(station, draw(st.integers(0, 9)), options=opts),
        lambda: requests.multi_command(
            station,
            draw(st.integers(0, 0xFFFF)),
            draw(st.integers(0, 65535)) / 100,
            eeprom=draw(st.booleans()),
            receive=draw(st.integers(0, 3)),
            options=opts,
        ),
    ]
    build = draw(st.sampled_from(builders))
    return opts, build()


def _expected(opts: Fr700LineOptions, request: Fr700Request) -> HostRequest:
    wait = opts.wait_time_digit if opts.wait_field else None
    return HostRequest(request.station, request.instruction, wait, request.data)


@PROPERTY
@given(built_requests(), st.lists(st.integers(min_value=0), max_size=10))
def test_request_parser_reads_back_every_built_request(
    built: tuple[Fr700LineOptions, Fr700Request], cuts: list[int]
) -> None:
    opts, request = built
    parser = RequestParser(wait_field=opts.wait_field, terminator=opts.terminator)
    events: list[object] = []
    for chunk in split(request.frame * 2, cuts):
        events += parser.feed(chunk)
    assert events == [_expected(opts, request)] * 2
    assert parser.buffered == 0
