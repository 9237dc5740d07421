"""Frame events every protocol's parser shares: bad frames and discarded bytes.

A parser yields its protocol's replies, and for everything else one of these,
so that nothing is lost unseen and the bus counts both protocols alike.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["BadFrame", "BadFrameReason", "DiscardReason", "Discarded"]


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
