"""The sans-IO Modbus TCP framer and codec (sj300_async/gateway/modbus/_framing.py).

Every reader runs three ways, as h11's tests do: the whole buffer, byte by
byte, and with trailing data; a property test checks that the events do not
depend on how the stream is cut. The module imports no I/O (the AST scan).
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st
from sans_io_scan import module_violations

from sj300_async.gateway.modbus._framing import (
    MAX_READ,
    MAX_WRITE,
    NEED_DATA,
    Event,
    Exc,
    FrameError,
    Framer,
    ReadRegisters,
    Refused,
    WriteRegisters,
    encode_exception,
    encode_registers,
    encode_written,
    excerpt,
)


def adu(tid: int, unit: int, pdu: bytes, *, protocol: int = 0, length: int | None = None) -> bytes:
    """An MBAP header and *pdu* (the length field right unless given)."""
    size = 1 + len(pdu) if length is None else length
    return struct.pack(">HHHB", tid, protocol, size, unit) + pdu


def events(framer: Framer) -> list[Event]:
    out: list[Event] = []
    while (event := framer.next_event()) is not NEED_DATA:
        assert not isinstance(event, type(NEED_DATA))
        out.append(event)
        if isinstance(event, FrameError):
            break
    return out


def feed_whole(data: bytes) -> list[Event]:
    framer = Framer()
    framer.receive_data(data)
    return events(framer)


def feed_bytewise(data: bytes) -> list[Event]:
    framer = Framer()
    out: list[Event] = []
    for i in range(len(data)):
        framer.receive_data(data[i : i + 1])
        out += events(framer)
        if out and isinstance(out[-1], FrameError):
            break
    return out


def decode(data: bytes) -> list[Event]:
    """The events of *data*, the same whole and byte by byte (checked here)."""
    whole = feed_whole(data)
    assert feed_bytewise(data) == whole
    return whole


READ = bytes.fromhex("03 0064 000e")  # FC3, 14 registers at 100


def test_the_module_imports_no_io() -> None:
    assert module_violations("gateway.modbus._framing", allowed=set()) == []


def test_a_read_whole_bytewise_and_with_trailing_data() -> None:
    frame = adu(0x1234, 7, READ)
    expected = ReadRegisters(0x1234, 7, 3, 100, 14)
    assert decode(frame) == [expected]
    framer = Framer()
    framer.receive_data(frame + frame[:5])  # the next frame's first bytes stay buffered
    assert events(framer) == [expected]
    assert framer.buffered == 5
    framer.receive_data(frame[5:])
    assert events(framer) == [expected]
    assert framer.buffered == 0


def test_pipelined_requests_come_out_in_order_with_their_ids() -> None:
    stream = (
        adu(1, 1, READ)
        + adu(2, 2, bytes.fromhex("06 03e8 0001"))
        + adu(3, 3, bytes.fromhex("10 2ee8 0002 04 0000 0258"))
        + adu(4, 4, bytes.fromhex("04 0000 0004"))
    )
    assert decode(stream) == [
        ReadRegisters(1, 1, 3, 100, 14),
        WriteRegisters(2, 2, 6, 1000, (1,)),
        WriteRegisters(3, 3, 16, 12008, (0, 600)),
        ReadRegisters(4, 4, 4, 0, 4),
    ]


@pytest.mark.parametrize(
    ("pdu", "code"),
    [
        (bytes.fromhex("03 0000 0000"), Exc.ILLEGAL_VALUE),  # quantity 0
        (bytes.fromhex("03 0000 007e"), Exc.ILLEGAL_VALUE),  # 126 > 125
        (bytes.fromhex("04 0000 007e"), Exc.ILLEGAL_VALUE),
        (bytes.fromhex("03 0000 00"), Exc.ILLEGAL_VALUE),  # PDU too short
        (bytes.fromhex("03 0000 0001 00"), Exc.ILLEGAL_VALUE),  # too long
        (bytes.fromhex("03 ffff 0002"), Exc.ILLEGAL_ADDRESS),  # past 65535
        (bytes.fromhex("06 0000"), Exc.ILLEGAL_VALUE),
        (bytes.fromhex("10 0000 007c 02 0000"), Exc.ILLEGAL_VALUE),  # 124 > 123
        (bytes.fromhex("10 0000 0000 00"), Exc.ILLEGAL_VALUE),  # quantity 0
        (bytes.fromhex("10 0000 0002 03 000000"), Exc.ILLEGAL_VALUE),  # byte count != 2n
        (bytes.fromhex("10 0000 0002 04 0000"), Exc.ILLEGAL_VALUE),  # data short
        (bytes.fromhex("10 0000 0001"), Exc.ILLEGAL_VALUE),  # no byte count
        (bytes.fromhex("10 ffff 0002 04 00000000"), Exc.ILLEGAL_ADDRESS),
        *(
            (bytes([function]) + bytes(4), Exc.ILLEGAL_FUNCTION)
            for function in (1, 2, 5, 8, 11, 12, 15, 17, 20, 21, 22, 23, 24, 43, 0x64, 0x83)
        ),
        (bytes([0x2B]), Exc.ILLEGAL_FUNCTION),  # function code only
    ],
)
def test_the_specs_exception_for_each_bad_request(pdu: bytes, code: Exc) -> None:
    [event] = decode(adu(9, 1, pdu))
    assert isinstance(event, Refused)
    assert (event.transaction_id, event.unit_id, event.function, event.code) == (
        9,
        1,
        pdu[0],
        code,
    )


def test_the_largest_requests_pass() -> None:
    assert decode(adu(1, 1, bytes.fromhex("03 ff83 007d"))) == [
        ReadRegisters(1, 1, 3, 0xFF83, MAX_READ)
    ]
    values = tuple(range(MAX_WRITE))
    pdu = struct.pack(f">BHHB{MAX_WRITE}H", 16, 0, MAX_WRITE, 2 * MAX_WRITE, *values)
    assert decode(adu(1, 1, pdu)) == [WriteRegisters(1, 1, 16, 0, values)]


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (adu(1, 1, READ, protocol=1), "protocol id 1, not 0"),
        (adu(1, 1, READ, protocol=0xFFFF), "protocol id 65535, not 0"),
        (adu(1, 1, b"", length=1), "length 1 outside 2..254"),
        (adu(1, 1, b"", length=0), "length 0 outside 2..254"),
        (adu(1, 1, b"", length=255), "length 255 outside 2..254"),
        (b"\xff" + adu(1, 1, READ), "protocol id 256, not 0"),  # a stray byte first
    ],
)
def test_a_broken_header_stops_the_framer(frame: bytes, reason: str) -> None:
    [event] = decode(frame)
    assert event == FrameError(reason, frame[:7])  # the header that broke
    framer = Framer()
    framer.receive_data(frame)
    assert framer.next_event() == framer.next_event() == event  # for good
    framer.receive_data(adu(2, 1, READ))
    assert framer.next_event() == event


def test_a_stray_byte_after_a_frame_stops_the_next_one() -> None:
    stream = adu(1, 1, READ) + b"\x00" + adu(2, 1, READ)
    first, error = decode(stream)
    assert first == ReadRegisters(1, 1, 3, 100, 14)
    assert isinstance(error, FrameError)


def test_the_buffer_is_capped() -> None:
    framer = Framer(max_buffer=100)
    framer.receive_data(adu(1, 1, READ) * 9)  # 108 bytes, all whole frames
    [error] = events(framer)
    assert isinstance(error, FrameError)
    assert error.reason == "more than 100 bytes waiting"
    assert len(error.data) == 32


def test_the_answers_byte_for_byte() -> None:
    assert encode_registers(0x1234, 7, 3, [1, 0xFFFF]) == bytes.fromhex(
        "1234 0000 0007 07 03 04 0001 ffff"
    )
    assert encode_written(1, 2, 6, 1000, 1) == bytes.fromhex("0001 0000 0006 02 06 03e8 0001")
    assert encode_written(1, 2, 16, 12008, 2) == bytes.fromhex("0001 0000 0006 02 10 2ee8 0002")
    assert encode_exception(5, 9, 3, Exc.PATH_UNAVAILABLE) == bytes.fromhex(
        "0005 0000 0003 09 83 0a"
    )
    assert encode_exception(5, 9, 0x83, 1) == bytes.fromhex("0005 0000 0003 09 83 01")


def test_the_excerpt_is_bounded_hex() -> None:
    assert excerpt(b"\x00\xff\n") == "00 ff 0a"
    assert excerpt(bytes(100), limit=2) == "00 00 ... (100 bytes)"


_frames = st.one_of(
    st.builds(
        lambda tid, unit, function, data: adu(tid, unit, bytes([function]) + data),
        st.integers(0, 0xFFFF),
        st.integers(0, 255),
        st.integers(0, 255),
        st.binary(max_size=252),
    ),
    st.builds(
        lambda tid, unit, a, n: adu(tid, unit, struct.pack(">BHH", 3, a, n)),
        st.integers(0, 0xFFFF),
        st.integers(0, 255),
        st.integers(0, 0xFFFF),
        st.integers(0, 200),
    ),
)


@given(st.lists(_frames, max_size=8), st.binary(max_size=40), st.data())
def test_events_do_not_depend_on_the_cuts(
    frames: list[bytes], tail: bytes, data: st.DataObject
) -> None:
    stream = b"".join(frames) + tail
    whole = feed_whole(stream)
    cuts = sorted(data.draw(st.sets(st.integers(1, max(1, len(stream) - 1)), max_size=10)))
    framer = Framer()
    cut: list[Event] = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        framer.receive_data(stream[start:end])
        cut += events(framer)
        if cut and isinstance(cut[-1], FrameError):
            break
    assert cut == whole
    # Every well-framed frame gives exactly one event, with its own ids.
    assert len(whole) >= len(frames)
    for frame, event in zip(frames, whole, strict=False):
        assert not isinstance(event, FrameError)
        assert (event.transaction_id, event.unit_id) == struct.unpack_from(">H2xxxB", frame)
