"""The FR-700 line framer: the whole line, both directions, for captures and the sniffer.

A line carries the host's requests (ENQ, formats A, A1, A2, B), the drives'
replies (STX data ETX sum: E, E1, E2, E3, C1; ACK station: C; NAK station
code: D) and the host's own answers to read data (ACK station: C; NAK
station: F, the re-output request), each followed by the line's terminator.
:class:`Fr700LineFramer` splits such a stream, both directions interleaved
in any chunking, into pieces that keep every byte, and tells what each piece
is as a :class:`~sj300_async.wire._frames.LineFrame`. Sans-IO: bytes in,
pieces out.

It is built from the configured dialect (``Fr700Dialect.line_framer()``),
because the line options decide where frames end: the terminator, and
without one the waiting-time field (a request's length).

Where a frame ends (the reply parser's and the drives' rules, in one place):

- With a terminator (CR, or CR LF) a frame runs from its start byte (ENQ,
  STX, ACK, NAK) to the CR; with CR LF an LF right after the CR belongs to
  the frame, and a missing LF is tolerated (the CR ended it).
- Without one, by its length: a request by its instruction (a read has no
  data, HF0 ten digits, the A1 writes two, other writes four, plus the
  waiting-time character when the line has the field; a code that is not
  hex ends it after the code); an ACK is 3 characters; a data reply ends two
  characters (the sum) after its ETX; a NAK is 4 characters when a fourth,
  printable one follows (the drive's code, format D) and 3 otherwise (the
  host's re-output request, format F, which the re-sent STX reply follows).
- A start byte before the end cuts the frame short; a frame that has not
  ended after :data:`~sj300_async.fr700.MAX_FRAME` characters (the longest
  reply, a model name) is overlong and cut after one more. Both become
  noise pieces, as do the bytes between frames.

Decisions where nothing says:

- Chunking never changes the pieces. A piece is returned once the bytes
  that follow cannot change it, so three cases wait for the next byte (or
  :meth:`~Fr700LineFramer.flush`): a frame that ended at its CR on a CR LF
  line (is an LF next?), a 3-character NAK without a terminator (does a
  code follow?), and a run of noise (it ends at the next start byte, or
  after as many bytes as the longest frame, so garbage never grows a
  buffer beyond the longest frame: :attr:`~Fr700LineFramer.buffered`).
- What a frame is follows its content wherever the content tells, whatever
  the direction: ENQ is a request (inbound too: local echo), STX a reply,
  a 3-character NAK the host's re-output request, a 4-character NAK the
  drive's. Only ``ACK station`` reads both ways, the drive's write
  acknowledgement (C) or the host's "data received" (C): the direction
  decides when known (the host wrote it: its answer; it reached the host: a
  reply), and on a tap (``outbound=None``) the pending request does: a
  write to that station makes it the drive's reply, anything else (a read,
  a multi-command, nothing) the host's answer to read data.
- A request's :attr:`~sj300_async.wire._frames.LineFrame.message` is the
  :class:`~sj300_async.fr700.Fr700Request` the library's builders make for
  it (kind, reply width, the frame as seen), so the dialect's ``answers``,
  ``reply_frame_length`` and ``processing_s`` work on it; a sniffed HFF is
  taken as changing the drive (a read-only bus's exception for the bank
  selected before a parameter read cannot be seen on the line). A reply's
  is the reply parser's event (:class:`~sj300_async.fr700.Fr700Data` for
  C1 too, as the parser yields it).
- Problems are named in the protocol's words: ``"bad sum check"`` (then
  ``check_ok`` is False), ``"bad length"``, ``"bad characters"``,
  ``"bad station"``, ``"too short"``; noise is ``"garbage"``,
  ``"cut short"`` (a frame interrupted or never ended) or ``"overlong"``.
"""

from __future__ import annotations

import enum
import re
from typing import Final

from ..wire import BadFrame, BadFrameReason, FrameRole, LineFrame
from ._codec import DEFAULT_LINE_OPTIONS, Fr700LineOptions, parse_station
from ._codes import ACK, CR, ENQ, ETX, LF, NAK, STX, Fr700Instruction, Fr700NakCode
from ._events import Fr700Ack, Fr700Data, Fr700Nak, Fr700Reply
from ._parser import MAX_FRAME, decode_frame
from ._request_parser import BadRequest, HostAnswer, decode_host_frame, request_frame_length
from ._requests import READ_WIDTHS, Fr700Request, Fr700RequestKind

__all__ = [
    "Fr700LineFramer",
    "describe_host_answer",
    "describe_reply",
    "describe_request",
    "instruction_name",
    "request_from_frame",
]

I = Fr700Instruction  # noqa: E741
_START: Final = re.compile(b"[\x02\x05\x06\x15]")
_START_OR_CR: Final = re.compile(b"[\x02\x05\x06\x15\r]")
_START_OR_ETX: Final = re.compile(b"[\x02\x03\x05\x06\x15]")
#: The longest data reply before its ETX: STX, station, 20 characters of data.
_MAX_BEFORE_ETX: Final = MAX_FRAME - 3
#: Data characters of a multi-command's reply (C1).
_MULTI_REPLY_WIDTH: Final = 12
_REQUEST_PROBLEMS: Final = {
    Fr700NakCode.SUM_CHECK: "bad sum check",
    Fr700NakCode.PROTOCOL: "bad length",
    Fr700NakCode.CHARACTER: "bad characters",
}
_FRAME_NAMES: Final = {ENQ: "request", STX: "reply", ACK: "ACK", NAK: "NAK"}


class _End(enum.Enum):
    """How the first piece of a buffer ends."""

    FRAME = "frame"  #: a whole frame (its terminator included)
    GARBAGE = "garbage"  #: bytes outside any frame
    CUT_SHORT = "cut short"  #: a frame interrupted by a start byte, or never ended
    OVERLONG = "overlong"  #: a frame longer than the longest one


_NOISE_SUMMARIES: Final = {
    _End.GARBAGE: "bytes outside a frame",
    _End.CUT_SHORT: "a frame cut short",
    _End.OVERLONG: "an overlong frame",
}


def instruction_name(code: int) -> str:
    """An instruction's name in words (``"output frequency"``); ranges by their first code's."""
    try:
        name = Fr700Instruction(code).name
    except ValueError:
        if code <= 0x63:
            name = I.READ_PARAMETER.name
        elif 0x74 <= code <= 0x77:
            name = I.FAULT_HISTORY.name
        elif 0x80 <= code <= 0xE3:
            name = I.WRITE_PARAMETER.name
        else:
            return "instruction"
    words = name.lower().replace("_", " ")
    return words.replace(" ram", " RAM").replace(" eeprom", " EEPROM")


def describe_request(request: Fr700Request) -> str:
    """``"station 01: read output frequency (6F)"``, ``"station 01: run command (FA) 02"``."""
    name = instruction_name(request.instruction)
    if request.kind is Fr700RequestKind.READ and not name.startswith("read "):
        name = "read " + name
    elif request.kind is not Fr700RequestKind.READ and name == "instruction":
        name = "write instruction"
    text = f"station {request.station:02d}: {name} ({request.instruction:02X})"
    if request.data:
        text += " " + request.data.decode("ascii", "replace")
    return text


def describe_reply(reply: Fr700Reply) -> str:
    """A reply in a few words: ``"station 01: NAK 2 (sum check error)"``, ``"station 01: ACK"``.

    Data as sent: ``"station 01: data 1770"``.
    """
    if isinstance(reply, Fr700Nak):
        code = reply.code
        return f"station {reply.station:02d}: NAK {code.wire.decode()} ({code.description})"
    if isinstance(reply, Fr700Ack):
        return f"station {reply.station:02d}: ACK"
    return f"station {reply.station:02d}: data {reply.data.decode('ascii', 'replace')}"


def describe_host_answer(station: int, *, reoutput: bool) -> str:
    """The host's answer to read data in a few words.

    ``"station 01: host ACK (data received)"``, ``"station 01: host NAK (send the data again)"``.
    """
    what = "NAK (send the data again)" if reoutput else "ACK (data received)"
    return f"station {station:02d}: host {what}"


def request_from_frame(station: int, instruction: int, data: bytes, frame: bytes) -> Fr700Request:
    """The :class:`Fr700Request` the library's builders make for a request read off the line.

    Its kind and reply width follow the instruction, as :func:`~sj300_async.fr700.requests.read`,
    :func:`~sj300_async.fr700.requests.write` and
    :func:`~sj300_async.fr700.requests.multi_command` set them; *frame* is kept as seen.
    """
    if instruction < 0x80:
        return Fr700Request(
            station, instruction, Fr700RequestKind.READ, data, frame, READ_WIDTHS.get(instruction)
        )
    if instruction == I.MULTI_COMMAND:
        return Fr700Request(
            station, instruction, Fr700RequestKind.MULTI, data, frame, _MULTI_REPLY_WIDTH
        )
    kind = Fr700RequestKind.RESET if instruction == I.INVERTER_RESET else Fr700RequestKind.WRITE
    return Fr700Request(station, instruction, kind, data, frame)


class Fr700LineFramer:
    """Splits an FR-700 line into frames and noise, and tells what each is (see the module).

    Args:
        options: the line's options (the configured dialect's ``options``):
            the terminator, and the waiting-time field.
    """

    def __init__(self, options: Fr700LineOptions = DEFAULT_LINE_OPTIONS) -> None:
        self.options = options
        self._terminator = options.terminator
        self._wait_field = options.wait_field
        #: The longest piece: the longest frame with its terminator (noise runs are cut to it).
        self.max_piece = MAX_FRAME + len(options.terminator)
        self._pending = b""

    @property
    def buffered(self) -> int:
        """Bytes held for a piece not yet decided (never more than :attr:`max_piece`)."""
        return len(self._pending)

    def feed(self, data: bytes) -> list[bytes]:
        """Consume a chunk; return the pieces it completed, in order."""
        buffer = self._pending + bytes(data) if self._pending else bytes(data)
        pieces: list[bytes] = []
        pos, size = 0, len(buffer)
        while pos < size:
            cut = self._cut(buffer, pos, final=False)
            if cut is None:
                break
            end, _ = cut
            pieces.append(buffer[pos:end])
            pos = end
        self._pending = buffer[pos:]
        return pieces

    def flush(self) -> list[bytes]:
        """Return what is pending (a frame still open, or noise) as a piece, and forget it."""
        pending, self._pending = self._pending, b""
        return [pending] if pending else []

    def classify(
        self, piece: bytes, *, outbound: bool | None, pending: object | None = None
    ) -> LineFrame:
        """What *piece* is (see the module docstring for the direction and *pending*)."""
        cut = self._cut(piece, 0, final=True) if piece else (0, _End.GARBAGE)
        assert cut is not None  # final: always decided
        stop, end = cut
        if end is not _End.FRAME:
            return LineFrame(piece, FrameRole.NOISE, None, _NOISE_SUMMARIES[end], problem=end.value)
        body = self._strip(piece)
        kind = body[0]
        if stop != len(piece):  # more than one frame (not a piece of this framer)
            station = parse_station(body[1:3])
            return _broken_named(piece, "bad length", station, _FRAME_NAMES[kind])
        if kind == ENQ:
            return self._request(piece, body)
        if kind == STX:
            return _reply(piece, decode_frame(body))
        if kind == NAK and len(body) == 3:
            return self._host_answer(piece, body)
        if kind == NAK:
            return _reply(piece, decode_frame(body))
        # ACK station: the drive's write acknowledgement or the host's "data received".
        decoded = decode_frame(body)
        if isinstance(decoded, BadFrame):
            return _broken(piece, decoded.reason, decoded.node, "ACK")
        if outbound is None:
            outbound = not (
                isinstance(pending, Fr700Request)
                and pending.kind is Fr700RequestKind.WRITE
                and pending.station == decoded.station
            )
        if outbound:
            return self._host_answer(piece, body)
        return _reply(piece, decoded)

    # -- splitting -------------------------------------------------------------------------

    def _cut(self, buffer: bytes, pos: int, *, final: bool) -> tuple[int, _End] | None:
        """Where the piece starting at *pos* ends, and how; None: the next bytes may change it.

        With *final* (no more bytes will come) it is always decided.
        """
        size = len(buffer)
        if not _START.match(buffer, pos):
            limit = min(size, pos + self.max_piece)
            match = _START.search(buffer, pos, limit)
            if match is not None:
                return match.start(), _End.GARBAGE
            if limit - pos == self.max_piece or final:
                return limit, _End.GARBAGE
            return None
        if self._terminator:
            return self._cut_at_cr(buffer, pos, final=final)
        return self._cut_by_length(buffer, pos, final=final)

    def _cut_at_cr(self, buffer: bytes, pos: int, *, final: bool) -> tuple[int, _End] | None:
        size = len(buffer)
        limit = pos + MAX_FRAME  # the last index where the CR may be
        match = _START_OR_CR.search(buffer, pos + 1, min(size, limit + 1))
        if match is None:
            if size > limit:
                return limit + 1, _End.OVERLONG
            return (size, _End.CUT_SHORT) if final else None
        at = match.start()
        if buffer[at] != CR:
            return at, _End.CUT_SHORT
        if self._terminator == b"\r":
            return at + 1, _End.FRAME
        if at + 1 < size:
            return (at + 2 if buffer[at + 1] == LF else at + 1), _End.FRAME
        return (at + 1, _End.FRAME) if final else None

    def _cut_by_length(self, buffer: bytes, pos: int, *, final: bool) -> tuple[int, _End] | None:
        size = len(buffer)
        kind = buffer[pos]
        need: int | None
        if kind == STX:
            # Up to the ETX (a start byte first cuts it short), then the sum.
            match = _START_OR_ETX.search(buffer, pos + 1, min(size, pos + _MAX_BEFORE_ETX + 1))
            if match is None:
                if size > pos + _MAX_BEFORE_ETX:
                    return pos + _MAX_BEFORE_ETX + 1, _End.OVERLONG
                return (size, _End.CUT_SHORT) if final else None
            if buffer[match.start()] != ETX:
                return match.start(), _End.CUT_SHORT
            need = match.start() + 3 - pos
        elif kind == NAK:
            need = 3
            if size >= pos + 4 and 0x20 <= buffer[pos + 3] <= 0x7E:
                need = 4
            elif size < pos + 4 and not final:
                need = None  # a code may follow
        else:  # ENQ or ACK
            need = request_frame_length(buffer[pos : pos + 5], wait_field=self._wait_field)
        # A start byte before the frame's end cuts it short.
        stop = min(size, pos + need) if need is not None else size
        match = _START.search(buffer, pos + 1, stop)
        if match is not None:
            return match.start(), _End.CUT_SHORT
        if need is not None and size >= pos + need:
            return pos + need, _End.FRAME
        if final:
            if kind == NAK and size == pos + 3:
                return size, _End.FRAME
            return size, _End.CUT_SHORT
        return None

    def _strip(self, frame: bytes) -> bytes:
        """*frame* without its terminator (a whole frame, as cut)."""
        if not self._terminator:
            return frame
        if frame.endswith(b"\r\n") and self._terminator == b"\r\n":
            return frame[:-2]
        return frame[:-1]

    # -- classifying ---------------------------------------------------------------------

    def _request(self, piece: bytes, body: bytes) -> LineFrame:
        decoded = decode_host_frame(body, wait_field=self._wait_field)
        if isinstance(decoded, BadRequest):
            problem = _REQUEST_PROBLEMS.get(decoded.code, "bad length")
            station = parse_station(body[1:3])
            if len(body) < 3:
                problem = "too short"
            elif station is None:
                problem = "bad station"
            return _broken_named(piece, problem, station, "request")
        assert not isinstance(decoded, HostAnswer)  # an ENQ frame
        request = request_from_frame(decoded.station, decoded.instruction, decoded.data, piece)
        return LineFrame(
            piece,
            FrameRole.REQUEST,
            request.station,
            describe_request(request),
            message=request,
            check_ok=True,
            expects_reply=request.expects_reply,
        )

    def _host_answer(self, piece: bytes, body: bytes) -> LineFrame:
        decoded = decode_host_frame(body, wait_field=self._wait_field)
        if not isinstance(decoded, HostAnswer):
            station = parse_station(body[1:3])
            problem = "bad length" if station is not None else "bad station"
            return _broken_named(piece, problem, station, _FRAME_NAMES[body[0]])
        return LineFrame(
            piece,
            FrameRole.HOST_ANSWER,
            decoded.station,
            describe_host_answer(decoded.station, reoutput=decoded.reoutput),
        )


def _reply(piece: bytes, decoded: Fr700Reply | BadFrame) -> LineFrame:
    if isinstance(decoded, BadFrame):
        return _broken(piece, decoded.reason, decoded.node, _FRAME_NAMES[piece[0]])
    return LineFrame(
        piece,
        FrameRole.REPLY,
        decoded.station,
        describe_reply(decoded),
        message=decoded,
        check_ok=True if isinstance(decoded, Fr700Data) else None,
    )


def _broken(piece: bytes, reason: BadFrameReason, node: int | None, what: str) -> LineFrame:
    problem = {
        BadFrameReason.BAD_BCC: "bad sum check",
        BadFrameReason.BAD_NODE: "bad station",
    }.get(reason, reason.value)
    return _broken_named(piece, problem, node, what)


def _broken_named(piece: bytes, problem: str, node: int | None, what: str) -> LineFrame:
    return LineFrame(
        piece,
        FrameRole.BROKEN,
        node,
        f"broken {what}: {problem}",
        problem=problem,
        check_ok=False if problem == "bad sum check" else None,
    )
