"""The shared machinery of every simulated line: what a server needs of a simulated bus."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from ..wire import ParserStats

__all__ = ["BusModel", "LineCounters", "Transmission"]


@dataclass(frozen=True, slots=True)
class Transmission:
    """Bytes the line carries back to the host: send *data* *delay_s* seconds after ``now``."""

    delay_s: float
    data: bytes


class BusModel(Protocol):
    """What the servers need of a simulated bus, whatever protocol its drives speak."""

    def receive(self, data: bytes, now: float) -> list[Transmission]:
        """Feed the host's bytes that arrived at *now*; return the replies, in order."""


class LineCounters:
    """What every simulated line counts, whatever protocol its drives speak."""

    __slots__ = (
        "absent",
        "corrupted_replies",
        "delayed_replies",
        "dropped_replies",
        "naks",
        "parser",
        "replies",
        "requests",
    )

    def __init__(self, parser: ParserStats) -> None:
        #: Valid request frames, whoever they were for (broadcasts included).
        self.requests = 0
        #: Frames for a node without a drive, or a silenced one.
        self.absent = 0
        #: Replies put on the line (NAKs and corrupted ones included, dropped ones not).
        self.replies = 0
        #: Negative replies put on the line, by code.
        self.naks: dict[Any, int] = {}
        #: Replies lost to :meth:`Faults.drop_next`.
        self.dropped_replies = 0
        #: Replies damaged by :meth:`Faults.corrupt_next`.
        self.corrupted_replies = 0
        #: Replies held back by :meth:`Faults.delay_next`.
        self.delayed_replies = 0
        #: The request parser's own counters.
        self.parser = parser

    @property
    def bad_frames(self) -> int:
        """Complete frames the parser rejected (bad check code, length, characters...)."""
        return self.parser.bad_frames

    @property
    def discarded_bytes(self) -> int:
        """Bytes thrown away outside complete frames."""
        return self.parser.discarded_bytes

    def __repr__(self) -> str:
        names = [n for cls in type(self).__mro__ for n in getattr(cls, "__slots__", ())]
        fields = ", ".join(f"{n}={getattr(self, n)!r}" for n in names if n != "parser")
        extra = f"bad_frames={self.bad_frames}, discarded={self.discarded_bytes}"
        return f"{type(self).__name__}({fields}, {extra})"
