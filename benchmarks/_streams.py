"""Realistic reply streams: a polling host's mix of SJ300 replies, and its Modbus ASCII twin.

The SJ300 stream is what a host polling a bus of drives reads back: mostly
monitor blocks and status words, parameter reads, ACKs of writes, the odd
trip history and NAK, from nodes 1..32, with values a running drive reports.

The peer stream pairs every SJ300 frame with one Modbus ASCII response of the
*nearest legal length on the wire*. A Modbus ASCII frame is
``: addr(2) func(2) data(2n) LRC(2) CR LF``, i.e. 9 + 2n characters, and a
read-holding-registers response of N registers has n = 1 + 2N, so 11 + 4N
characters. Where Modbus cannot be as short as the SJ300 frame (ACK 7 bytes,
NAK 9 bytes) the shortest legal response is taken (11 characters), which
favours the peer. See :data:`KINDS` for the pairing.

Both streams are cut into the same sequence of chunk sizes (random 1..64
bytes, fixed seed), the way a USB-serial adapter hands bytes to the host.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from pymodbus.framer import FramerAscii
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU
from pymodbus.pdu.other_message import ReadExceptionStatusResponse
from pymodbus.pdu.register_message import ReadHoldingRegistersResponse

from sj300_async import (
    Direction,
    InputMonitor,
    InverterStatus,
    MonitorData,
    NakCode,
    OutputTerminal,
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
    encode_monitor,
    encode_reply,
    encode_status,
    encode_trip_history,
)

__all__ = [
    "KINDS",
    "MAX_CHUNK",
    "ReplyKind",
    "Streams",
    "build_streams",
    "chunk_sizes",
    "split",
]

#: Largest chunk a read returns (a full-speed USB bulk packet).
MAX_CHUNK = 64

_MODBUS_FRAMER = FramerAscii(DecodePDU(is_server=False))


def _nearest_register_count(wire_length: int) -> int:
    # 11 + 4N characters; ties go to the longer frame (never happens for SJ300 sizes).
    return max(1, round((wire_length - 11) / 4))


@dataclass(frozen=True, slots=True)
class ReplyKind:
    """One kind of reply in the mix, and how its Modbus twin is made."""

    #: Short label, e.g. ``"03 monitor"``.
    label: str
    #: Share of the stream, in percent.
    percent: float
    #: Builds the SJ300 reply from the random source and a node.
    make: Callable[[random.Random, int], Reply]
    #: What the Modbus twin is, for the printed composition.
    peer_label: str
    #: Builds the Modbus twin for an SJ300 frame of the given wire length.
    make_peer: Callable[[random.Random, int, int], ModbusPDU]


def _registers(rng: random.Random, wire_length: int, node: int) -> ModbusPDU:
    count = _nearest_register_count(wire_length)
    values = [rng.randrange(10_000) for _ in range(count)]
    return ReadHoldingRegistersResponse(registers=values, dev_id=node)


def _exception_status(rng: random.Random, _wire_length: int, node: int) -> ModbusPDU:
    return ReadExceptionStatusResponse(status=rng.randrange(256), dev_id=node)


def _exception(rng: random.Random, _wire_length: int, node: int) -> ModbusPDU:
    return ExceptionResponse(3, exception_code=rng.choice((2, 3, 4)), device_id=node)


_STATUSES = (
    (StatusA.RUNNING, StatusB.RUNNING, StatusC.CONSTANT_SPEED),
    (StatusA.RUNNING, StatusB.RUNNING, StatusC.ACCELERATING),
    (StatusA.STOPPING, StatusB.RUNNING, StatusC.DECELERATING),
    (StatusA.INITIAL, StatusB.STOPPED, StatusC.STOP),
    (StatusA.TRIP, StatusB.TRIPPED, StatusC.STOP),
)


def _status(rng: random.Random, node: int) -> Reply:
    return DataReply(node, encode_status(InverterStatus(*rng.choice(_STATUSES))))


def _monitor(rng: random.Random, node: int) -> Reply:
    running = rng.random() < 0.85
    freq_hz = round(rng.uniform(5.0, 60.0), 2) if running else 0.0
    run_h = rng.randrange(60_000)
    data = MonitorData(
        output_frequency_hz=freq_hz,
        output_current_a=round(rng.uniform(0.5, 32.0), 1) if running else 0.0,
        direction=rng.choice((Direction.FORWARD, Direction.REVERSE)) if running else Direction.STOP,
        pid_feedback_percent=round(rng.uniform(0.0, 100.0), 2),
        input_terminals=InputMonitor(rng.getrandbits(9)),
        output_terminals=OutputTerminal(rng.getrandbits(6)),
        frequency_conversion=round(freq_hz * 29.5, 2),  # B086 = 29.5: rpm of a 4-pole motor
        output_torque_percent=rng.randrange(150) if running else 0,
        output_voltage_v=round(rng.uniform(180.0, 460.0), 1) if running else 0.0,
        power_kw=round(rng.uniform(0.1, 15.0), 1) if running else 0.0,
        run_time_h=run_h,
        power_on_time_h=run_h + rng.randrange(20_000),
    )
    return DataReply(node, encode_monitor(data))


_EMPTY_RECORD = TripRecord(
    0, StatusA.INITIAL, TripStatusB(0), TripStatusC.RESET, 0.0, 0, 0.0, 0.0, 0
)
_TRIPS = (
    (1, TripStatusB(0)),
    (2, TripStatusB(0)),
    (3, TripStatusB(0)),
    (5, TripStatusB(0)),
    (7, TripStatusB.OVER_VOLTAGE),
    (9, TripStatusB.UNDER_VOLTAGE),
    (12, TripStatusB(0)),
    (14, TripStatusB.GROUND_FAULT),
    (21, TripStatusB.THERMAL),
    (30, TripStatusB.IGBT_U | TripStatusB.IGBT_V),
)


def _trip_record(rng: random.Random) -> TripRecord:
    factor, cause = rng.choice(_TRIPS)
    run_h = rng.randrange(60_000)
    return TripRecord(
        trip_factor=factor,
        status_a=rng.choice((StatusA.RUNNING, StatusA.STOPPING, StatusA.INITIAL)),
        status_b=cause,
        status_c=rng.choice(tuple(TripStatusC)),
        output_frequency_hz=round(rng.uniform(0.0, 60.0), 1),
        run_time_h=run_h,
        output_current_a=round(rng.uniform(0.0, 60.0), 1),
        output_voltage_v=round(rng.uniform(0.0, 460.0), 1),
        power_on_time_h=run_h + rng.randrange(20_000),
    )


def _trip_history(rng: random.Random, node: int) -> Reply:
    filled = rng.randrange(7)
    records = [_trip_record(rng) for _ in range(filled)] + [_EMPTY_RECORD] * (6 - filled)
    total = filled + rng.randrange(50) if filled else 0
    return DataReply(node, encode_trip_history(TripHistory(total, tuple(records))))


def _parameter(rng: random.Random, node: int) -> Reply:
    # Typical 06 answers: times (x 100), frequencies (x 100), codes and percentages.
    value = rng.choice((rng.randrange(360_000), rng.randrange(40_000), rng.randrange(100)))
    return AckDataReply(node, b"%08d" % value)


def _ack(_rng: random.Random, node: int) -> Reply:
    return AckReply(node)


_NAK_CODES = (NakCode.ABNORMAL_PARAMETER, NakCode.EXECUTION_DISABLED, NakCode.CHECKSUM)


def _nak(rng: random.Random, node: int) -> Reply:
    return NakReply(node, rng.choice(_NAK_CODES))


#: The mix of a host polling a bus: percentages sum to 100.
KINDS: tuple[ReplyKind, ...] = (
    ReplyKind("03 monitor", 35, _monitor, "read holding registers, 25 regs", _registers),
    ReplyKind("04 status", 30, _status, "read holding registers, 1 reg", _registers),
    ReplyKind(
        "06 parameter (ACK + 8)", 20, _parameter, "read holding registers, 1 reg", _registers
    ),
    ReplyKind(
        "ACK (00/01/02/07 writes)", 12, _ack, "read exception status (07)", _exception_status
    ),
    ReplyKind("05 trip history", 2, _trip_history, "read holding registers, 109 regs", _registers),
    ReplyKind("NAK", 1, _nak, "exception response (0x83)", _exception),
)


@dataclass(frozen=True, slots=True)
class Streams:
    """The two wire streams, frame by frame, and what they are made of."""

    #: Index into :data:`KINDS` of each frame, in stream order.
    kinds: tuple[int, ...]
    #: SJ300 reply frames (STX .. CR), in stream order.
    ours: tuple[bytes, ...]
    #: The Modbus ASCII twin of each frame (':' .. CR LF), in the same order.
    peer: tuple[bytes, ...]

    def count(self, kind: int) -> int:
        """Number of frames of one kind (an index into :data:`KINDS`)."""
        return self.kinds.count(kind)


def _exact_counts(frames: int) -> list[int]:
    # Largest-remainder rounding: the counts sum to exactly `frames`.
    raw = [frames * k.percent / 100 for k in KINDS]
    counts = [int(x) for x in raw]
    by_remainder = sorted(range(len(raw)), key=lambda i: raw[i] - counts[i], reverse=True)
    for i in by_remainder[: frames - sum(counts)]:
        counts[i] += 1
    return counts


def build_streams(frames: int, seed: int) -> Streams:
    """Build *frames* replies in the mix of :data:`KINDS`, shuffled, and their Modbus twins."""
    rng = random.Random(seed)
    kinds = [i for i, n in enumerate(_exact_counts(frames)) for _ in range(n)]
    rng.shuffle(kinds)
    ours: list[bytes] = []
    peer: list[bytes] = []
    for index in kinds:
        kind = KINDS[index]
        node = rng.randint(1, 32)
        frame = encode_reply(kind.make(rng, node))
        ours.append(frame)
        peer.append(_MODBUS_FRAMER.buildFrame(kind.make_peer(rng, len(frame), node)))
    return Streams(tuple(kinds), tuple(ours), tuple(peer))


def chunk_sizes(total: int, seed: int, max_chunk: int = MAX_CHUNK) -> list[int]:
    """Random read sizes 1..max_chunk (fixed seed) that add up to at least *total*."""
    rng = random.Random(seed)
    sizes: list[int] = []
    covered = 0
    while covered < total:
        size = rng.randint(1, max_chunk)
        sizes.append(size)
        covered += size
    return sizes


def split(stream: bytes, sizes: Sequence[int]) -> list[bytes]:
    """Cut *stream* into consecutive chunks of the given sizes (the last may be shorter)."""
    chunks: list[bytes] = []
    pos = 0
    for size in sizes:
        if pos >= len(stream):
            break
        chunks.append(stream[pos : pos + size])
        pos += size
    return chunks
