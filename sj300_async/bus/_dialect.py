"""What the async stack needs to know about a protocol: the dialect interface.

The arbiter, the protocol adapter, the bus and the URL parser are
protocol-neutral; a dialect tells them everything protocol-specific:

- on the line: how to parse it, which reply answers which request, what a
  positive reply carries and what a negative one means, what may be retried,
  frame lengths (the longest and the shortest reply) and processing times,
  the host's own answers to a reply (FR-700's ACK and re-output request), and
  the request that resynchronizes a node that missed an answer;
- around the line: its drive class and broadcast, which requests change a
  drive (a read-only bus refuses them), the range of node numbers, its URL
  options, the simulator that serves it on ``sim://`` and the profile that
  tells the gateway and the command line what its drives' answers mean.

A dialect is generic in its request type and its reply type, so the
transaction path (drive → :class:`~sj300_async.bus.Channel` → arbiter →
dialect) is typed end to end: a positive reply comes back to the drive as
the data it carries (``bytes``), with nothing to re-check.

Dialects are found by name through :mod:`._registry`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Protocol, TypeVar, runtime_checkable

from ..wire import BadFrame, Discarded, LineFrame, SJ300Error

if TYPE_CHECKING:
    from ._channel import Channel

__all__ = [
    "Dialect",
    "LineFramer",
    "LineParser",
    "LineRequest",
    "ReplyT",
    "RequestT",
    "SimulatorFactory",
]


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


#: A dialect's request type.
RequestT = TypeVar("RequestT", bound=LineRequest)
#: A dialect's reply type: what its parser yields besides bad frames and discards.
ReplyT = TypeVar("ReplyT")


class LineParser(Protocol[ReplyT]):
    """A sans-IO reply parser: bytes in, events out."""

    def feed(self, data: bytes) -> list[ReplyT | BadFrame | Discarded]:
        """Consume a chunk; return the events it completed."""

    def reset(self) -> list[ReplyT | BadFrame | Discarded]:
        """Forget a partial frame; return it as events (``Discarded``, in practice)."""


class LineFramer(Protocol):
    """A sans-IO splitter of a whole line, both directions (captures, the sniffer).

    Unlike the reply parser it keeps every byte: each piece it returns is a
    frame or a run of bytes outside any frame, exactly as received, and the
    pieces of a stream joined together are the stream (less what is still
    pending).
    """

    def feed(self, data: bytes) -> list[bytes]:
        """Consume a chunk; return the pieces it completed, in order."""

    def flush(self) -> list[bytes]:
        """Return what is pending (an incomplete frame) as a piece, and forget it."""

    def classify(
        self, piece: bytes, *, outbound: bool | None, pending: object | None = None
    ) -> LineFrame:
        """What *piece* is.

        Args:
            outbound: True when the host wrote it, False when it reached the
                host, None when unknown (a tap on the line: decided by content).
            pending: the request (the protocol's object, ``LineFrame.message``)
                still waiting for its answer, if any; it settles a piece that
                reads as either a request or an answer (an SJ300 status reply
                is as long as a set-frequency request).
        """


class SimulatorFactory(Protocol):
    """Builds the simulated line that serves a dialect on ``sim://`` (``Dialect.simulator``).

    The result has ``receive(data, now) -> [Transmission...]`` (the
    simulator's ``BusModel``).
    """

    def __call__(
        self,
        dialect: object,
        nodes: tuple[int, ...],
        *,
        factory_defaults: bool,
        wait_ms: int | None,
    ) -> object: ...


class Dialect(Protocol[RequestT, ReplyT]):
    """The protocol-specific part of a bus (see the module docstring)."""

    #: Short name, the registry's key: ``"sj300"``.
    name: str
    #: The lowest and highest address of a single drive.
    node_range: tuple[int, int]
    #: What the protocol calls an address, for messages: ``"node"``, ``"station"``.
    node_noun: str
    #: The nodes a ``sim://`` bus simulates when the URL does not say, as a node list.
    default_sim_nodes: str
    #: Query keys of a bus URL that configure this protocol (see :meth:`configure`).
    url_options: frozenset[str]
    #: Where its simulator lives, ``"package.module:callable"`` (a
    #: :class:`SimulatorFactory`), imported only when a ``sim://`` bus needs it.
    simulator: str
    #: The pcapng link type of its captures: one of the user link types 147..162
    #: (docs/CAPTURE.md lists who has which).
    capture_linktype: int

    @property
    def profile(self) -> str | None:
        """Where its profile lives, ``"package.module:attribute"``, or None.

        A :class:`sj300_async.profiles.Profile` says what its drives' answers
        mean, for the gateway and the command line; it is imported on first
        use. None: the protocol has none (the library still talks to its drives).
        """

    def configure(self, options: Mapping[str, str]) -> Dialect[RequestT, ReplyT]:
        """The dialect with the URL's protocol *options* applied (keys from :attr:`url_options`).

        Raises:
            LocalProtocolError: a bad option value.
        """

    # -- on the line --------------------------------------------------------------

    def new_parser(self) -> LineParser[ReplyT]:
        """A fresh reply parser (one per bus)."""

    def answers(self, request: RequestT, reply: ReplyT) -> bool:
        """True when *reply* has the node and shape of an answer to *request*."""

    def accept(self, request: RequestT, reply: ReplyT) -> bytes:
        """The data a positive answer carries (``b""`` for a bare acknowledgement).

        Raises:
            NakError: the answer is negative (the arbiter counts it by code).
        """

    def retryable(self, exc: SJ300Error) -> bool:
        """May the request be sent again after this error?"""

    def writes(self, request: RequestT) -> bool:
        """Does *request* change a drive? (A read-only bus refuses those.)"""

    def reply_frame_length(self, request: RequestT) -> int:
        """Length of the longest reply the request can get (for the time-out)."""

    def shortest_reply_length(self, request: RequestT) -> int:
        """Length of the shortest reply the request can get, a refusal included.

        With the request's own length it sets the plausibility floor
        (:meth:`~._timing.BusTiming.answer_floor`): a frame shaped like the
        answer that arrives sooner than the line could carry both is a
        duplicate or a stray, not the answer. Too short a value only weakens
        that check; too long a value would reject genuine answers.
        """

    def sync_request(self, node: int, pending: Sequence[RequestT]) -> RequestT | None:
        """A read-only request to *node* whose answer no reply to *pending* can pass for.

        After a time-out or a corrupted answer, *node*'s replies to *pending*
        may still come, late. Before the node's next request the arbiter sends
        this one and waits for its positive answer (a NAK could belong to any
        request, so it does not count): the node answers in order, so every
        late reply is then behind. Return None when no request of another
        shape exists; the arbiter then waits out the late replies instead
        (:data:`~._timing.LATE_REPLY_HORIZON` time-outs).
        """

    def processing_s(self, request: RequestT) -> float:
        """The device's own processing time for *request*, beyond the wire and wait times."""

    @property
    def acknowledges(self) -> bool:
        """Does the host ever answer a good reply (may :meth:`acknowledgement` give bytes)?

        The arbiter asks once, and then asks :meth:`acknowledgement` after
        every answer only when this is true.
        """

    def acknowledgement(self, request: RequestT, reply: ReplyT) -> bytes | None:
        """Bytes the host sends after a good reply (FR-700 computer ACK), or None."""

    def answer_delay_s(self) -> float:
        """How long the host waits after a reply before answering it (ACK or re-output request)."""

    def rest_after_acknowledgement_s(self) -> float:
        """How long the line must rest after the host's acknowledgement."""

    def reoutput_request(self, request: RequestT, bad_frame: BadFrame) -> bytes | None:
        """Bytes asking the device to send a damaged reply again (FR-700 format F), or None.

        The arbiter sends them at most once per attempt, :meth:`answer_delay_s`
        after the damaged frame, and waits a full response time-out more.
        """

    def line_framer(self) -> LineFramer:
        """A fresh splitter of the whole line, both directions (captures, the sniffer)."""

    def describe(self, reply: ReplyT) -> str:
        """The reply's meaning in a few words, for traces and logs."""

    def parameter_code(self, text: str) -> str | None:
        """The protocol's own name of parameter *text* (``"f002"`` → ``"F002"``), or None.

        None means *text* does not name a parameter of this protocol (a poller
        given several protocols' parameters reads each bus's own).
        """

    # -- around the line --------------------------------------------------------------

    def make_drive(self, channel: Channel[RequestT], node: int) -> object:
        """The protocol's drive object at *node* (validated by the drive class)."""

    def make_broadcast(self, channel: Channel[RequestT]) -> object | None:
        """The protocol's every-drive object, or None when it has no broadcast."""
