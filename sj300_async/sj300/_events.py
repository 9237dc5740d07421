"""What the parsers yield: reply frames, bad frames, and discarded bytes.

All events are frozen, slotted dataclasses. A parser yields exactly these
types (see :data:`ParserEvent`); anything it does not yield as a reply it
yields as :class:`BadFrame` or :class:`Discarded`, so nothing is lost unseen.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..wire import BadFrame, Discarded
from ._codes import NakCode

__all__ = [
    "AckDataReply",
    "AckReply",
    "DataReply",
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


ParserEvent = AckReply | AckDataReply | DataReply | NakReply | BadFrame | Discarded
