"""The FR-700 reply parser: a byte stream from the line in, typed reply events out.

Usage (sans-IO: no sockets, no clocks, no asyncio)::

    parser = Fr700ReplyParser(terminator=b"\\r")
    for event in parser.feed(chunk):      # any chunk size, any split
        ...                               # Fr700Ack / Fr700Nak / Fr700Data /
                                          # BadFrame / Discarded

Three kinds of frame start with their own byte::

    STX station(2) data(n) ETX sum(2)     E, E1, E2, E3 (and C1)
    ACK station(2)                        C
    NAK station(2) code(1)                D

each followed by the line's terminator (none, CR, or CR LF). How a frame
ends depends on it, and the parser is told which one the line uses:

- With a CR terminator every frame ends at its CR, whatever its length; the
  length is then checked. A data reply is read by STX..ETX, never by a
  fixed width: the width depends on the instruction. With CR LF, an LF right
  after the CR belongs to the frame; a missing LF is tolerated (the CR has
  already ended the frame).
- Without a terminator, the ACK frame is three bytes and the NAK frame four;
  a data reply ends two characters (the sum) after its ETX.

State machine (all of it in :meth:`Fr700ReplyParser.feed`)::

    HUNTING --STX/ACK/NAK--> IN_FRAME --end (see above)--> frame --> HUNTING
       |                        |                         (CR LF: AFTER_CR --LF?--> HUNTING)
       \\--other bytes: Discarded(GARBAGE)
                                 IN_FRAME --STX/ACK/NAK--> Discarded(RESTARTED), new frame
                                 IN_FRAME --longer than 26 bytes--> Discarded(OVERLONG) --> HUNTING

A frame is yielded as a reply only when it is whole and right: the sum
matches (data replies; C and D have no sum; the sum is read in either
case), the station is 00..1F and the NAK code one hex character (upper
case, as the reference lists them), and the data is printable ASCII. Otherwise it is
a :class:`~sj300_async.BadFrame` (never an exception, never a wrong value).
The buffer of an incomplete frame never exceeds :data:`MAX_FRAME` bytes.

Decision where the reference is silent: a start byte inside a frame begins
a new frame (the old one is discarded as restarted). Data characters and
sums are hex or text, never a control byte, so a start byte inside a frame
can only mean the frame was cut short.
"""

from __future__ import annotations

import enum
import logging
import re
from typing import Final

from ..wire import (
    BadFrame,
    BadFrameReason,
    Discarded,
    DiscardReason,
    LocalProtocolError,
    ParserStats,
)
from ._codec import MAX_REPLY_DATA, parse_station
from ._codes import ACK, CR, ETX, LF, NAK, Fr700NakCode
from ._events import Fr700Ack, Fr700Data, Fr700Nak, Fr700Reply

__all__ = ["MAX_FRAME", "Fr700ReplyParser"]

_log = logging.getLogger("sj300_async.fr700.parser")

#: The longest reply without its terminator: STX, station, 20 characters of data, ETX, sum.
MAX_FRAME: Final = 1 + 2 + MAX_REPLY_DATA + 1 + 2
#: The longest part of a data reply before its ETX.
_MAX_BEFORE_ETX: Final = 1 + 2 + MAX_REPLY_DATA
_START: Final = re.compile(b"[\x02\x06\x15]")
_FIXED_LENGTH: Final = {ACK: 3, NAK: 4}
_HEX_VALUES: Final = {b"%02X" % i: i for i in range(256)} | {b"%02x" % i: i for i in range(256)}
_PRINTABLE: Final = re.compile(rb"[\x20-\x7e]+")
_NAK_CODES: Final = {ord(b"%X" % code): Fr700NakCode(code) for code in range(16)}
_CR: Final = bytes((CR,))
_ETX: Final = bytes((ETX,))
_LF: Final = LF

Event = Fr700Reply | BadFrame | Discarded


class _State(enum.Enum):
    HUNTING = "hunting"  #: between frames: every byte but a start byte is garbage
    IN_FRAME = "in frame"  #: collecting a frame
    AFTER_CR = "after CR"  #: (CR LF lines) a frame just ended at its CR; an LF belongs to it


def decode_frame(frame: bytes) -> Fr700Reply | BadFrame:
    """Decode one whole frame (start byte through sum, no terminator) into a reply or BadFrame."""
    kind = frame[0]
    if kind in _FIXED_LENGTH:
        station = parse_station(frame[1:3])
        if len(frame) != _FIXED_LENGTH[kind]:
            return BadFrame(BadFrameReason.BAD_LENGTH, frame, station)
        if station is None:
            return BadFrame(BadFrameReason.BAD_NODE, frame)
        if kind == ACK:
            return Fr700Ack(station)
        code = _NAK_CODES.get(frame[3])
        if code is None:
            return BadFrame(BadFrameReason.BAD_CHARACTERS, frame, station)
        return Fr700Nak(station, code)
    # STX station data ETX sum: at least one data character.
    if len(frame) < 7:
        return BadFrame(BadFrameReason.TOO_SHORT, frame, parse_station(frame[1:3]))
    station = parse_station(frame[1:3])
    if frame[-3] != ETX:
        return BadFrame(BadFrameReason.BAD_LENGTH, frame, station)
    check = _HEX_VALUES.get(frame[-2:])
    if check is None or check != sum(frame[1:-3]) & 0xFF:
        return BadFrame(BadFrameReason.BAD_BCC, frame, station)
    if station is None:
        return BadFrame(BadFrameReason.BAD_NODE, frame)
    data = frame[3:-3]
    if not _PRINTABLE.fullmatch(data):
        return BadFrame(BadFrameReason.BAD_CHARACTERS, frame, station)
    return Fr700Data(station, data)


class Fr700ReplyParser:
    """Parses FR-700 replies out of a byte stream (see the module docstring).

    Args:
        terminator: the line's terminator: ``b""``, ``b"\\r"`` or ``b"\\r\\n"``.

    Raises:
        LocalProtocolError: another terminator.

    Attributes:
        stats: counters of frames, bad frames and every discarded byte.
    """

    def __init__(self, terminator: bytes = b"\r") -> None:
        if terminator not in (b"", b"\r", b"\r\n"):
            raise LocalProtocolError(
                f"terminator must be b'', b'\\r' or b'\\r\\n', got {terminator!r}"
            )
        self.terminator = terminator
        self.stats = ParserStats()
        self._state = _State.HUNTING
        self._partial = bytearray()
        # Without a terminator: the whole frame's length once known (ACK/NAK at
        # once, a data reply when its ETX arrives), else None.
        self._need: int | None = None

    @property
    def buffered(self) -> int:
        """Bytes held for an incomplete frame (never more than :data:`MAX_FRAME`)."""
        return len(self._partial)

    def reset(self) -> list[Event]:
        """Forget any partial frame (e.g. after draining the line); return it as discarded."""
        events: list[Event] = []
        if self._state is _State.IN_FRAME:
            self._discard(events, DiscardReason.RESTARTED, bytes(self._partial))
            self.stats.restarted_frames += 1
        self._partial.clear()
        self._need = None
        self._state = _State.HUNTING
        return events

    def feed(self, data: bytes | bytearray | memoryview) -> list[Event]:
        """Consume a chunk; return the events it completed (possibly none)."""
        if type(data) is not bytes:
            data = bytes(data)
        events: list[Event] = []
        pos, end = 0, len(data)
        while pos < end:
            state = self._state
            if state is _State.AFTER_CR:
                if data[pos] == _LF:
                    pos += 1
                self._state = _State.HUNTING
            elif state is _State.HUNTING:
                pos = self._hunt(data, pos, events)
            elif self.terminator:
                pos = self._until_cr(data, pos, events)
            else:
                pos = self._by_length(data, pos, events)
        return events

    # -- states --------------------------------------------------------------------

    def _hunt(self, data: bytes, pos: int, events: list[Event]) -> int:
        match = _START.search(data, pos)
        if match is None:
            self._discard(events, DiscardReason.GARBAGE, data[pos:])
            return len(data)
        start = match.start()
        if start > pos:
            self._discard(events, DiscardReason.GARBAGE, data[pos:start])
        self._begin(data[start])
        return start + 1

    def _begin(self, start_byte: int) -> None:
        self._partial.append(start_byte)
        self._need = _FIXED_LENGTH.get(start_byte)
        self._state = _State.IN_FRAME

    def _until_cr(self, data: bytes, pos: int, events: list[Event]) -> int:
        cr = data.find(_CR, pos)
        stop = cr if cr >= 0 else len(data)
        resume = self._cut_short(data, pos, stop, MAX_FRAME, events)
        if resume is not None:
            return resume
        if cr < 0:
            self._partial += data[pos:]
            return len(data)
        frame = bytes(self._partial) + data[pos:cr]
        self._partial.clear()
        self._state = _State.AFTER_CR if self.terminator == b"\r\n" else _State.HUNTING
        self._emit(frame, events)
        return cr + 1

    def _by_length(self, data: bytes, pos: int, events: list[Event]) -> int:
        need = self._need
        if need is None:  # a data reply before its ETX
            etx = data.find(_ETX, pos)
            stop = etx if etx >= 0 else len(data)
            resume = self._cut_short(data, pos, stop, _MAX_BEFORE_ETX, events)
            if resume is not None:
                return resume
            if etx < 0:
                self._partial += data[pos:]
                return len(data)
            self._partial += data[pos : etx + 1]
            self._need = len(self._partial) + 2  # the sum
            return etx + 1
        stop = min(len(data), pos + need - len(self._partial))
        resume = self._cut_short(data, pos, stop, need, events)
        if resume is not None:
            return resume
        self._partial += data[pos:stop]
        if len(self._partial) == need:
            frame = bytes(self._partial)
            self._partial.clear()
            self._need = None
            self._state = _State.HUNTING
            self._emit(frame, events)
        return stop

    def _cut_short(
        self, data: bytes, pos: int, stop: int, limit: int, events: list[Event]
    ) -> int | None:
        """Handle a restart or an overlong frame within ``data[pos:stop]``.

        Returns where feeding goes on when one happened, else None.
        """
        match = _START.search(data, pos, stop)
        first = match.start() if match is not None else stop
        if len(self._partial) + (first - pos) > limit:
            # Longer than any legal frame: abandon it at byte limit + 1, as a
            # byte-by-byte feed would, and hunt for the next start byte.
            cut = pos + limit + 1 - len(self._partial)
            self._discard(events, DiscardReason.OVERLONG, bytes(self._partial) + data[pos:cut])
            self.stats.overlong_frames += 1
            self._partial.clear()
            self._need = None
            self._state = _State.HUNTING
            return cut
        if match is not None:
            # A new frame starts before this one ended: the partial frame is lost.
            self._discard(events, DiscardReason.RESTARTED, bytes(self._partial) + data[pos:first])
            self.stats.restarted_frames += 1
            self._partial.clear()
            self._begin(data[first])
            return first + 1
        return None

    # -- results --------------------------------------------------------------------

    def _emit(self, frame: bytes, events: list[Event]) -> None:
        event = decode_frame(frame)
        if type(event) is BadFrame:
            self.stats.bad_frames += 1
            if _log.isEnabledFor(logging.DEBUG):
                _log.debug("bad frame (%s): %s", event.reason.value, frame.hex(" "))
        else:
            self.stats.frames += 1
        events.append(event)

    def _discard(self, events: list[Event], reason: DiscardReason, data: bytes) -> None:
        self.stats.discarded_bytes += len(data)
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("discarded %d bytes (%s): %s", len(data), reason.value, data.hex(" "))
        events.append(Discarded(reason, data))
