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

from ..wire import BadFrame, BadFrameReason, slot_setters
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
from ._events import AckDataReply, AckReply, DataReply, NakReply, Reply
from ._framing import FrameSplitter

__all__ = ["DATA_PATTERNS", "DECIMAL_FIELD", "ReplyParser", "parse_bcc", "parse_node"]

#: Short reply bodies decoded once and shared (see ReplyParser._decode_body): the
#: longest body kept (a status reply: node, 8 digits, BCC) and how many.
_CACHED_BODY_MAX: Final = 12
_SHORT_REPLIES_KEPT: Final = 1024
_SHORT_REPLIES: Final[dict[bytes, Reply]] = {}

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


# -- the fast path of ReplyParser._decode_body -------------------------------------------
#
# For each pair of BCC characters (hex, either case), the XOR of the *whole* body
# that a correct BCC implies: XOR(node .. data) is the BCC's value, and the two
# characters themselves add their own bits. Folding the whole body saves cutting
# the BCC off first.
_WHOLE_BODY_XOR: Final = {
    chars: value ^ chars[0] ^ chars[1] for chars, value in _HEX_VALUES.items()
}
_ACK_BODY_LEN: Final = 5  # node ACK BCC
_SHORT_BODY_LEN: Final = 7  # node ACK 2-digits BCC, node NAK code BCC
_STATUS_BODY_LEN: Final = 2 + STATUS_DATA_LEN + 2
_PARAMETER_BODY_LEN: Final = 2 + 1 + 8 + 2  # node ACK value BCC
_MONITOR_BODY_LEN: Final = 2 + MONITOR_DATA_LEN + 2
_TRIP_HISTORY_BODY_LEN: Final = 2 + TRIP_HISTORY_DATA_LEN + 2
_REPLY_BODY_LENGTHS: Final = frozenset(
    (
        _ACK_BODY_LEN,
        _SHORT_BODY_LEN,
        _STATUS_BODY_LEN,
        _PARAMETER_BODY_LEN,
        _MONITOR_BODY_LEN,
        _TRIP_HISTORY_BODY_LEN,
    )
)
# Hex letters -> a digit: after this, isdigit() tells "all hex digits".
_HEX_AS_DIGITS: Final = bytes.maketrans(b"ABCDEFabcdef", b"000000000000")
_NAK_CODES: Final = {b"%02d" % code: NakCode(code) for code in range(100)}

_new = object.__new__
(_set_ack_node,) = slot_setters(AckReply)
_set_ack_data_node, _set_ack_data_data = slot_setters(AckDataReply)
_set_data_node, _set_data_data = slot_setters(DataReply)
_set_nak_node, _set_nak_code = slot_setters(NakReply)


class ReplyParser(FrameSplitter[Reply]):
    """Parses replies from drives out of a byte stream (see the module docstring).

    Attributes:
        stats: counters of frames, bad frames and every discarded byte.
    """

    def __init__(self) -> None:
        super().__init__(MAX_REPLY_BODY)

    def _decode_body(self, body: bytes) -> Reply | BadFrame:
        # Fast paths for a valid reply, with the checks of _decode_general in
        # their cheapest form (bytes.isdigit() is ASCII-only): they return only
        # what _decode_general would return for the same body, and leave
        # everything else (negative values, any defect) to it.
        #
        # A poll gets the same short replies over and over (a drive's status, the
        # ACK of a write, a NAK): each such body is decoded once and its frozen
        # reply shared. Only bodies of up to 12 characters, whose values are
        # few (32 nodes; a status is one of a few hundred combinations), so in
        # a steady poll the table fills once and stays. A parameter value (13)
        # has 10^8 of them: a stream of changing values would empty the table
        # over and over, evicting the statuses with it (the codec benchmark's
        # random values did).
        # A monitor block or a trip history varies, and hashing it costs more
        # than it saves. Bounded all the same; a bad frame is never kept (it
        # is counted each time it comes).
        n = len(body)
        if n <= _CACHED_BODY_MAX:
            known = _SHORT_REPLIES.get(body)
            if known is not None:
                return known
            event = self._decode_short(body)
            if not isinstance(event, BadFrame):
                if len(_SHORT_REPLIES) >= _SHORT_REPLIES_KEPT:
                    _SHORT_REPLIES.clear()
                _SHORT_REPLIES[body] = event
            return event
        if n == _PARAMETER_BODY_LEN:
            return self._decode_short(body)
        # A monitor block or a trip history: decoded here, not in a method of
        # its own (a call less on a third of a poll's replies).
        node = _NODES.get(body[:2])
        if node is None or xor_bytes(body) != _WHOLE_BODY_XOR.get(body[-2:]):
            return self._decode_general(body)  # (also when the BCC is not hex)
        if n == _MONITOR_BODY_LEN:
            # Items 1-4 and 7-13 all digits (no minus sign), items 5-6 hex.
            if (
                body[2:34].isdigit()
                and body[50:106].isdigit()
                and body[34:50].translate(_HEX_AS_DIGITS).isdigit()
            ):
                reply = _new(DataReply)
                _set_data_node(reply, node)
                _set_data_data(reply, body[2:106])
                return reply
        elif n == _TRIP_HISTORY_BODY_LEN:
            data = body[2:-2]
            if data.isdigit():
                reply = _new(DataReply)
                _set_data_node(reply, node)
                _set_data_data(reply, data)
                return reply
        return self._decode_general(body)

    def _decode_short(self, body: bytes) -> Reply | BadFrame:
        """A body of up to 13 characters (ACK, NAK, status, parameter), not in the table."""
        n = len(body)
        node = _NODES.get(body[:2])
        if node is None or n not in _REPLY_BODY_LENGTHS:
            return self._decode_general(body)
        if xor_bytes(body) != _WHOLE_BODY_XOR.get(body[-2:]):
            return self._decode_general(body)  # (also when the BCC is not hex)
        if n == _STATUS_BODY_LEN:
            data = body[2:-2]
            if data.isdigit():  # (an ACK or NAK marker is not a digit)
                reply = _new(DataReply)
                _set_data_node(reply, node)
                _set_data_data(reply, data)
                return reply
        elif body[2] == ACK:  # n is 5, 7 or 13 here
            if n == _ACK_BODY_LEN:
                ack = _new(AckReply)
                _set_ack_node(ack, node)
                return ack
            data = body[3:-2]
            if data.isdigit():  # command 09's 2 digits, or command 06's 8 (not negative)
                ack_data = _new(AckDataReply)
                _set_ack_data_node(ack_data, node)
                _set_ack_data_data(ack_data, data)
                return ack_data
        elif body[2] == NAK and n == _SHORT_BODY_LEN:
            code = _NAK_CODES.get(body[3:5])
            if code is not None:
                nak = _new(NakReply)
                _set_nak_node(nak, node)
                _set_nak_code(nak, code)
                return nak
        return self._decode_general(body)

    def _decode_general(self, body: bytes) -> Reply | BadFrame:
        """The general path (any body): see :func:`_decode_reply_body`."""
        event = _decode_reply_body(body)
        if type(event) is BadFrame:
            self._bad(event)
        return event


def _decode_reply_body(body: bytes) -> Reply | BadFrame:
    """Decode a body checking one thing after the other; the first defect is the reason."""
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
