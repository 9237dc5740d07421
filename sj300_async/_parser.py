"""The reply parser: a byte stream from the line in, typed reply events out.

Usage (sans-IO: no sockets, no clocks, no asyncio)::

    parser = ReplyParser()
    for event in parser.feed(chunk):      # any chunk size, any split
        ...                               # AckReply / AckDataReply / DataReply /
                                          # NakReply / BadFrame / Discarded

``feed`` was chosen over h11's ``receive_data`` / ``next_event`` pair: a reply
stream has no back-pressure to express, and returning the whole list for a
chunk is both simpler for the caller and cheaper per frame.

A frame is yielded as a reply only when its BCC matches *and* every field has
the characters its shape requires (digits where digits belong, hex for the
two terminal items of the monitor block). Otherwise it is a
:class:`BadFrame` event: never an exception, never a wrong value.
"""

from __future__ import annotations

import re
from typing import Final

from ._bcc import xor_bytes
from ._codes import NakCode
from ._constants import (
    ACK,
    MAX_NODE,
    MAX_REPLY_BODY,
    MIN_NODE,
    MONITOR_DATA_LEN,
    NAK,
    STATUS_DATA_LEN,
    TRIP_HISTORY_DATA_LEN,
)
from ._events import (
    AckDataReply,
    AckReply,
    BadFrame,
    BadFrameReason,
    DataReply,
    NakReply,
    Reply,
)
from ._framing import FrameSplitter

__all__ = ["DATA_PATTERNS", "DECIMAL_FIELD", "ReplyParser", "parse_bcc", "parse_node"]

# One 8-character decimal field: eight digits, or a minus sign and seven digits.
_DEC = rb"(?:[0-9]{8}|-[0-9]{7})"
_HEX8 = rb"[0-9A-Fa-f]{8}"
#: One 8-character decimal field, as a compiled pattern.
DECIMAL_FIELD: Final = re.compile(_DEC)

#: The character pattern of each data reply, by length.
DATA_PATTERNS: Final[dict[int, re.Pattern[bytes]]] = {
    STATUS_DATA_LEN: re.compile(rb"[0-9]{8}"),
    # items 1-4 decimal, 5-6 terminal bit patterns in hex, 7-13 decimal
    MONITOR_DATA_LEN: re.compile(_DEC * 4 + _HEX8 * 2 + _DEC * 7),
    TRIP_HISTORY_DATA_LEN: re.compile(_DEC + rb"{55}"),
}
#: Data after ACK: command 06 (a value, possibly signed) and command 09 ("00"/"01").
_ACK_DATA_PATTERNS: Final[dict[int, re.Pattern[bytes]]] = {
    8: DECIMAL_FIELD,
    2: re.compile(rb"[0-9]{2}"),
}
_TWO_DIGITS = re.compile(rb"[0-9]{2}")
_HEX_VALUES: Final = {b"%02X" % i: i for i in range(256)} | {b"%02x" % i: i for i in range(256)}
# Smallest legal reply body: node(2) + ACK + BCC(2).
_MIN_REPLY_BODY: Final = 5


def parse_bcc(chars: bytes) -> int | None:
    """Return the value of two hex BCC characters (either case), or None if they are not hex."""
    return _HEX_VALUES.get(chars)


_NODES: Final = {b"%02d" % n: n for n in range(MIN_NODE, MAX_NODE + 1)}


def parse_node(chars: bytes) -> int | None:
    """Return the node number of two decimal characters 01..32, or None."""
    return _NODES.get(chars)


class ReplyParser(FrameSplitter[Reply]):
    """Parses replies from drives out of a byte stream (see the module docstring).

    Attributes:
        stats: counters of frames, bad frames and every discarded byte.
    """

    def __init__(self) -> None:
        super().__init__(MAX_REPLY_BODY)

    def _decode_body(self, body: bytes) -> Reply | BadFrame:
        if len(body) < _MIN_REPLY_BODY:
            return BadFrame(BadFrameReason.TOO_SHORT, body)
        check = parse_bcc(body[-2:])
        if check is None or check != xor_bytes(body[:-2]):
            return BadFrame(BadFrameReason.BAD_BCC, body)
        node = parse_node(body[:2])
        if node is None:
            return BadFrame(BadFrameReason.BAD_NODE, body)
        marker = body[2]
        if marker == ACK:
            data = body[3:-2]
            if not data:
                return AckReply(node)
            pattern = _ACK_DATA_PATTERNS.get(len(data))
            if pattern is None:
                return BadFrame(BadFrameReason.BAD_LENGTH, body, node)
            if not pattern.fullmatch(data):
                return BadFrame(BadFrameReason.BAD_CHARACTERS, body, node)
            return AckDataReply(node, data)
        if marker == NAK:
            code = body[3:-2]
            if len(code) != 2:
                return BadFrame(BadFrameReason.BAD_LENGTH, body, node)
            if not _TWO_DIGITS.fullmatch(code):
                return BadFrame(BadFrameReason.BAD_CHARACTERS, body, node)
            return NakReply(node, NakCode(int(code)))
        data = body[2:-2]
        pattern = DATA_PATTERNS.get(len(data))
        if pattern is None:
            return BadFrame(BadFrameReason.BAD_LENGTH, body, node)
        if not pattern.fullmatch(data):
            return BadFrame(BadFrameReason.BAD_CHARACTERS, body, node)
        return DataReply(node, data)
