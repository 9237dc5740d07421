"""Enums every protocol shares: the tolerant code enum base, and the run direction."""

from __future__ import annotations

import enum
from typing import Self

__all__ = ["Direction", "TolerantIntEnum"]


class TolerantIntEnum(enum.IntEnum):
    """IntEnum that keeps unknown values as ``UNKNOWN_<n>`` pseudo-members."""

    @classmethod
    def _missing_(cls, value: object) -> Self | None:
        if not isinstance(value, int) or isinstance(value, bool):
            return None
        member = int.__new__(cls, value)
        member._name_ = f"UNKNOWN_{value}"
        member._value_ = value
        return member

    @property
    def known(self) -> bool:
        """True when the manual lists this code."""
        return self._name_ in type(self).__members__


class Direction(TolerantIntEnum):
    """Run direction: the data of command 00 and monitor item 3."""

    STOP = 0  #: stopped / stop command
    FORWARD = 1  #: forward rotation / run forward
    REVERSE = 2  #: reverse rotation / run reverse
