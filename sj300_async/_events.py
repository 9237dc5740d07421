"""What the parsers yield: reply frames, bad frames, and discarded bytes.

All events are frozen, slotted dataclasses. A parser yields exactly these
types (see :data:`ParserEvent`); anything it does not yield as a reply it
yields as :class:`BadFrame` or :class:`Discarded`, so nothing is lost unseen.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

from ._codes import NakCode

__all__ = [
    "AckDataReply",
    "AckReply",
    "BadFrame",
    "BadFrameReason",
    "DataReply",
    "DiscardReason",
    "Discarded",
    "NakReply",
    "ParserEvent",
    "Reply",
]


@dataclass(frozen=True, slots=True)
class AckReply:
    """Positive reply without data (``STX node ACK BCC CR``)."""

    node: int


@dataclass(frozen=True, slots=True)
class AckDataReply:
    """Positive reply with data: 8 digits for command 06, 2 for command 09."""

    node: int
    data: bytes


@dataclass(frozen=True, slots=True)
class DataReply:
    """Data reply without ACK: 8 characters (04), 104 (03) or 440 (05)."""

    node: int
    data: bytes


@dataclass(frozen=True, slots=True)
class NakReply:
    """Negative reply: the drive refused the request with an error code."""

    node: int
    code: NakCode


Reply = AckReply | AckDataReply | DataReply | NakReply


class BadFrameReason(enum.Enum):
    """Why a complete STX..CR frame was rejected."""

    TOO_SHORT = "too short"  #: fewer characters than the smallest legal frame
    BAD_BCC = "bad BCC"  #: the block check code does not match
    BAD_NODE = "bad node"  #: the node field is not a valid address
    BAD_LENGTH = "bad length"  #: no frame of the protocol has this length
    BAD_CHARACTERS = "bad characters"  #: e.g. a letter where digits belong
    BAD_COMMAND = "bad command"  #: (requests) the command field is not a command


@dataclass(frozen=True, slots=True)
class BadFrame:
    """A complete frame that is not valid; it carries the raw bytes between STX and CR."""

    reason: BadFrameReason
    #: The bytes between STX and CR.
    body: bytes
    #: The node address when it could be read, else None.
    node: int | None = None


class DiscardReason(enum.Enum):
    """Why bytes were thrown away outside of a complete frame."""

    GARBAGE = "garbage"  #: bytes before an STX, outside any frame
    RESTARTED = "restarted"  #: a partial frame cut short by a new STX
    OVERLONG = "overlong"  #: a frame longer than the longest legal one


@dataclass(frozen=True, slots=True)
class Discarded:
    """Bytes the parser threw away, and why."""

    reason: DiscardReason
    data: bytes


ParserEvent = AckReply | AckDataReply | DataReply | NakReply | BadFrame | Discarded


def slot_setters(cls: type) -> tuple[Callable[[Any, Any], None], ...]:
    """The ``__set__`` of each field's slot of a frozen, slotted dataclass, in field order.

    For decoders on a trusted path (values already checked): ``obj =
    object.__new__(cls)`` and one setter call per field build the same object
    as ``cls(...)``, which has no ``__post_init__`` here, at about half the
    cost of the generated ``__init__``'s ``object.__setattr__`` per field.
    """
    return tuple(vars(cls)[f.name].__set__ for f in fields(cls))


def unfrozen_twin(cls: type) -> type:
    """A plain class with the same slots as the frozen, slotted dataclass *cls*.

    For decoders on a trusted path that fill many fields: set the twin's
    attributes (plain slot stores, the cheapest there are), then assign
    ``__class__ = cls``. Python allows that because the two layouts are the
    same, and the result is the object ``cls(...)`` would have built (no
    ``__post_init__`` here), for about half the cost of the setters of
    :func:`slot_setters` once there are ten or so fields.
    """
    return type(f"Unfrozen{cls.__name__}", (), {"__slots__": vars(cls)["__slots__"]})
