"""The drive's side of the FR-700 line: the host's frames in, requests and answers out.

Sans-IO, in the codec because more than the simulator reads requests: the
simulated drives (:mod:`sj300_async.simulator.fr700`, which re-exports it)
and the line framer (:mod:`._line_frames`, captures and the sniffer) split
and judge the host's frames alike (:func:`request_frame_length`,
:func:`decode_host_frame`).

What the host sends::

    ENQ station(2) instruction(2) [wait(1)] data(0/2/4/10) sum(2)   A, A1, A2, B
    ACK station(2)                                                  C: read data received
    NAK station(2)                                                  F: send the data again

each followed by the line's terminator. A drive reads a frame the way the
drives' manual implies: with a CR terminator up to the CR, then checks the
length its instruction calls for; without one, by that length alone (the
instruction says it: a read has no data, HF0 ten digits, the A1 writes two,
every other write four).

What a frame turns into, in the order a drive checks:

=============================================  =================================
station not 00..1F                             BadRequest(None): nobody answers
a character that is not 0-9 or A-F             BadRequest(station, CHARACTER 7)
the length does not fit the instruction        BadRequest(station, PROTOCOL 3)
  (e.g. the waiting-time field missing)
the sum does not match                         BadRequest(station, SUM_CHECK 2)
a start byte before the frame ended            BadRequest(station, PROTOCOL 3)
otherwise                                      HostRequest / HostAnswer
=============================================  =================================

Decisions where the reference is silent: with CR LF an LF right after the
CR belongs to the frame, a missing LF is tolerated; lower-case hex is a
character error (the reference lists only 0-9 and A-F); a damaged host
answer (C / F) is ignored, as there is nothing a drive could answer to it.
"""

from __future__ import annotations

import enum
import logging
import re
from dataclasses import dataclass
from typing import Final

from ..wire import Discarded, DiscardReason, ParserStats
from ._codec import parse_station, sum_check
from ._codes import A1_INSTRUCTIONS, ACK, CR, ENQ, LF, NAK, Fr700Instruction, Fr700NakCode

__all__ = [
    "MAX_REQUEST",
    "BadRequest",
    "HostAnswer",
    "HostRequest",
    "RequestEvent",
    "RequestParser",
    "data_length",
    "decode_host_frame",
    "request_frame_length",
]

# The simulated drives log under this name, as when this module was theirs.
_log = logging.getLogger("sj300_async.simulator.fr700")

#: The longest request without its terminator: an A2 with the waiting-time field.
MAX_REQUEST: Final = 1 + 2 + 2 + 1 + 10 + 2
_START: Final = re.compile(b"[\x05\x06\x15]")
_HEX_UPPER: Final = re.compile(rb"[0-9A-F]+")
_CR: Final = bytes((CR,))


@dataclass(frozen=True, slots=True)
class HostRequest:
    """A whole, valid request frame."""

    station: int
    instruction: int
    #: The waiting-time digit (0..15), or None on a line without the field.
    wait_digit: int | None
    #: The data characters (hex digits; empty for a read).
    data: bytes


@dataclass(frozen=True, slots=True)
class HostAnswer:
    """The host's answer to read data: ACK (C) or, with *reoutput*, NAK (F)."""

    station: int
    reoutput: bool


@dataclass(frozen=True, slots=True)
class BadRequest:
    """A frame a drive rejects: *station* (when readable) answers NAK *code*."""

    station: int | None
    code: Fr700NakCode
    frame: bytes


RequestEvent = HostRequest | HostAnswer | BadRequest | Discarded


def data_length(instruction: int) -> int:
    """Data characters the instruction's request carries (format B, A1, A or A2)."""
    if instruction < 0x80:
        return 0
    if instruction == Fr700Instruction.MULTI_COMMAND:
        return 10
    return 2 if instruction in A1_INSTRUCTIONS else 4


def request_frame_length(head: bytes | bytearray, *, wait_field: bool) -> int | None:
    """The length of the host's frame starting *head*, without a terminator, once known.

    An ACK or NAK (C, F) is 3 characters; a request is known from its
    instruction code (5 characters in), and one whose code is not hex ends
    there (a character error).
    """
    if head[0] != ENQ:
        return 3
    if len(head) < 5:
        return None
    try:
        instruction = int(head[3:5], 16)
    except ValueError:
        return 5  # unreadable: end it here, it is a character error
    return 5 + wait_field + data_length(instruction) + 2


def decode_host_frame(frame: bytes, *, wait_field: bool) -> HostRequest | HostAnswer | BadRequest:
    """One whole frame of the host (start byte through sum, no terminator), as a drive reads it."""
    station = parse_station(frame[1:3]) if _HEX_UPPER.fullmatch(frame[1:3]) else None
    if frame[0] != ENQ:
        if len(frame) != 3 or station is None:
            return BadRequest(None, Fr700NakCode.PROTOCOL, frame)
        return HostAnswer(station, reoutput=frame[0] == NAK)
    if station is None:
        return BadRequest(None, Fr700NakCode.CHARACTER, frame)
    if not _HEX_UPPER.fullmatch(frame, 1):
        return BadRequest(station, Fr700NakCode.CHARACTER, frame)
    if len(frame) < 7:
        return BadRequest(station, Fr700NakCode.PROTOCOL, frame)
    instruction = int(frame[3:5], 16)
    if len(frame) != 5 + wait_field + data_length(instruction) + 2:
        return BadRequest(station, Fr700NakCode.PROTOCOL, frame)
    if sum_check(frame[1:-2]) != frame[-2:]:
        return BadRequest(station, Fr700NakCode.SUM_CHECK, frame)
    wait = int(frame[5:6], 16) if wait_field else None
    return HostRequest(station, instruction, wait, frame[5 + wait_field : -2])


class _State(enum.Enum):
    HUNTING = "hunting"
    IN_FRAME = "in frame"
    AFTER_CR = "after CR"


class RequestParser:
    """Parses the host's frames on an FR-700 line (see the module docstring).

    Args:
        wait_field: requests carry the waiting-time character.
        terminator: ``b""``, ``b"\\r"`` or ``b"\\r\\n"``.
    """

    def __init__(self, *, wait_field: bool = True, terminator: bytes = b"\r") -> None:
        self.wait_field = wait_field
        self.terminator = terminator
        self.stats = ParserStats()
        self._state = _State.HUNTING
        self._partial = bytearray()

    @property
    def buffered(self) -> int:
        """Bytes held for an incomplete frame (never more than :data:`MAX_REQUEST`)."""
        return len(self._partial)

    def feed(self, data: bytes) -> list[RequestEvent]:
        """Consume a chunk; return the events it completed."""
        events: list[RequestEvent] = []
        for byte in data:  # requests are short and rare: clarity over speed
            self._step(byte, events)
        return events

    def _step(self, byte: int, events: list[RequestEvent]) -> None:
        state = self._state
        if state is _State.AFTER_CR:
            self._state = _State.HUNTING
            if byte == LF:
                return
            state = _State.HUNTING
        if state is _State.HUNTING:
            if byte in (ENQ, ACK, NAK):
                self._partial.append(byte)
                self._state = _State.IN_FRAME
            else:
                self._discard(events, DiscardReason.GARBAGE, bytes((byte,)))
            return
        if byte in (ENQ, ACK, NAK):  # a new frame before this one ended
            self._restart(events)
            self._partial.append(byte)
            return
        if self.terminator:
            if byte == CR:
                self._finish(events)
                self._state = _State.AFTER_CR if self.terminator == b"\r\n" else _State.HUNTING
                return
            self._partial.append(byte)
            if len(self._partial) > MAX_REQUEST:
                self._overlong(events)
            return
        self._partial.append(byte)
        if len(self._partial) == self._expected_length():
            self._finish(events)
            self._state = _State.HUNTING

    def _expected_length(self) -> int | None:
        """The whole frame's length without a terminator, once it can be known."""
        return request_frame_length(self._partial, wait_field=self.wait_field)

    def _finish(self, events: list[RequestEvent]) -> None:
        frame = bytes(self._partial)
        self._partial.clear()
        event = self._decode(frame)
        if isinstance(event, BadRequest):
            self.stats.bad_frames += 1
            if _log.isEnabledFor(logging.DEBUG):
                _log.debug("bad request (NAK %X): %s", event.code, frame.hex(" "))
        else:
            self.stats.frames += 1
        events.append(event)

    def _decode(self, frame: bytes) -> HostRequest | HostAnswer | BadRequest:
        return decode_host_frame(frame, wait_field=self.wait_field)

    def _restart(self, events: list[RequestEvent]) -> None:
        frame = bytes(self._partial)
        self._partial.clear()
        self.stats.restarted_frames += 1
        station = parse_station(frame[1:3]) if frame[0] == ENQ else None
        if station is not None and _HEX_UPPER.fullmatch(frame[1:3]):
            # An interrupted request: its drive answers it as incomplete (NAK 3).
            self.stats.bad_frames += 1
            events.append(BadRequest(station, Fr700NakCode.PROTOCOL, frame))
        else:
            self._discard(events, DiscardReason.RESTARTED, frame)

    def _overlong(self, events: list[RequestEvent]) -> None:
        self.stats.overlong_frames += 1
        self._discard(events, DiscardReason.OVERLONG, bytes(self._partial))
        self._partial.clear()
        self._state = _State.HUNTING

    def _discard(self, events: list[RequestEvent], reason: DiscardReason, data: bytes) -> None:
        self.stats.discarded_bytes += len(data)
        if events and isinstance(events[-1], Discarded) and events[-1].reason is reason:
            # One event per run of garbage, not one per byte.
            events[-1] = Discarded(reason, events[-1].data + data)
            return
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("discarded %d bytes (%s): %s", len(data), reason.value, data.hex(" "))
        events.append(Discarded(reason, data))
