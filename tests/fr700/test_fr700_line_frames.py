"""The FR-700 line framer: the whole line, both directions, split and told apart.

The frames come from the library itself wherever it can make them: requests
from the builders, replies from the simulated drives answering them (with
their faults), the host's ACK and re-output request from the dialect; the
manual's worked examples and a few hand-made broken frames complete them.
Every check runs in each line configuration the dialect allows (waiting-time
field on and off, no terminator, CR, CR LF).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sj300_async.simulator.fr700 as sim_fr700
from sj300_async.bus import Dialect, LineFramer
from sj300_async.fr700 import (
    MAX_FRAME,
    Fr700Ack,
    Fr700Data,
    Fr700Dialect,
    Fr700LineOptions,
    Fr700Nak,
    Fr700NakCode,
    Fr700Reply,
    Fr700ReplyParser,
    Fr700Request,
    encode_ack,
    encode_data_reply,
    encode_host_ack,
    encode_nak,
    encode_reoutput_request,
    requests,
)
from sj300_async.fr700 import _request_parser as codec_request_parser
from sj300_async.fr700._codes import Fr700Instruction as I
from sj300_async.fr700._line_frames import Fr700LineFramer, request_from_frame
from sj300_async.simulator.fr700 import Fr700SimulatedBus, corrupt
from sj300_async.wire import BadFrame, Discarded
from sj300_async.wire._enums import Direction
from sj300_async.wire._frames import FrameRole, LineFrame

from .fr700wire import ACK, CR, ENQ, ETX, LF, NAK, STX, ref_sum

PROPERTY = settings(max_examples=150, deadline=None)
WAIT_1 = Fr700LineOptions(wait_time_digit=1)

#: Every line configuration: (waiting-time field, terminator).
VARIANTS = [
    pytest.param(wait, term, id=f"{'wait' if wait else 'nowait'}-{name}")
    for wait in (True, False)
    for term, name in ((b"", "none"), (b"\r", "cr"), (b"\r\n", "crlf"))
]
variant_params = pytest.mark.parametrize(("wait_field", "term"), VARIANTS)


def dialect_for(wait_field: bool, term: bytes) -> Fr700Dialect:
    return Fr700Dialect(wait_field=wait_field, terminator=term, send_ack=True)


@dataclass(frozen=True)
class Sent:
    """One frame of a conversation and what the framer must make of it."""

    data: bytes
    outbound: bool  #: the host wrote it
    role: FrameRole
    #: The request (REQUEST) or the reply parser's event (REPLY) expected as ``message``.
    message: object | None
    #: The request waiting for its answer when the frame crossed the line.
    pending: Fr700Request | None


def conversation(dialect: Fr700Dialect) -> list[Sent]:
    """Every frame format, both directions: the builders' requests and the simulator's answers."""
    options = dialect.options
    term = options.terminator
    sim = Fr700SimulatedBus(range(4), wait_field=options.wait_field, terminator=term)
    parser = dialect.new_parser()
    frames: list[Sent] = []

    def answers(request: Fr700Request, data: bytes) -> list[Fr700Reply | BadFrame]:
        """What the drives send back for *data*, recorded; the parser's events."""
        events: list[Fr700Reply | BadFrame] = []
        for sent in sim.receive(data, 0.0):
            (event,) = parser.feed(sent.data)
            assert not isinstance(event, Discarded)
            role = FrameRole.BROKEN if isinstance(event, BadFrame) else FrameRole.REPLY
            message = None if isinstance(event, BadFrame) else event
            frames.append(Sent(sent.data, False, role, message, request))
            events.append(event)
        return events

    def exchange(request: Fr700Request) -> list[Fr700Reply | BadFrame]:
        frames.append(Sent(request.frame, True, FrameRole.REQUEST, request, None))
        events = answers(request, request.frame)
        for event in events:
            if isinstance(event, Fr700Data):  # the host's ACK (format C)
                ack = dialect.acknowledgement(request, event)
                assert ack is not None
                frames.append(Sent(ack, True, FrameRole.HOST_ANSWER, None, request))
                assert not sim.receive(ack, 0.0)
        return events

    exchange(requests.read(1, I.OUTPUT_FREQUENCY, options=options))  # B -> E
    exchange(requests.read(1, I.STATUS, options=options))  # B -> E1
    exchange(requests.set_frequency(1, 50.0, options=options))  # A -> C
    exchange(requests.run(1, Direction.FORWARD, options=options))  # A1 -> C
    exchange(requests.multi_command(2, 0x02, 30.0, options=options))  # A2 -> C1
    exchange(requests.write(1, I.WRITE_SET_FREQUENCY_RAM, 0xFFFF, options=options))  # -> D (C)
    exchange(requests.read(3, I.READ_OPERATION_MODE, options=options))
    exchange(requests.read(9, I.STATUS, options=options))  # nobody there: no answer
    exchange(requests.reset(2, options=options))  # never answered
    # A damaged reply, the host's re-output request (format F), the reply again.
    request = requests.read(0, I.OUTPUT_FREQUENCY, options=options)
    sim.faults.corrupt_next(0)
    (bad,) = exchange(request)
    assert isinstance(bad, BadFrame)
    reoutput = dialect.reoutput_request(request, bad)
    assert reoutput == encode_reoutput_request(0, term)
    frames.append(Sent(reoutput, True, FrameRole.HOST_ANSWER, None, request))
    (again,) = answers(request, reoutput)
    assert isinstance(again, Fr700Data)
    # A request the drives find damaged: they answer NAK 2 (format D).
    good = requests.read(3, I.OUTPUT_CURRENT, options=options).frame
    body_end = len(good) - len(term)
    damaged = good[: body_end - 1] + (b"0" if good[body_end - 1 : body_end] != b"0" else b"1")
    frames.append(Sent(damaged + term, True, FrameRole.BROKEN, None, None))
    answers(request, damaged + term)
    # E2 (six digits) and E3 (a model name) to reads of instructions the library cannot name.
    six = requests.read(1, 0x66, options=options)  # its width is not known: any
    frames.append(Sent(six.frame, True, FrameRole.REQUEST, six, None))
    frames.append(
        Sent(
            encode_data_reply(1, b"00A1B2", term),
            False,
            FrameRole.REPLY,
            Fr700Data(1, b"00A1B2"),
            six,
        )
    )
    model = requests.read(1, 0x67, options=options)
    name = b"FR-A740-2.2K-CHT    "
    frames.append(Sent(model.frame, True, FrameRole.REQUEST, model, None))
    frames.append(
        Sent(encode_data_reply(1, name, term), False, FrameRole.REPLY, Fr700Data(1, name), model)
    )
    return frames


def stream_of(frames: list[Sent]) -> bytes:
    return b"".join(f.data for f in frames)


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


def pieces_of(framer: LineFramer, chunks: list[bytes]) -> list[bytes]:
    pieces = [p for chunk in chunks for p in framer.feed(chunk)]
    return pieces + framer.flush()


def tap(framer: LineFramer, pieces: list[bytes]) -> list[LineFrame]:
    """Classify as a sniffer does: by content, with the request still waiting for its answer."""
    pending: object | None = None
    frames = []
    for piece in pieces:
        frame = framer.classify(piece, outbound=None, pending=pending)
        if frame.role is FrameRole.REQUEST:
            pending = frame.message if frame.expects_reply else None
        elif frame.role is FrameRole.REPLY:
            pending = None
        frames.append(frame)
    return frames


# -- the dialect ------------------------------------------------------------------------------


def test_the_dialect_has_link_type_148_and_builds_its_framer_from_its_options() -> None:
    dialect = Fr700Dialect().configure({"terminator": "crlf", "wait_field": "0"})
    assert dialect.capture_linktype == 148
    framer = dialect.line_framer()
    assert isinstance(framer, Fr700LineFramer)
    assert framer.options == dialect.options
    assert framer.max_piece == MAX_FRAME + 2
    typed: Dialect[Fr700Request, Fr700Reply] = dialect  # the protocol, for mypy --strict
    assert typed.line_framer() is not framer  # a fresh one each time


def test_the_simulator_reads_requests_with_the_codecs_parser() -> None:
    # The drives' request parser moved into the codec (the framer reads requests with it).
    assert sim_fr700.RequestParser is codec_request_parser.RequestParser
    assert sim_fr700.HostRequest is codec_request_parser.HostRequest


# -- every format, both directions ----------------------------------------------------------


@variant_params
def test_every_frame_is_one_piece_and_reads_as_what_it_was(wait_field: bool, term: bytes) -> None:
    dialect = dialect_for(wait_field, term)
    frames = conversation(dialect)
    framer = dialect.line_framer()
    pieces = pieces_of(framer, [stream_of(frames)])
    assert pieces == [f.data for f in frames]
    for sent in frames:
        for outbound in (sent.outbound, None):
            line = framer.classify(sent.data, outbound=outbound, pending=sent.pending)
            assert line.data == sent.data
            assert line.role is sent.role, (sent, outbound, line)
            assert line.message == sent.message
            assert line.summary
            if line.role is FrameRole.REQUEST:
                assert line.check_ok is True
                assert line.expects_reply == (sent.data[3:5] != b"FD")
            else:
                assert not line.expects_reply


@variant_params
def test_a_request_is_the_dialects_own_and_pairs_with_its_reply(
    wait_field: bool, term: bytes
) -> None:
    dialect = dialect_for(wait_field, term)
    frames = conversation(dialect)
    framer = dialect.line_framer()
    lines = tap(framer, pieces_of(framer, [stream_of(frames)]))
    requests_seen = [line for line in lines if line.role is FrameRole.REQUEST]
    assert len(requests_seen) == 12
    for line in requests_seen:
        request = line.message
        assert isinstance(request, Fr700Request)
        assert request.frame == line.data
        assert line.node == request.station
        assert dialect.reply_frame_length(request) >= dialect.shortest_reply_length(request)
        assert dialect.processing_s(request) > 0
    paired = 0
    for request_line, reply_line in itertools.pairwise(lines):
        if request_line.role is FrameRole.REQUEST and reply_line.role is FrameRole.REPLY:
            request, reply = request_line.message, reply_line.message
            assert isinstance(request, Fr700Request)
            assert isinstance(reply, Fr700Ack | Fr700Nak | Fr700Data)
            assert dialect.answers(request, reply)
            paired += 1
    assert paired == 9


def test_request_summaries() -> None:
    framer = Fr700Dialect().line_framer()

    def summary(request: Fr700Request) -> str:
        return framer.classify(request.frame, outbound=True).summary

    assert summary(requests.read(1, I.OUTPUT_FREQUENCY)) == "station 01: read output frequency (6F)"
    assert summary(requests.read(5, I.STATUS)) == "station 05: read status (7A)"
    assert summary(requests.read(1, 7)) == "station 01: read parameter (07)"
    assert summary(requests.read(1, I.READ_SET_FREQUENCY_RAM)) == (
        "station 01: read set frequency RAM (6D)"
    )
    assert summary(requests.run(31, Direction.FORWARD)) == "station 31: run command (FA) 02"
    assert summary(requests.set_frequency(1, 60.0)) == (
        "station 01: write set frequency RAM (ED) 1770"
    )
    assert summary(requests.multi_command(2, 2, 30.0)) == (
        "station 02: multi command (F0) 0000020BB8"
    )
    assert summary(requests.reset(3)) == "station 03: inverter reset (FD) 9696"
    assert summary(requests.write(1, 0xE5, 1)) == "station 01: write instruction (E5) 0001"


def test_reply_and_host_answer_summaries() -> None:
    framer = Fr700Dialect().line_framer()

    def summary(data: bytes, outbound: bool | None = None) -> str:
        return framer.classify(data, outbound=outbound).summary

    assert summary(encode_nak(1, Fr700NakCode.SUM_CHECK)) == "station 01: NAK 2 (sum check error)"
    assert summary(encode_nak(1, 0xA)) == "station 01: NAK A (mode error)"
    assert summary(encode_data_reply(1, b"1770")) == "station 01: data 1770"
    assert summary(encode_ack(1), outbound=False) == "station 01: ACK"
    assert summary(encode_host_ack(1)) == "station 01: host ACK (data received)"
    assert summary(encode_reoutput_request(1)) == "station 01: host NAK (send the data again)"


def test_the_manuals_worked_examples() -> None:
    # ENQ 01 E1 1 07AD F4: a write of H07AD to parameter offset H61, waiting time 10 ms.
    framer = Fr700Dialect().line_framer()
    (piece,) = framer.feed(ENQ + b"01E1107AD" + b"F4" + CR)
    line = framer.classify(piece, outbound=None)
    assert line.role is FrameRole.REQUEST
    assert line.summary == "station 01: write parameter (E1) 07AD"
    assert line.message == requests.write(1, 0xE1, 0x07AD, options=WAIT_1)
    assert line.message == request_from_frame(1, 0xE1, b"07AD", piece)
    # STX 01 1770 ETX 30: 60.00 Hz.
    (piece,) = framer.feed(STX + b"011770" + ETX + b"30" + CR)
    line = framer.classify(piece, outbound=None)
    assert (line.role, line.message, line.check_ok) == (
        FrameRole.REPLY,
        Fr700Data(1, b"1770"),
        True,
    )


# -- chunking ----------------------------------------------------------------------------------


@variant_params
def test_byte_by_byte_gives_the_same_pieces(wait_field: bool, term: bytes) -> None:
    dialect = dialect_for(wait_field, term)
    stream = stream_of(conversation(dialect)) + b"\x00noise\xff" + encode_data_reply(1, b"12", term)
    whole = pieces_of(dialect.line_framer(), [stream])
    assert pieces_of(dialect.line_framer(), [bytes((b,)) for b in stream]) == whole
    assert b"".join(whole) == stream


@PROPERTY
@given(
    variant=st.sampled_from([(w, t) for w in (True, False) for t in (b"", b"\r", b"\r\n")]),
    noise=st.lists(st.tuples(st.integers(0, 40), st.binary(max_size=12)), max_size=4),
    cuts=st.lists(st.integers(min_value=0, max_value=1000), max_size=40),
)
def test_any_chunking_gives_the_same_pieces_and_the_same_reading(
    variant: tuple[bool, bytes], noise: list[tuple[int, bytes]], cuts: list[int]
) -> None:
    dialect = dialect_for(*variant)
    frames = [f.data for f in conversation(dialect)]
    for where, garbage in noise:  # noise between frames, anywhere
        frames.insert(where % (len(frames) + 1), garbage)
    stream = b"".join(frames)
    reference = dialect.line_framer()
    whole = pieces_of(reference, [stream])
    framer = dialect.line_framer()
    chunked = []
    for chunk in split(stream, cuts):
        chunked += framer.feed(chunk)
        assert framer.buffered <= framer.max_piece
    chunked += framer.flush()
    assert chunked == whole
    assert b"".join(chunked) == stream
    assert tap(framer, chunked) == tap(reference, whole)


@PROPERTY
@given(
    variant=st.sampled_from([(w, t) for w in (True, False) for t in (b"", b"\r", b"\r\n")]),
    data=st.lists(
        st.one_of(
            st.binary(max_size=30),
            st.lists(st.sampled_from(b"\x02\x03\x05\x06\x15\r\n01AF7"), max_size=30).map(bytes),
        ),
        max_size=8,
    ),
)
def test_garbage_keeps_every_byte_and_never_grows_a_buffer(
    variant: tuple[bool, bytes], data: list[bytes]
) -> None:
    dialect = dialect_for(*variant)
    framer = dialect.line_framer()
    pieces: list[bytes] = []
    for chunk in data:
        pieces += framer.feed(chunk)
        assert framer.buffered <= framer.max_piece
    pieces += framer.flush()
    assert b"".join(pieces) == b"".join(data)
    for piece in pieces:
        assert 0 < len(piece) <= framer.max_piece
        line = framer.classify(piece, outbound=None)  # never raises
        assert line.data == piece
        assert (line.problem is None) == line.valid


def test_a_long_run_of_garbage_is_cut_to_the_longest_frame() -> None:
    framer = Fr700Dialect().line_framer()
    pieces = framer.feed(b"x" * 1000)
    assert framer.buffered < framer.max_piece
    assert all(len(p) == framer.max_piece for p in pieces)
    assert len(pieces) == 1000 // framer.max_piece
    assert {framer.classify(p, outbound=False).problem for p in pieces} == {"garbage"}


# -- noise and broken frames --------------------------------------------------------------------


@variant_params
def test_noise_between_frames_is_its_own_piece(wait_field: bool, term: bytes) -> None:
    dialect = dialect_for(wait_field, term)
    request = requests.read(1, I.STATUS, options=dialect.options)
    reply = encode_data_reply(1, b"03", term)
    framer = dialect.line_framer()
    pieces = pieces_of(framer, [b"\xff\x00" + request.frame + b"zz" + reply + b"\x7f"])
    assert pieces == [b"\xff\x00", request.frame, b"zz", reply, b"\x7f"]
    roles = [framer.classify(p, outbound=None).role for p in pieces]
    assert roles == [
        FrameRole.NOISE,
        FrameRole.REQUEST,
        FrameRole.NOISE,
        FrameRole.REPLY,
        FrameRole.NOISE,
    ]
    noise = framer.classify(b"zz", outbound=False)
    assert (noise.problem, noise.node, noise.summary) == ("garbage", None, "bytes outside a frame")


@variant_params
def test_a_frame_cut_short_by_a_start_byte_is_noise(wait_field: bool, term: bytes) -> None:
    dialect = dialect_for(wait_field, term)
    request = requests.read(1, I.STATUS, options=dialect.options)
    reply = encode_data_reply(1, b"03", term)
    framer = dialect.line_framer()
    pieces = pieces_of(framer, [request.frame[:4] + reply[:5] + request.frame])
    assert pieces == [request.frame[:4], reply[:5], request.frame]
    for piece in pieces[:2]:
        line = framer.classify(piece, outbound=None)
        assert (line.role, line.problem) == (FrameRole.NOISE, "cut short")


@variant_params
def test_an_incomplete_frame_waits_and_flushes_as_noise(wait_field: bool, term: bytes) -> None:
    dialect = dialect_for(wait_field, term)
    request = requests.set_frequency(1, 50.0, options=dialect.options)
    framer = dialect.line_framer()
    assert framer.feed(request.frame[:6]) == []
    assert framer.buffered == 6
    (piece,) = framer.flush()
    assert piece == request.frame[:6]
    assert framer.buffered == 0
    assert framer.classify(piece, outbound=True).problem == "cut short"


@pytest.mark.parametrize("term", [b"", b"\r", b"\r\n"], ids=["none", "cr", "crlf"])
def test_an_overlong_frame_is_noise_cut_after_the_longest(term: bytes) -> None:
    framer = dialect_for(True, term).line_framer()
    pieces = framer.feed(STX + b"01" + b"7" * 40 + ETX + b"00" + term)
    first = pieces[0]
    # Cut as the reply parser cuts it: after the longest frame (or data field), one byte more.
    assert len(first) == (MAX_FRAME + 1 if term else MAX_FRAME - 2)
    assert framer.classify(first, outbound=False).problem == "overlong"
    assert b"".join(pieces + framer.flush()) == STX + b"01" + b"7" * 40 + ETX + b"00" + term


@variant_params
def test_a_wrong_sum_check_is_a_broken_frame(wait_field: bool, term: bytes) -> None:
    dialect = dialect_for(wait_field, term)
    framer = dialect.line_framer()
    reply = corrupt(encode_data_reply(4, b"1770", term))  # the simulator's own damage
    line = framer.classify(reply, outbound=False)
    assert (line.role, line.node, line.problem, line.check_ok) == (
        FrameRole.BROKEN,
        4,
        "bad sum check",
        False,
    )
    assert line.summary == "broken reply: bad sum check"
    assert not line.valid
    body = b"04" + b"6F" + (b"0" if wait_field else b"")
    request = ENQ + body + (b"00" if ref_sum(body) != b"00" else b"01") + term
    line = framer.classify(request, outbound=None)
    assert (line.role, line.node, line.problem, line.check_ok) == (
        FrameRole.BROKEN,
        4,
        "bad sum check",
        False,
    )
    assert line.summary == "broken request: bad sum check"


@variant_params
def test_other_broken_frames_say_why(wait_field: bool, term: bytes) -> None:
    framer = dialect_for(wait_field, term).line_framer()

    def problem(data: bytes) -> tuple[FrameRole, str | None, bool | None]:
        line = framer.classify(data + term, outbound=None)
        return line.role, line.problem, line.check_ok

    broken = FrameRole.BROKEN
    assert problem(corrupt(encode_ack(3, b""))) == (broken, "bad station", None)
    assert problem(corrupt(encode_nak(3, 2, b""))) == (broken, "bad station", None)
    assert problem(NAK + b"03x") == (broken, "bad characters", None)
    assert problem(STX + b"0" + ETX + b"00") == (broken, "too short", None)
    if term:  # without a terminator these lengths cannot be told (the frame ends by its length)
        assert problem(ACK + b"031") == (broken, "bad length", None)
        assert problem(ENQ + b"016F" + b"0" * 4 + ref_sum(b"016F0000")) == (
            broken,
            "bad length",
            None,
        )
        assert problem(ENQ + b"01") == (broken, "bad length", None)
        assert problem(ENQ + b"0") == (broken, "too short", None)


# -- telling who spoke ------------------------------------------------------------------------


def test_the_ack_reads_by_the_pending_request_on_a_tap() -> None:
    framer = Fr700Dialect().line_framer()
    ack = encode_ack(1)
    write_1 = requests.set_frequency(1, 50.0)

    def role(pending: object | None, outbound: bool | None = None) -> FrameRole:
        return framer.classify(ack, outbound=outbound, pending=pending).role

    # The drive's acknowledgement of a write to that station...
    assert role(write_1) is FrameRole.REPLY
    assert framer.classify(ack, outbound=None, pending=write_1).message == Fr700Ack(1)
    # ...the host's "data received" otherwise.
    assert role(requests.read(1, I.OUTPUT_FREQUENCY)) is FrameRole.HOST_ANSWER
    assert role(requests.multi_command(1, 2, 10.0)) is FrameRole.HOST_ANSWER
    assert role(requests.set_frequency(2, 50.0)) is FrameRole.HOST_ANSWER
    assert role(requests.reset(1)) is FrameRole.HOST_ANSWER
    assert role(None) is FrameRole.HOST_ANSWER
    assert role(object()) is FrameRole.HOST_ANSWER
    # A known direction decides.
    assert role(None, outbound=False) is FrameRole.REPLY
    assert role(write_1, outbound=True) is FrameRole.HOST_ANSWER
    host = framer.classify(ack, outbound=True)
    assert (host.node, host.message, host.expects_reply) == (1, None, False)


def test_a_nak_reads_by_its_length() -> None:
    framer = Fr700Dialect().line_framer()
    for outbound in (True, False, None):
        drive = framer.classify(encode_nak(1, 2), outbound=outbound)
        assert (drive.role, drive.message) == (FrameRole.REPLY, Fr700Nak(1, Fr700NakCode(2)))
        host = framer.classify(encode_reoutput_request(1), outbound=outbound)
        assert (host.role, host.message) == (FrameRole.HOST_ANSWER, None)


def test_content_decides_an_enq_or_stx_frame_whatever_the_direction() -> None:
    # Local echo reaches the host in the request's shape: still a request.
    framer = Fr700Dialect().line_framer()
    request = requests.read(1, I.STATUS)
    assert framer.classify(request.frame, outbound=False).message == request
    assert framer.classify(encode_data_reply(1, b"03"), outbound=True).role is FrameRole.REPLY


def test_a_piece_of_two_frames_is_broken() -> None:
    framer = Fr700Dialect().line_framer()
    line = framer.classify(encode_host_ack(1) + encode_host_ack(2), outbound=True)
    assert (line.role, line.problem) == (FrameRole.BROKEN, "bad length")


# -- the line configurations ------------------------------------------------------------------


def test_the_waiting_time_field_decides_a_requests_length() -> None:
    with_field = requests.read(1, I.STATUS, options=dialect_for(True, b"\r").options).frame
    without = requests.read(1, I.STATUS, options=dialect_for(False, b"\r").options).frame
    assert len(with_field) == len(without) + 1
    wrong = dialect_for(False, b"\r").line_framer().classify(with_field, outbound=True)
    assert (wrong.role, wrong.problem) == (FrameRole.BROKEN, "bad length")
    # Without a terminator the field moves where the frame ends: read back by the other
    # configuration, the frame ends one byte early.
    framer = dialect_for(False, b"").line_framer()
    pieces = pieces_of(framer, [requests.read(1, I.STATUS).frame.removesuffix(CR)])
    assert [len(p) for p in pieces] == [7, 1]


def test_with_crlf_a_frame_waits_for_its_lf_and_tolerates_a_missing_one() -> None:
    framer = dialect_for(True, b"\r\n").line_framer()
    reply = encode_data_reply(1, b"1770", b"\r\n")
    assert framer.feed(reply[:-1]) == []  # the CR: is an LF next?
    assert framer.feed(reply[-1:]) == [reply]
    request = requests.read(1, I.STATUS, options=framer.options)
    pieces = pieces_of(framer, [reply[:-1] + request.frame])
    assert pieces == [reply[:-1], request.frame]
    line = framer.classify(reply[:-1], outbound=False)
    assert (line.role, line.message) == (FrameRole.REPLY, Fr700Data(1, b"1770"))


def test_with_cr_an_lf_is_noise() -> None:
    framer = dialect_for(True, b"\r").line_framer()
    reply = encode_data_reply(1, b"1770", b"\r\n")
    assert pieces_of(framer, [reply]) == [reply[:-1], LF]
    assert framer.classify(LF, outbound=False).role is FrameRole.NOISE


def test_without_a_terminator_a_three_character_nak_waits_for_the_next_byte() -> None:
    framer = dialect_for(True, b"").line_framer()
    reoutput = encode_reoutput_request(1, b"")
    reply = encode_data_reply(1, b"1770", b"")
    assert framer.feed(reoutput) == []  # a NAK code may follow
    assert framer.feed(reply) == [reoutput, reply]
    assert framer.feed(encode_nak(1, 2, b"")) == [encode_nak(1, 2, b"")]  # its code: done
    assert framer.feed(reoutput) == []
    assert framer.flush() == [reoutput]


@variant_params
def test_the_framer_agrees_with_the_reply_parser(wait_field: bool, term: bytes) -> None:
    dialect = dialect_for(wait_field, term)
    replies = [f for f in conversation(dialect) if not f.outbound]
    framer = dialect.line_framer()
    for sent in replies:
        (event,) = Fr700ReplyParser(term).feed(sent.data)
        line = framer.classify(sent.data, outbound=False)
        if isinstance(event, BadFrame):
            assert line.role is FrameRole.BROKEN
        else:
            assert line.message == event
