"""The request parser: the drive's side of the line (used by the simulator, and by tests).

It splits the host's byte stream into requests the same way
:class:`~sj300_async.ReplyParser` splits replies, and reports each frame's
defect in the terms a drive answers with: a :class:`BadFrame` whose reason
maps to a NAK code (see :data:`NAK_FOR_BAD_REQUEST`). It checks only the
frame's shape; whether a parameter code exists or a value is in range is
the drive's own judgement.
"""

from __future__ import annotations

import re
from functools import lru_cache
from typing import Final

from ..wire import BadFrame, BadFrameReason
from ._bcc import xor_bytes
from ._codes import NakCode
from ._commands import Command, RequestData
from ._constants import BROADCAST, CR_BYTE, MAX_REQUEST_BODY, STX_BYTE
from ._framing import FrameSplitter
from ._parser import parse_bcc, parse_node
from ._requests import Request

__all__ = ["NAK_FOR_BAD_REQUEST", "RequestParser"]

_COMMANDS: Final = {c.wire: c for c in Command}

#: (length, pattern) of each request data shape.
_DATA_SHAPES: Final[dict[RequestData, tuple[int, re.Pattern[bytes]]]] = {
    RequestData.NONE: (0, re.compile(rb"")),
    RequestData.RUN_MODE: (1, re.compile(rb"[0-9]")),
    RequestData.FREQUENCY: (6, re.compile(rb"[0-9]{6}")),
    RequestData.TERMINALS: (16, re.compile(rb"[0-9A-Fa-f]{16}")),
    RequestData.PARAMETER_CODE: (4, re.compile(rb"[A-Za-z][0-9]{3}")),
    RequestData.PARAMETER_VALUE: (12, re.compile(rb"[A-Za-z][0-9]{3}[0-9]{8}")),
}

#: The NAK code a drive answers for each kind of bad request (None: it stays silent).
NAK_FOR_BAD_REQUEST: Final[dict[BadFrameReason, NakCode | None]] = {
    BadFrameReason.BAD_BCC: NakCode.CHECKSUM,
    BadFrameReason.BAD_COMMAND: NakCode.ABNORMAL_COMMAND,
    BadFrameReason.BAD_LENGTH: NakCode.PROTOCOL,
    BadFrameReason.BAD_CHARACTERS: NakCode.ASCII,
    BadFrameReason.TOO_SHORT: NakCode.PROTOCOL,
    # A frame whose node cannot be read is addressed to nobody: nobody answers.
    BadFrameReason.BAD_NODE: None,
}

_MIN_REQUEST_BODY: Final = 6  # node(2) + command(2) + BCC(2)

# A line carries the same few requests over and over (a poll asks every drive the
# same questions), and decoding is a pure function of the body whose results are
# frozen: each of the bodies seen most recently is decoded once. Bounded, so a line full of
# distinct frames costs memory for this many at most.
_DECODED_BODIES: Final = 1024


@lru_cache(maxsize=_DECODED_BODIES)
def _decode(body: bytes) -> Request | BadFrame:
    """The request (or the defect) in the body of one frame, STX and CR stripped."""
    node: int | None
    node = BROADCAST if body[:2] == b"FF" else parse_node(body[:2])
    if node is None:
        return BadFrame(BadFrameReason.BAD_NODE, body)
    if len(body) < _MIN_REQUEST_BODY:
        return BadFrame(BadFrameReason.TOO_SHORT, body, node)
    check = parse_bcc(body[-2:])
    if check is None or check != xor_bytes(body[:-2]):
        return BadFrame(BadFrameReason.BAD_BCC, body, node)
    command = _COMMANDS.get(body[2:4])
    if command is None:
        return BadFrame(BadFrameReason.BAD_COMMAND, body, node)
    data = body[4:-2]
    length, pattern = _DATA_SHAPES[command.spec.request]
    if len(data) != length:
        return BadFrame(BadFrameReason.BAD_LENGTH, body, node)
    if not pattern.fullmatch(data):
        return BadFrame(BadFrameReason.BAD_CHARACTERS, body, node)
    return Request(node, command, data, STX_BYTE + body + CR_BYTE)


class RequestParser(FrameSplitter[Request]):
    """Parses requests out of the host's byte stream.

    ``feed(chunk)`` returns :class:`~sj300_async.Request` objects for valid
    frames and :class:`BadFrame` / :class:`Discarded` events for the rest.
    """

    def __init__(self) -> None:
        super().__init__(MAX_REQUEST_BODY)

    def _decode_body(self, body: bytes) -> Request | BadFrame:
        event = _decode(body)
        if type(event) is BadFrame:
            self._bad(event)
        return event
