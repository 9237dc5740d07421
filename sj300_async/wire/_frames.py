"""Frames as they crossed the line, whichever way: what captures and the sniffer see.

The host's reply parser sees only what drives say. A capture, the passive
sniffer and the Wireshark dissector see the whole line: the host's requests,
the drives' replies, the host's own answers to a reply (FR-700's ACK and
re-output request), frames that are broken and bytes outside any frame.
Each protocol's *line framer* (``Dialect.line_framer()``) splits a byte stream
into such pieces and tells what each one is, as a :class:`LineFrame`.

Nothing here knows a protocol, and nothing imports asyncio.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["FrameRole", "LineFrame"]


class FrameRole(enum.Enum):
    """What a piece of the line is."""

    REQUEST = "request"  #: the host asks a drive (or every drive)
    REPLY = "reply"  #: a drive answers
    HOST_ANSWER = "host answer"  #: the host answers a reply (FR-700's ACK, re-output request)
    BROKEN = "broken"  #: shaped like a frame, but not a valid one (e.g. a bad check code)
    NOISE = "noise"  #: bytes outside any frame, or a frame cut short


@dataclass(frozen=True, slots=True)
class LineFrame:
    """One piece of the line, exactly as it crossed it, and what it is."""

    #: The bytes, start and end codes included, byte for byte.
    data: bytes
    role: FrameRole
    #: The node (station) it names, when it could be read; broadcast is the
    #: protocol's broadcast number (SJ300: 0xFF).
    node: int | None
    #: A few words: ``"node 01: command 04 (read status)"``, ``"NAK 02 (check sum error)"``.
    summary: str
    #: The protocol's own object: its request (REQUEST) or reply (REPLY), usable
    #: with the dialect (``answers``, ``reply_frame_length``...); None otherwise.
    message: object | None = None
    #: BROKEN and NOISE: why (``"bad BCC"``, ``"bad length"``, ``"garbage"``).
    problem: str | None = None
    #: False when the frame's check code is wrong; None when it has none or is not read.
    check_ok: bool | None = None
    #: A request that gets an answer (not a broadcast); False for every other role.
    expects_reply: bool = False

    @property
    def valid(self) -> bool:
        """A request, reply or host answer (not broken, not noise)."""
        return self.role not in (FrameRole.BROKEN, FrameRole.NOISE)
