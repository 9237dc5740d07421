"""The FR-700 computer link as a dialect of the protocol-neutral async stack.

What the arbiter learns from it:

- Matching: a reply answers a request when it comes from the addressed
  station and has the request's shape: a read wants data of the expected
  width (any width for an unknown instruction), a write wants ACK, a
  multi-command wants a C1 echoing its send and receive types. A NAK from
  the station answers any request.
- Refusal: a NAK becomes :class:`~sj300_async.NakError` with the station as
  ``node`` and an :class:`Fr700NakCode` as ``code``.
- Retries: NAK 1, 2, 3, 4, 5 and 7 are transmission errors, worth another
  attempt; 0 (the drive has tripped on too many errors), A, B and C are not.
- Timing: the drive's processing time is the waiting time (the request's
  field, else the drive's own Pr.123 which the caller passes as its wait
  time) plus the data check time: about 12 ms for monitors, the run command
  and RAM frequency, up to 30 ms for parameters and EEPROM (the reference);
  seconds for the clears (decision: 5 s for HFC parameter clear, 30 ms for
  HF4 fault-history clear, an EEPROM write).
- The shortest reply: ACK (3 characters + terminator) for a write, NAK
  (4 + terminator) for a read or a multi-command.
- Resync after a missed answer: a read whose data width no pending request's
  reply has (writes are answered by ACK, reads by data of their width, a
  multi-command by 12 characters): H7A status (2 digits), else H6F output
  frequency (4 digits); none when both widths are pending, or a pending read
  of an unknown instruction may answer with any width (the arbiter then
  waits instead).
- The host's answer to read data (optional in the protocol): with
  ``send_ack`` the host sends ACK (format C) after good data, waiting the
  reference's 10 ms "computer processing delay" before it, and the line
  rests 10 ms after it. With ``request_reoutput`` (default on) a damaged
  data reply is answered with NAK (format F) once per attempt, which makes
  the drive send its reply again; if that one is damaged too, the attempt
  ends as a :class:`~sj300_async.RemoteProtocolError`.
- The inverter reset (HFD H9696) expects no reply: the arbiter sends it as
  it sends a broadcast (and counts it among the ``broadcasts``), resting the
  line for the request's wire time plus the broadcast processing time. The
  drive itself needs about a second to restart; the caller waits for that.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Final

from ..wire import BadFrame, LocalProtocolError, NakError, SJ300Error
from ._codec import (
    MAX_REPLY_DATA,
    Fr700LineOptions,
    encode_host_ack,
    encode_reoutput_request,
    terminator_bytes,
)
from ._codes import Fr700Instruction, Fr700NakCode
from ._events import Fr700Ack, Fr700Data, Fr700Nak, Fr700Reply
from ._line_frames import Fr700LineFramer
from ._parameters import fr700_parameter_info
from ._parser import Fr700ReplyParser
from ._requests import READ_WIDTHS, Fr700Request, Fr700RequestKind, read

if TYPE_CHECKING:
    from ..bus import Channel
    from ._drive import Fr700Drive

__all__ = ["ANSWER_DELAY_S", "CHECK_TIME_S", "EEPROM_CHECK_TIME_S", "FR700_DIALECT", "Fr700Dialect"]

#: Data check time of monitors, the run command and the RAM frequency.
CHECK_TIME_S: Final = 0.012
#: Data check time of parameters and EEPROM writes.
EEPROM_CHECK_TIME_S: Final = 0.030
#: The host waits this long after a reply before answering it, and after its ACK.
ANSWER_DELAY_S: Final = 0.010

I = Fr700Instruction  # noqa: E741
_SLOW: Final = frozenset(
    {
        *range(0x64),  # parameter read
        *range(0x80, 0xE4),  # parameter write
        I.READ_SET_FREQUENCY_EEPROM,
        I.WRITE_SET_FREQUENCY_EEPROM,
        I.WRITE_LINK_EXTENSION,
        I.CLEAR_FAULT_HISTORY,
    }
)
_CLEAR_S: Final = 5.0
#: Reads a resync tries, in order: each answers with data of its own width.
_SYNC_READS: Final = (I.STATUS, I.OUTPUT_FREQUENCY)
#: Data characters of a multi-command's reply (C1).
_MULTI_REPLY_WIDTH: Final = 12
#: The URL's ``terminator=`` values.
_TERMINATORS: Final = {"none": "", "": "", "cr": "\r", "crlf": "\r\n"}


def _nak_error(station: int, code: Fr700NakCode) -> NakError:
    return NakError(
        station,
        code,
        f"station {station:02d} answered NAK {code.wire.decode()} ({code.description})",
    )


class Fr700Dialect:
    """The Mitsubishi FR-700 computer link (see the module docstring).

    Args:
        wait_field: requests carry the waiting-time character (the drive's
            Pr.123 = 9999, the factory setting).
        terminator: ``""``, ``"\\r"`` (factory setting) or ``"\\r\\n"`` (str or bytes).
        send_ack: answer good read data with ACK (format C).
        wait_time_digit: the waiting time requested, 0..15 x 10 ms.
        request_reoutput: answer damaged read data with NAK (format F) once.

    Raises:
        LocalProtocolError: a line option the protocol does not allow.
    """

    name = "fr700"
    node_range = (0, 31)
    node_noun = "station"
    default_sim_nodes = "0-7"
    url_options = frozenset(("wait_field", "terminator", "ack"))
    simulator = "sj300_async.simulator.fr700:simulate"
    profile = "sj300_async.fr700._profile:FR700_PROFILE"
    capture_linktype = 148  # LINKTYPE_USER1 (docs/CAPTURE.md)

    def __init__(
        self,
        *,
        wait_field: bool = True,
        terminator: str | bytes = "\r",
        send_ack: bool = False,
        wait_time_digit: int = 0,
        request_reoutput: bool = True,
    ) -> None:
        self.options = Fr700LineOptions(
            wait_field=wait_field,
            wait_time_digit=wait_time_digit,
            terminator=terminator_bytes(terminator),
        )
        self.send_ack = bool(send_ack)
        self.request_reoutput = bool(request_reoutput)

    def __repr__(self) -> str:
        o = self.options
        return (
            f"Fr700Dialect(wait_field={o.wait_field}, terminator={o.terminator!r}, "
            f"send_ack={self.send_ack}, wait_time_digit={o.wait_time_digit}, "
            f"request_reoutput={self.request_reoutput})"
        )

    def configure(self, options: Mapping[str, str]) -> Fr700Dialect:
        """A dialect with the URL's ``wait_field``, ``terminator`` and ``ack`` applied.

        Raises:
            LocalProtocolError: an unknown option or a bad value.
        """
        from ..bus import parse_flag

        unknown = set(options) - self.url_options
        if unknown:
            raise LocalProtocolError(f"unknown FR-700 option(s): {', '.join(sorted(unknown))}")
        terminator = options.get("terminator", "cr").lower()
        if terminator not in _TERMINATORS:
            raise LocalProtocolError(f"terminator must be none, cr or crlf, got {terminator!r}")
        return Fr700Dialect(
            wait_field=parse_flag("wait_field", options.get("wait_field", "1")),
            terminator=_TERMINATORS[terminator],
            send_ack=parse_flag("ack", options.get("ack", "0")),
            wait_time_digit=self.options.wait_time_digit,
            request_reoutput=self.request_reoutput,
        )

    def new_parser(self) -> Fr700ReplyParser:
        return Fr700ReplyParser(self.options.terminator)

    def answers(self, request: Fr700Request, event: Fr700Reply) -> bool:
        if event.station != request.station:
            return False
        if isinstance(event, Fr700Nak):
            return True
        kind = request.kind
        if kind is Fr700RequestKind.WRITE:
            return isinstance(event, Fr700Ack)
        if not isinstance(event, Fr700Data):
            return False
        if kind is Fr700RequestKind.MULTI:
            # A C1 echoes the send and receive types: a late reply to another
            # multi-command of other types is not this one's answer.
            return len(event.data) == 12 and event.data[:2] == request.data[:2]
        return request.reply_width is None or len(event.data) == request.reply_width

    def accept(self, request: Fr700Request, reply: Fr700Reply) -> bytes:
        if isinstance(reply, Fr700Data):
            return reply.data
        if isinstance(reply, Fr700Ack):
            return b""
        raise _nak_error(reply.station, reply.code)

    def retryable(self, exc: SJ300Error) -> bool:
        if isinstance(exc, NakError):
            return Fr700NakCode(exc.code).is_transmission_error
        return True

    def writes(self, request: Fr700Request) -> bool:
        return request.mutating

    def reply_frame_length(self, request: Fr700Request) -> int:
        term = len(self.options.terminator)
        nak = 4 + term
        if request.kind is Fr700RequestKind.WRITE:
            return max(3 + term, nak)
        width = request.reply_width if request.reply_width is not None else MAX_REPLY_DATA
        return 1 + 2 + width + 1 + 2 + term

    def shortest_reply_length(self, request: Fr700Request) -> int:
        term = len(self.options.terminator)
        if request.kind is Fr700RequestKind.WRITE:
            return 3 + term  # ACK (a NAK is one character longer)
        return 4 + term  # NAK: shorter than any data reply

    def sync_request(self, node: int, pending: Sequence[Fr700Request]) -> Fr700Request | None:
        widths: set[int] = set()
        for request in pending:
            if request.kind is Fr700RequestKind.READ:
                if request.reply_width is None:
                    return None  # its reply may have any width
                widths.add(request.reply_width)
            elif request.kind is Fr700RequestKind.MULTI:
                widths.add(_MULTI_REPLY_WIDTH)
            # a write's reply is an ACK, which no read's answer is
        for instruction in _SYNC_READS:
            if READ_WIDTHS[instruction] not in widths:
                return read(node, instruction, options=self.options)
        return None

    def processing_s(self, request: Fr700Request) -> float:
        if request.instruction == I.PARAMETER_CLEAR:
            check = _CLEAR_S
        elif request.instruction in _SLOW:
            check = EEPROM_CHECK_TIME_S
        else:
            check = CHECK_TIME_S
        return self.options.wait_s + check

    @property
    def acknowledges(self) -> bool:
        return self.send_ack

    def acknowledgement(self, request: Fr700Request, reply: Fr700Reply) -> bytes | None:
        if self.send_ack and isinstance(reply, Fr700Data):
            return encode_host_ack(request.station, self.options.terminator)
        return None

    def answer_delay_s(self) -> float:
        return ANSWER_DELAY_S

    def rest_after_acknowledgement_s(self) -> float:
        return ANSWER_DELAY_S

    def reoutput_request(self, request: Fr700Request, bad_frame: BadFrame) -> bytes | None:
        if not self.request_reoutput:
            return None
        if request.kind not in (Fr700RequestKind.READ, Fr700RequestKind.MULTI):
            return None
        # Only a damaged data reply can be asked for again (ACK and NAK frames
        # have no sum), and only the addressed station's: an unreadable station
        # is taken as ours, since only the addressed drive talks now.
        if not bad_frame.body.startswith(b"\x02"):
            return None
        if bad_frame.node is not None and bad_frame.node != request.station:
            return None
        return encode_reoutput_request(request.station, self.options.terminator)

    def line_framer(self) -> Fr700LineFramer:
        """A splitter of the whole line that ends frames as this dialect's line options do."""
        return Fr700LineFramer(self.options)

    def describe(self, reply: Fr700Reply) -> str:
        if isinstance(reply, Fr700Nak):
            return (
                f"station {reply.station:02d} NAK {reply.code.wire.decode()} "
                f"({reply.code.description})"
            )
        if isinstance(reply, Fr700Ack):
            return f"station {reply.station:02d} ACK"
        return f"station {reply.station:02d} data {reply.data.decode('ascii', 'replace')}"

    def parameter_code(self, text: str) -> str | None:
        if not isinstance(text, str) or not text.strip().upper().startswith("PR"):
            return None
        try:
            # Only catalogued parameters: their values have a unit (read_parameter's meaning).
            number = fr700_parameter_info(text).number
        except LocalProtocolError:
            return None
        return f"Pr.{number}"

    def make_drive(self, channel: Channel[Fr700Request], node: int) -> Fr700Drive:
        from ._drive import Fr700Drive

        return Fr700Drive(channel, node, options=self.options)

    def make_broadcast(self, channel: Channel[Fr700Request]) -> None:
        return None  # the computer link has no broadcast


#: The FR-700 dialect at the drive's factory settings (what ``protocol="fr700"`` starts from).
FR700_DIALECT: Final = Fr700Dialect()
