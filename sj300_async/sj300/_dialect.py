"""The Hitachi SJ300 ASCII protocol as a dialect of the protocol-neutral async stack.

What the bus learns from it:

- Matching: a reply answers a request when it comes from the addressed node
  and has the shape of the command's reply (:func:`~._matching.answers`); a
  NAK from the node answers any request.
- Acceptance: a positive reply gives its data (``b""`` for a bare ACK); a
  NAK becomes :class:`~sj300_async.NakError` with its :class:`NakCode`.
- Retries: NAK 01..08 are transmission errors, worth another attempt; 11,
  13 and 16 are the drive's verdict.
- Timing: replies are at most 449 characters; the drive states no
  processing time beyond its C078 wait (the caller's ``wait_time_s``). The
  shortest reply is an ACK (7 characters) or a NAK (9).
- Resync after a missed answer: command 09 "can store" (ACK + 2 digits, a
  shape no other command's answer has), else 04 status (8 data characters),
  else 03 monitor (104), each unless a request of that command is among the
  pending ones; with all three pending, none (the arbiter waits instead).
- Around the line: nodes 1..32, :class:`~._drive.Drive` per node and
  :class:`~._drive.Broadcast` for node FF; the commands in
  :data:`MUTATING_COMMANDS` change a drive; no URL options; the simulator is
  :func:`sj300_async.simulator.sj300.simulate`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Final

from ..wire import BadFrame, LocalProtocolError, NakError, SJ300Error
from ._codes import NakCode
from ._commands import Command, reply_frame_length, shortest_reply_frame_length
from ._constants import MAX_NODE, MIN_NODE
from ._drive import Broadcast, Drive
from ._events import AckDataReply, AckReply, DataReply, NakReply, Reply
from ._line_frames import SJ300LineFramer
from ._matching import answers as _answers
from ._parameters import normalize_code
from ._parser import ReplyParser
from ._requests import Request, can_store, read_monitor, read_status

if TYPE_CHECKING:
    from ..bus import Channel

__all__ = ["MUTATING_COMMANDS", "SJ300_DIALECT", "SJ300Dialect"]

#: Read-only commands whose positive answers have shapes of their own, in the
#: order a resync tries them (see ``SJ300Dialect.sync_request``).
_SYNC_COMMANDS: Final = (
    (Command.CAN_STORE, can_store),
    (Command.READ_STATUS, read_status),
    (Command.READ_MONITOR, read_monitor),
)

#: Commands that change a drive; a read-only bus refuses them.
MUTATING_COMMANDS: Final = frozenset(
    {
        Command.RUN,
        Command.SET_FREQUENCY,
        Command.SET_TERMINALS,
        Command.WRITE_PARAMETER,
        Command.INITIALIZE,
        Command.STORE,
        Command.RECALCULATE,
    }
)


class SJ300Dialect:
    """The Hitachi SJ300 ASCII protocol (see the module docstring)."""

    name = "sj300"
    node_range = (MIN_NODE, MAX_NODE)
    node_noun = "node"
    default_sim_nodes = "1-8"
    url_options: frozenset[str] = frozenset()
    simulator = "sj300_async.simulator.sj300:simulate"
    profile = "sj300_async.sj300._profile:SJ300_PROFILE"
    capture_linktype = 147  # LINKTYPE_USER0 (docs/CAPTURE.md)
    acknowledges = False  # the host never answers an SJ300 reply

    def __repr__(self) -> str:
        return "SJ300Dialect()"

    def configure(self, options: Mapping[str, str]) -> SJ300Dialect:
        if options:
            raise LocalProtocolError(f"the SJ300 protocol has no options: {sorted(options)}")
        return self

    def new_parser(self) -> ReplyParser:
        return ReplyParser()

    # The function itself, not a method calling it: one call less per frame.
    answers = staticmethod(_answers)

    def accept(self, request: Request, reply: Reply) -> bytes:
        # Most answers carry data: test for those first (exact types: the parser
        # makes no subclasses, and an identity test is the cheapest there is).
        if type(reply) is DataReply or type(reply) is AckDataReply:
            return reply.data
        if type(reply) is NakReply:
            raise NakError(reply.node, reply.code)
        return b""  # AckReply

    def retryable(self, exc: SJ300Error) -> bool:
        # NAK 01..08 are transmission errors; 11, 13 and 16 are the drive's verdict.
        if isinstance(exc, NakError):
            return NakCode(exc.code).is_transmission_error
        return True

    def writes(self, request: Request) -> bool:
        return request.command in MUTATING_COMMANDS

    def reply_frame_length(self, request: Request) -> int:
        return reply_frame_length(request.command)

    def shortest_reply_length(self, request: Request) -> int:
        return shortest_reply_frame_length(request.command)

    def sync_request(self, node: int, pending: Sequence[Request]) -> Request | None:
        # Each command's positive answer has a shape of its own (matching checks
        # the kind and the data length), so a sync of a command none of the
        # pending requests has cannot be answered by their late replies.
        commands = {request.command for request in pending}
        for command, build in _SYNC_COMMANDS:
            if command not in commands:
                return build(node)
        return None

    def processing_s(self, request: Request) -> float:
        return 0.0  # the SJ300 states none beyond C078; the margin covers it

    def acknowledgement(self, request: Request, reply: Reply) -> bytes | None:
        return None

    def answer_delay_s(self) -> float:
        return 0.0

    def rest_after_acknowledgement_s(self) -> float:
        return 0.0

    def reoutput_request(self, request: Request, bad_frame: BadFrame) -> bytes | None:
        return None  # an SJ300 cannot be asked to repeat a reply: the host retries

    def line_framer(self) -> SJ300LineFramer:
        return SJ300LineFramer()

    def describe(self, reply: Reply) -> str:
        if isinstance(reply, NakReply):
            return f"node {reply.node:02d} NAK {int(reply.code):02d} ({reply.code.description})"
        if isinstance(reply, AckReply):
            return f"node {reply.node:02d} ACK"
        kind = "ACK + data" if isinstance(reply, AckDataReply) else "data"
        return f"node {reply.node:02d} {kind} {reply.data.decode('ascii', 'replace')}"

    def parameter_code(self, text: str) -> str | None:
        try:
            return normalize_code(text)
        except LocalProtocolError:
            return None

    def make_drive(self, channel: Channel[Request], node: int) -> Drive:
        return Drive(channel, node)

    def make_broadcast(self, channel: Channel[Request]) -> Broadcast:
        return Broadcast(channel)


SJ300_DIALECT: Final = SJ300Dialect()
