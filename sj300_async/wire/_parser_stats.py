"""Counters every protocol's parser keeps: nothing it throws away goes uncounted."""

from __future__ import annotations

__all__ = ["ParserStats"]


class ParserStats:
    """Counters of everything a parser saw; all discards are counted here."""

    __slots__ = ("bad_frames", "discarded_bytes", "frames", "overlong_frames", "restarted_frames")

    def __init__(self) -> None:
        #: Valid frames yielded.
        self.frames = 0
        #: Complete frames rejected (BadFrame events).
        self.bad_frames = 0
        #: Bytes thrown away outside complete frames (Discarded events).
        self.discarded_bytes = 0
        #: Partial frames cut short by an STX.
        self.restarted_frames = 0
        #: Frames abandoned for exceeding the longest legal length.
        self.overlong_frames = 0

    def __repr__(self) -> str:
        fields = ", ".join(f"{name}={getattr(self, name)}" for name in self.__slots__)
        return f"ParserStats({fields})"
