"""The codec's fast paths against the general paths they shortcut (hypothesis).

- ``FrameSplitter.feed`` splits a chunk at its CRs and decodes clean pieces at
  once; the state machine (``_run``) alone must give the very same events,
  Discarded events included, stats and buffer, for any stream cut any way.
- ``ReplyParser._decode_body`` checks the usual reply shapes in their
  cheapest form; the general path (``_decode_reply_body``) must agree on
  every body, valid or not, and the counters must too.
- The payload decoders check with ``isdigit()``/``a2b_hex()``, read with
  ``float()``/``int()`` and build through slot setters or an unfrozen twin;
  a reference written the plain way (regular expressions, ``int()``, the
  dataclasses' own constructors) must agree on every input: the same
  objects (equal, same repr and hash, still frozen) or the same refusal.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import re
from collections.abc import Callable
from functools import reduce
from operator import xor
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async import (
    Direction,
    InputMonitor,
    InverterStatus,
    MonitorData,
    NakCode,
    OutputTerminal,
    RemoteProtocolError,
    StatusA,
    StatusB,
    StatusC,
    TripHistory,
    TripRecord,
    TripStatusB,
    TripStatusC,
)
from sj300_async.sj300 import (
    AckDataReply,
    AckReply,
    DataReply,
    NakReply,
    Reply,
    ReplyParser,
    RequestParser,
    decode_monitor,
    decode_parameter_value,
    decode_status,
    decode_trip_history,
    encode_reply,
)
from sj300_async.sj300._parser import _decode_reply_body
from sj300_async.sj300._payloads import _input_monitor, _output_terminal, _trip_status_b
from sj300_async.wire import BadFrame, Discarded
from sj300_async.wire._fast_construct import slot_setters, unfrozen_twin

PROPERTY = settings(max_examples=300, deadline=None)
STX = b"\x02"
ACK = b"\x06"
NAK = b"\x15"
CR = b"\r"
MAX_BODY = 444


def bcc(body: bytes) -> bytes:
    return b"%02X" % reduce(xor, body, 0)


# -- strategies ----------------------------------------------------------------------------

nodes = st.integers(min_value=1, max_value=32)
digit_strings = {
    n: st.binary(min_size=n, max_size=n).map(lambda b: bytes(48 + x % 10 for x in b))
    for n in (2, 8)
}
decimal_fields = st.one_of(
    st.integers(min_value=0, max_value=99_999_999).map(lambda v: b"%08d" % v),
    st.integers(min_value=0, max_value=9_999_999).map(lambda v: b"-%07d" % v),
    st.just(b"-0000000"),
)
hex_fields = st.lists(st.sampled_from(b"0123456789abcdefABCDEF"), min_size=8, max_size=8).map(bytes)


def concat(*parts: st.SearchStrategy[bytes]) -> st.SearchStrategy[bytes]:
    return st.tuples(*parts).map(b"".join)


status_data = digit_strings[8]
monitor_data = concat(*[decimal_fields] * 4, hex_fields, hex_fields, *[decimal_fields] * 7)
trip_data = st.lists(decimal_fields, min_size=55, max_size=55).map(b"".join)
replies: st.SearchStrategy[Reply] = st.one_of(
    st.builds(AckReply, nodes),
    st.builds(AckDataReply, nodes, st.one_of(decimal_fields, digit_strings[2])),
    st.builds(DataReply, nodes, st.one_of(status_data, monitor_data, trip_data)),
    st.builds(NakReply, nodes, st.integers(min_value=0, max_value=99).map(NakCode)),
)

#: Characters that break a field in every way a parser could overlook.
nasty = st.sampled_from(b"0123456789-+_ eE.xAaFfGg\x00\x02\x06\x15\r\n\t\xff")


@st.composite
def mutated(draw: st.DrawFn, data: bytes) -> bytes:
    """*data* with up to three characters replaced by nasty ones."""
    out = bytearray(data)
    for _ in range(draw(st.integers(min_value=0, max_value=3))):
        if out:
            out[draw(st.integers(min_value=0, max_value=len(out) - 1))] = draw(nasty)
    return bytes(out)


def with_bcc(body: bytes, lower: bool) -> bytes:
    check = bcc(body)
    return body + (check.lower() if lower else check)


@st.composite
def reply_bodies(draw: st.DrawFn) -> bytes:
    """Bodies (STX and CR stripped) of every length the fast path knows, and others.

    Most carry a correct BCC, so that the checks after it are exercised: a
    valid reply with a few characters replaced, or one shape's node and
    marker with another shape's data.
    """
    kind = draw(st.integers(min_value=0, max_value=3))
    if kind == 0:  # a valid reply, untouched or mutated, BCC recomputed or not
        frame = encode_reply(draw(replies))
        body, check = frame[1:-3], frame[-3:-1]
        if draw(st.booleans()):
            body = draw(mutated(body))
        if draw(st.booleans()):
            return body + check  # the original's BCC: wrong if a character changed
        return with_bcc(body, draw(st.booleans()))
    if kind == 1:  # node, marker and data from any shape, any combination
        node = draw(
            st.one_of(
                st.sampled_from([b"01", b"32", b"00", b"33", b"1 ", b"FF"]),
                nodes.map(lambda n: b"%02d" % n),
            )
        )
        marker = draw(st.sampled_from([b"", ACK, NAK, b"0", b"-"]))
        data = draw(
            st.one_of(
                status_data, monitor_data, trip_data, decimal_fields, digit_strings[2], st.just(b"")
            )
        )
        return with_bcc(draw(mutated(node + marker + data)), draw(st.booleans()))
    if kind == 2:  # random bytes of a fast-path length, with a matching BCC
        length = draw(st.sampled_from([3, 5, 10, 11, 106, 442]))
        return with_bcc(draw(st.binary(min_size=length, max_size=length)), draw(st.booleans()))
    return draw(st.binary(max_size=450))


# -- the decode fast path ---------------------------------------------------------------------


@PROPERTY
@given(reply_bodies())
def test_decode_body_fast_path_equals_the_general_path(body: bytes) -> None:
    parser = ReplyParser()
    event = parser._decode_body(body)
    expected = _decode_reply_body(body)
    assert event == expected
    assert type(event) is type(expected)
    assert repr(event) == repr(expected)
    if STX[0] not in body and CR[0] not in body and len(body) <= MAX_BODY:  # one frame
        parser = ReplyParser()
        assert parser.feed(STX + body + CR) == [expected]
        bad = isinstance(expected, BadFrame)
        assert (parser.stats.frames, parser.stats.bad_frames) == ((0, 1) if bad else (1, 0))


@pytest.mark.parametrize(
    "body",
    [
        b"01" + ACK + b"0000000" + b"00",  # ACK + 7 digits: no such reply
        b"01" + ACK + b"00000000" + b"0",  # 13 characters, status shape + 1
        b"01" + b"000000000",  # 9 digits of data
        b"01" + b"0",  # one digit of data
        b"01" + NAK + b"0A",
        b"01" + ACK + b"-0000001",
        b"01" + b"-" + b"0" * 103,
    ],
)
def test_decode_body_fast_path_refuses_near_misses(body: bytes) -> None:
    for case in (False, True):
        full = with_bcc(body, case)
        assert ReplyParser()._decode_body(full) == _decode_reply_body(full)


#: One valid body of every shape the fast path decodes (BCC left off).
VALID_BODIES = [
    b"07" + ACK,
    b"07" + ACK + b"01",
    b"07" + NAK + b"16",
    b"07" + b"03010300",
    b"07" + ACK + b"00000500",
    b"07" + b"00005000" * 4 + b"000001aF" + b"0000002A" + b"00012345" * 7,
    b"07" + b"00000003" * 55,
]


@pytest.mark.parametrize("body", VALID_BODIES, ids=lambda b: f"len-{len(b) + 2}")
def test_decode_body_every_character_replaced(body: bytes) -> None:
    # Each position, each kind of wrong character, with a BCC that matches:
    # the fast path must refuse what the general path refuses, wherever it is.
    for i, char in itertools.product(range(len(body)), b"0-+ eAaG\x02\x06\x15\xff"):
        changed = with_bcc(body[:i] + bytes([char]) + body[i + 1 :], i % 2 == 0)
        assert ReplyParser()._decode_body(changed) == _decode_reply_body(changed), (i, char)


# -- the framing shortcut ---------------------------------------------------------------------


class MachineOnlyReplyParser(ReplyParser):
    """Every chunk through the state machine: what the shortcut must reproduce."""

    def feed(self, data: bytes | bytearray | memoryview) -> list[Any]:
        events: list[Any] = []
        self._partial = self._run(bytes(data), self._partial, events)
        return events


class MachineOnlyRequestParser(RequestParser):
    def feed(self, data: bytes | bytearray | memoryview) -> list[Any]:
        events: list[Any] = []
        self._partial = self._run(bytes(data), self._partial, events)
        return events


#: Around the longest legal body (444), where a frame becomes overlong.
overlong_lengths = st.one_of(st.integers(min_value=442, max_value=447), st.integers(440, 700))
noisy_byte = st.one_of(st.sampled_from(b"\x02\x06\x15\r0123456789ABF"), st.integers(0, 255))
stream_parts = st.lists(
    st.one_of(
        replies.map(encode_reply),
        reply_bodies().map(lambda body: STX + body + CR),
        st.lists(noisy_byte, max_size=60).map(bytes),
        overlong_lengths.map(lambda n: STX + b"7" * n),
        overlong_lengths.map(lambda n: STX + b"7" * n + CR),
        st.just(CR + CR),
        st.just(STX + STX),
    ),
    max_size=12,
)


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


def run_both(
    fast: ReplyParser | RequestParser, machine: ReplyParser | RequestParser, chunks: list[bytes]
) -> None:
    for chunk in chunks:
        assert fast.feed(chunk) == machine.feed(chunk), chunk
        assert fast._partial == machine._partial
        assert fast.buffered <= fast.max_body
    assert repr(fast.stats) == repr(machine.stats)
    assert fast.reset() == machine.reset()


@PROPERTY
@given(stream_parts, st.lists(st.integers(min_value=0), max_size=30))
def test_feed_equals_the_state_machine(parts: list[bytes], cuts: list[int]) -> None:
    stream = b"".join(parts)
    run_both(ReplyParser(), MachineOnlyReplyParser(), split(stream, cuts))


@PROPERTY
@given(stream_parts)
def test_feed_equals_the_state_machine_byte_by_byte(parts: list[bytes]) -> None:
    stream = b"".join(parts)
    chunks = [stream[i : i + 1] for i in range(len(stream))]
    run_both(ReplyParser(), MachineOnlyReplyParser(), chunks)


@PROPERTY
@given(stream_parts)
def test_feed_equals_the_state_machine_part_by_part(parts: list[bytes]) -> None:
    # Each part its own chunk: whole frames alone in a chunk (the shortcut
    # for one whole frame), bodies of 444 and 445 bytes around the longest
    # legal one, frames with an STX inside, and all of these after a partial
    # frame or noise.
    run_both(ReplyParser(), MachineOnlyReplyParser(), parts)


def test_a_chunk_of_one_whole_frame_is_one_event() -> None:
    frame = encode_reply(AckReply(7))
    parser = ReplyParser()
    assert parser.feed(frame) == [AckReply(7)]
    assert parser.feed(bytearray(frame)) == [AckReply(7)]
    assert parser.stats.frames == 2
    assert parser.buffered == 0
    # The same bytes after a partial frame end that frame instead.
    assert parser.feed(STX + b"07") == []
    events = parser.feed(frame)
    assert len(events) == 2
    assert isinstance(events[0], Discarded)
    assert events[1] == AckReply(7)


@PROPERTY
@given(
    st.lists(
        st.one_of(
            st.sampled_from([b"01041A", b"FF01000", b"0102" + b"0" * 16, b"0105"]).map(
                lambda body: STX + body + bcc(body) + CR
            ),
            st.lists(noisy_byte, max_size=40).map(bytes),
            st.integers(min_value=20, max_value=40).map(lambda n: STX + b"1" * n),
        ),
        max_size=10,
    ),
    st.lists(st.integers(min_value=0), max_size=20),
)
def test_request_feed_equals_the_state_machine(parts: list[bytes], cuts: list[int]) -> None:
    stream = b"".join(parts)
    run_both(RequestParser(), MachineOnlyRequestParser(), split(stream, cuts))


@pytest.mark.parametrize(
    "chunks",
    [
        [b"\x02" * 100_000],
        [(b"\x02" + b"1" * 443) * 200],
        [b"\r" * 100_000],
        [b"junk\r" * 20_000],
        [b"\x02" + b"5" * 100_000 + b"\r"],
    ],
    ids=["stx", "stx-443", "cr", "junk-cr", "overlong"],
)
def test_adversarial_chunks_equal_the_state_machine(chunks: list[bytes]) -> None:
    # Also a smoke test for cost: each of these is linear in the chunk.
    run_both(ReplyParser(), MachineOnlyReplyParser(), chunks)


def test_discards_and_bad_frames_are_logged_only_at_debug(caplog: pytest.LogCaptureFixture) -> None:
    stream = b"junk" + STX + b"01" + ACK + b"00" + CR  # garbage, then a bad BCC
    with caplog.at_level(logging.INFO, logger="sj300_async.parser"):
        ReplyParser().feed(stream)
    assert caplog.records == []
    with caplog.at_level(logging.DEBUG, logger="sj300_async.parser"):
        events = ReplyParser().feed(stream)
    assert [type(e) for e in events] == [Discarded, BadFrame]
    assert [r.getMessage().split(" (")[0] for r in caplog.records] == [
        "discarded 4 bytes",
        "bad frame",
    ]


# -- the payload decoders -------------------------------------------------------------------

_DEC = rb"(?:[0-9]{8}|-[0-9]{7})"
_HEX8 = rb"[0-9A-Fa-f]{8}"
REF_STATUS = re.compile(rb"[0-9]{8}")
REF_MONITOR = re.compile(_DEC * 4 + _HEX8 * 2 + _DEC * 7)
REF_TRIP = re.compile(_DEC * 55)
REF_PARAMETER = re.compile(_DEC)


def _fields(data: bytes) -> list[int]:
    return [int(data[i : i + 8]) for i in range(0, len(data), 8)]


def ref_status(data: bytes) -> InverterStatus:
    if not REF_STATUS.fullmatch(data):
        raise RemoteProtocolError("malformed")
    return InverterStatus(StatusA(int(data[0:2])), StatusB(int(data[2:4])), StatusC(int(data[4:6])))


def ref_monitor(data: bytes) -> MonitorData:
    if not REF_MONITOR.fullmatch(data):
        raise RemoteProtocolError("malformed")
    f = _fields(data[:32] + data[48:])
    inputs, outputs = int(data[32:40], 16), int(data[40:48], 16)
    return MonitorData(
        output_frequency_hz=f[0] / 100,
        output_current_a=f[1] / 10,
        direction=Direction(f[2]),
        pid_feedback_percent=f[3] / 100,
        input_terminals=InputMonitor(inputs) if inputs < 1 << 9 else _input_monitor(inputs),
        output_terminals=OutputTerminal(outputs) if outputs < 1 << 6 else _output_terminal(outputs),
        frequency_conversion=f[4] / 100,
        output_torque_percent=f[5],
        output_voltage_v=f[6] / 10,
        power_kw=f[7] / 10,
        run_time_h=f[9],
        power_on_time_h=f[10],
    )


def ref_trip_history(data: bytes) -> TripHistory:
    if not REF_TRIP.fullmatch(data):
        raise RemoteProtocolError("malformed")
    f = _fields(data)
    records = []
    for i in range(6):
        r = f[1 + 9 * i : 10 + 9 * i]
        if r[2] < 0:
            raise RemoteProtocolError("negative status B")
        records.append(
            TripRecord(
                trip_factor=r[0],
                status_a=StatusA(r[1]),
                status_b=TripStatusB(r[2]) if r[2] < 1 << 8 else _trip_status_b(r[2]),
                status_c=TripStatusC(r[3]),
                output_frequency_hz=r[4] / 10,
                run_time_h=r[5],
                output_current_a=r[6] / 10,
                output_voltage_v=r[7] / 10,
                power_on_time_h=r[8],
            )
        )
    return TripHistory(f[0], tuple(records))


def ref_parameter(data: bytes) -> int:
    if not REF_PARAMETER.fullmatch(data):
        raise RemoteProtocolError("malformed")
    return int(data)


def same_outcome(
    decoder: Callable[[bytes], object], reference: Callable[[bytes], object], data: bytes
) -> None:
    try:
        expected = reference(data)
    except RemoteProtocolError:
        with pytest.raises(RemoteProtocolError):
            decoder(data)
        return
    got = decoder(data)
    assert type(got) is type(expected)
    assert got == expected
    assert repr(got) == repr(expected)
    assert hash(got) == hash(expected)
    if dataclasses.is_dataclass(got) and not isinstance(got, type):
        # Built through a twin or slot setters, the object is still frozen.
        name = dataclasses.fields(got)[0].name
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(got, name, 0)
        assert dataclasses.replace(got) == got


trip_records = st.tuples(
    st.one_of(st.integers(0, 99).map(lambda v: b"%08d" % v), decimal_fields),  # factor
    st.one_of(st.integers(0, 12).map(lambda v: b"%08d" % v), decimal_fields),  # status A
    st.one_of(st.integers(0, 300).map(lambda v: b"%08d" % v), decimal_fields),  # status B
    st.one_of(st.integers(0, 10).map(lambda v: b"%08d" % v), decimal_fields),  # status C
    *[decimal_fields] * 5,
).map(b"".join)
trip_history_data = concat(decimal_fields, *[trip_records] * 6)
small_monitor_fields = st.one_of(st.integers(0, 3).map(lambda v: b"%08d" % v), decimal_fields)
monitor_data_any = concat(
    *[decimal_fields] * 2,
    small_monitor_fields,
    decimal_fields,
    hex_fields,
    hex_fields,
    *[decimal_fields] * 7,
)


@PROPERTY
@given(st.one_of(status_data, st.binary(max_size=9)).flatmap(mutated))
def test_decode_status_equals_the_reference(data: bytes) -> None:
    same_outcome(decode_status, ref_status, data)


@PROPERTY
@given(monitor_data_any.flatmap(mutated))
def test_decode_monitor_equals_the_reference(data: bytes) -> None:
    same_outcome(decode_monitor, ref_monitor, data)


@PROPERTY
@given(trip_history_data.flatmap(mutated))
def test_decode_trip_history_equals_the_reference(data: bytes) -> None:
    same_outcome(decode_trip_history, ref_trip_history, data)


@PROPERTY
@given(st.one_of(decimal_fields, st.binary(max_size=9)).flatmap(mutated))
def test_decode_parameter_value_equals_the_reference(data: bytes) -> None:
    same_outcome(decode_parameter_value, ref_parameter, data)


@pytest.mark.parametrize(
    ("decoder", "reference", "data"),
    [
        (decode_status, ref_status, b"03010300"),
        (decode_monitor, ref_monitor, VALID_BODIES[5][2:]),
        (decode_trip_history, ref_trip_history, VALID_BODIES[6][2:]),
        (decode_parameter_value, ref_parameter, b"00000500"),
    ],
    ids=["status", "monitor", "trip-history", "parameter"],
)
def test_decoders_every_character_replaced(
    decoder: Callable[[bytes], object], reference: Callable[[bytes], object], data: bytes
) -> None:
    for i, char in itertools.product(range(len(data)), b"0-+_ .eEaG\t\xff"):
        same_outcome(decoder, reference, data[:i] + bytes([char]) + data[i + 1 :])


def test_negative_zero_scaled_fields_decode_as_zero() -> None:
    # float("-0000000") is -0.0; the decoders give int()'s 0.0 (same repr).
    monitor = decode_monitor(b"-0000000" * 4 + b"0" * 16 + b"-0000000" * 7)
    assert repr(monitor.output_frequency_hz) == "0.0"
    assert repr(monitor.power_kw) == "0.0"
    assert monitor == ref_monitor(b"-0000000" * 4 + b"0" * 16 + b"-0000000" * 7)
    trips = decode_trip_history(b"-0000000" * 55)
    assert all(repr(r.output_voltage_v) == "0.0" for r in trips.records)


@pytest.mark.parametrize("cls", [MonitorData, TripRecord])
def test_unfrozen_twins_have_the_same_slots(cls: type[Any]) -> None:
    twin = unfrozen_twin(cls)
    fields = tuple(f.name for f in dataclasses.fields(cls))
    assert twin.__dict__["__slots__"] == cls.__dict__["__slots__"] == fields


@pytest.mark.parametrize(
    ("cls", "values"),
    [
        (AckReply, (7,)),
        (AckDataReply, (7, b"00000500")),
        (DataReply, (7, b"03010300")),
        (NakReply, (7, NakCode(16))),
        (InverterStatus, (StatusA.RUNNING, StatusB.RUNNING, StatusC.STOP)),
        (TripHistory, (0, ())),
    ],
)
def test_slot_setters_build_what_the_constructor_builds(cls: type, values: tuple[Any, ...]) -> None:
    obj: object = object.__new__(cls)
    for setter, value in zip(slot_setters(cls), values, strict=True):
        setter(obj, value)
    reference = cls(*values)
    assert (obj, repr(obj), hash(obj)) == (reference, repr(reference), hash(reference))
