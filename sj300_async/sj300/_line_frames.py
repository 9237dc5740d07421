"""The SJ300 line framer: the whole line, both directions, for captures and the sniffer.

Every SJ300 frame, request or reply, runs from STX to CR, so the splitter
of the reply and request parsers splits the line too; only here nothing is
decoded on the way and nothing is thrown away: a piece is a whole frame or
the bytes the splitter would have discarded (garbage, a frame cut short by a
new STX, an overlong one), byte for byte. A run of garbage is one piece
whatever the chunking: it ends at the next STX (or at :meth:`SJ300LineFramer.flush`),
and a run longer than the longest frame is cut every that many bytes.

Telling a request from a reply. With the direction known (a capture) the
frame is decoded as what it must be. On a tap the content decides: a third
byte ACK or NAK makes a reply; otherwise the frame is decoded both ways, and
almost always only one of them is valid (the lengths differ). One shape is
both: a status reply (node, 8 digits, BCC) is as long as a set-frequency
request (node, ``01``, 6 digits, BCC), and 8 digits starting ``01`` are valid
status data. Such a frame is the answer when the request pending on the
line is a status read of that node, and a request otherwise.
"""

from __future__ import annotations

from typing import Final

from ..wire import BadFrame, Discarded, DiscardReason, FrameRole, LineFrame
from ._commands import Command
from ._constants import BROADCAST, CR_BYTE, MAX_REPLY_BODY, MAX_REQUEST_BODY, STX_BYTE
from ._events import AckDataReply, AckReply, DataReply, NakReply, Reply
from ._framing import FrameSplitter
from ._matching import answers
from ._parser import _decode_reply_body
from ._request_parser import _decode
from ._requests import Request

__all__ = ["SJ300LineFramer", "describe_reply", "describe_request"]

_ACK: Final = 0x06
_NAK: Final = 0x15
_COMMAND_NAMES: Final = {c: c.name.lower().replace("_", " ") for c in Command}
#: The longest run of garbage kept as one piece: the longest frame, STX and CR included.
_MAX_NOISE: Final = max(MAX_REPLY_BODY, MAX_REQUEST_BODY) + 2


class _Pieces(FrameSplitter[bytes]):
    """The STX..CR splitter, keeping each frame whole (STX and CR included)."""

    def __init__(self) -> None:
        super().__init__(max(MAX_REPLY_BODY, MAX_REQUEST_BODY))

    def _decode_body(self, body: bytes) -> bytes:
        return STX_BYTE + body + CR_BYTE

    @property
    def in_frame(self) -> bool:
        """An STX has come and its frame has not ended."""
        return self._partial is not None


def describe_request(request: Request) -> str:
    """``"node 01: command 04 (read status)"``; the data follows when there is some."""
    who = "every node" if request.node == BROADCAST else f"node {request.node:02d}"
    text = f"{who}: {request.label} ({_COMMAND_NAMES[request.command]})"
    if request.data:
        text += " " + request.data.decode("ascii", "replace")
    return text


def describe_reply(reply: Reply) -> str:
    """``"node 01: NAK 02 (check sum (BCC) error)"``, ``"node 01: data 00030000"``."""
    if type(reply) is NakReply:
        return f"node {reply.node:02d}: NAK {int(reply.code):02d} ({reply.code.description})"
    if type(reply) is AckReply:
        return f"node {reply.node:02d}: ACK"
    assert type(reply) is AckDataReply or type(reply) is DataReply
    kind = "ACK + data" if type(reply) is AckDataReply else "data"
    return f"node {reply.node:02d}: {kind} {reply.data.decode('ascii', 'replace')}"


class SJ300LineFramer:
    """Splits an SJ300 line into frames and noise, and tells what each is (see the module)."""

    def __init__(self) -> None:
        self._splitter = _Pieces()
        #: A run of garbage not yet ended (the splitter reports it chunk by chunk).
        self._noise = b""

    def feed(self, data: bytes) -> list[bytes]:
        return self._pieces(self._splitter.feed(data), final=False)

    def flush(self) -> list[bytes]:
        return self._pieces(self._splitter.reset(), final=True)

    def _pieces(self, events: list[bytes | BadFrame | Discarded], *, final: bool) -> list[bytes]:
        pieces: list[bytes] = []
        for event in events:
            if type(event) is Discarded and event.reason is DiscardReason.GARBAGE:
                noise = self._noise + event.data
                cut = len(noise) - len(noise) % _MAX_NOISE
                pieces += [noise[at : at + _MAX_NOISE] for at in range(0, cut, _MAX_NOISE)]
                self._noise = noise[cut:]
                continue
            if self._noise:  # an STX ended the run
                pieces.append(self._noise)
                self._noise = b""
            pieces.append(_piece(event))
        if self._noise and (final or self._splitter.in_frame):
            pieces.append(self._noise)
            self._noise = b""
        return pieces

    def classify(
        self, piece: bytes, *, outbound: bool | None, pending: object | None = None
    ) -> LineFrame:
        if len(piece) < 2 or piece[0] != STX_BYTE[0] or piece[-1] != CR_BYTE[0]:
            # What the splitter discards: a frame cut short (by a new STX, or the
            # end of the capture), one too long, or bytes before any STX.
            why = "frame cut short" if piece[:1] == STX_BYTE else "bytes outside a frame"
            return LineFrame(piece, FrameRole.NOISE, None, f"noise: {why}", problem=why)
        body = piece[1:-1]
        if outbound is True:
            return _as_request(piece, _decode(body))
        if outbound is False or (len(body) > 2 and body[2] in (_ACK, _NAK)):
            return _as_reply(piece, _decode_reply_body(body))
        request = _decode(body)
        reply = _decode_reply_body(body)
        if type(request) is BadFrame:
            if type(reply) is BadFrame and pending is None and len(body) <= MAX_REQUEST_BODY:
                # Broken both ways, request-sized, and no answer is due: a request.
                return _as_request(piece, request)
            return _as_reply(piece, reply)
        if (
            not isinstance(reply, BadFrame)
            and isinstance(pending, Request)
            and answers(pending, reply)
        ):
            return _as_reply(piece, reply)
        return _as_request(piece, request)


def _piece(event: bytes | BadFrame | Discarded) -> bytes:
    if type(event) is Discarded:
        return event.data
    assert type(event) is bytes  # _Pieces decodes every body into bytes
    return event


def _broken(piece: bytes, bad: BadFrame, what: str) -> LineFrame:
    reason = bad.reason.value
    return LineFrame(
        piece,
        FrameRole.BROKEN,
        bad.node,
        f"broken {what}: {reason}",
        problem=reason,
        check_ok=False if reason == "bad BCC" else None,
    )


def _as_request(piece: bytes, decoded: Request | BadFrame) -> LineFrame:
    if type(decoded) is BadFrame:
        return _broken(piece, decoded, "request")
    assert type(decoded) is Request
    return LineFrame(
        piece,
        FrameRole.REQUEST,
        decoded.node,
        describe_request(decoded),
        message=decoded,
        check_ok=True,
        expects_reply=decoded.expects_reply,
    )


def _as_reply(piece: bytes, decoded: Reply | BadFrame) -> LineFrame:
    if type(decoded) is BadFrame:
        return _broken(piece, decoded, "reply")
    assert not isinstance(decoded, BadFrame)
    return LineFrame(
        piece,
        FrameRole.REPLY,
        decoded.node,
        describe_reply(decoded),
        message=decoded,
        check_ok=True,
    )
