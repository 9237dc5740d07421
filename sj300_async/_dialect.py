"""What the async stack needs to know about a protocol: the dialect interface.

The arbiter, the protocol adapter and the bus are protocol-neutral; a
dialect tells them how to parse the line, which reply answers which
request, what a negative reply means, and the protocol's timing quirks.
SJ300 is the first dialect (here); the Mitsubishi FR-700 computer link is
the second (:mod:`sj300_async.fr700`).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from ._codes import NakCode
from ._errors import NakError, SJ300Error
from ._events import BadFrame, Discarded, NakReply, Reply
from ._matching import answers
from ._parser import ReplyParser
from ._reply_encoding import encode_reply
from ._requests import Request
from ._timing import reply_frame_length

__all__ = ["SJ300_DIALECT", "Dialect", "LineParser", "LineRequest", "SJ300Dialect"]


@runtime_checkable
class LineRequest(Protocol):
    """What the arbiter needs of a request, whatever the protocol."""

    @property
    def node(self) -> int:
        """The addressed station (for messages and statistics)."""

    @property
    def frame(self) -> bytes:
        """The bytes to write."""

    @property
    def expects_reply(self) -> bool:
        """False for a broadcast or a command the device never answers."""

    @property
    def label(self) -> str:
        """A short name for messages, e.g. ``"command 04"``."""


class LineParser(Protocol):
    """A sans-IO reply parser: bytes in, events out."""

    def feed(self, data: bytes) -> list[Any]:
        """Consume a chunk; return the events it completed."""

    def reset(self) -> list[Any]:
        """Forget a partial frame; return it as discarded events."""


class Dialect(Protocol):
    """The protocol-specific part of a bus."""

    #: Short name, e.g. ``"sj300"``.
    name: str

    def new_parser(self) -> LineParser:
        """A fresh reply parser (one per connection)."""

    def answers(self, request: Any, event: Any) -> bool:
        """True when *event* has the node and shape of an answer to *request*."""

    def refusal(self, request: Any, reply: Any) -> SJ300Error | None:
        """The error a negative reply stands for, or None for a positive reply."""

    def retryable(self, exc: SJ300Error) -> bool:
        """May the request be sent again after this error?"""

    def reply_frame_length(self, request: Any) -> int:
        """Length of the longest reply the request can get (for the time-out)."""

    def processing_s(self, request: Any) -> float:
        """The device's own processing time for *request*, beyond the wire and wait times."""

    def acknowledgement(self, request: Any, reply: Any) -> bytes | None:
        """Bytes the host sends after a good reply (FR-700 computer ACK), or None."""

    def answer_delay_s(self) -> float:
        """How long the host waits after a reply before answering it (ACK or re-output request)."""

    def rest_after_acknowledgement_s(self) -> float:
        """How long the line must rest after the host's acknowledgement."""

    def reoutput_request(self, request: Any, bad_frame: BadFrame) -> bytes | None:
        """Bytes asking the device to send a damaged reply again (FR-700 format F), or None.

        The arbiter sends them at most once per attempt, :meth:`answer_delay_s`
        after the damaged frame, and waits a full response time-out more.
        """

    def trace_bytes(self, event: Any) -> bytes:
        """The wire bytes of a parser event, for the trace hook."""


class SJ300Dialect:
    """The Hitachi SJ300 ASCII protocol."""

    name = "sj300"

    def new_parser(self) -> ReplyParser:
        return ReplyParser()

    def answers(self, request: Request, event: Reply) -> bool:
        return answers(request, event)

    def refusal(self, request: Request, reply: Reply) -> SJ300Error | None:
        if isinstance(reply, NakReply):
            return NakError(reply.node, reply.code)
        return None

    def retryable(self, exc: SJ300Error) -> bool:
        # NAK 01..08 are transmission errors; 11, 13 and 16 are the drive's verdict.
        if isinstance(exc, NakError):
            return NakCode(exc.code).is_transmission_error
        return True

    def reply_frame_length(self, request: Request) -> int:
        return reply_frame_length(request.command)

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

    def trace_bytes(self, event: Reply | BadFrame | Discarded) -> bytes:
        if isinstance(event, Discarded):
            return event.data
        if isinstance(event, BadFrame):
            return event.body
        return encode_reply(event)


SJ300_DIALECT = SJ300Dialect()
