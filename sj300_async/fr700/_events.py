"""What the FR-700 reply parser yields: replies, plus the library's BadFrame and Discarded.

The reply events are frozen, slotted dataclasses. Bad frames and discarded
bytes reuse :class:`~sj300_async.BadFrame` and :class:`~sj300_async.Discarded`
so that the protocol adapter, the statistics and the arbiter treat both
protocols alike. For FR-700, ``BadFrame.body`` holds the whole frame from
its first byte (STX, ACK or NAK, which tells the formats apart) through the
sum check, without the CR/LF terminator.

Format C1 (the multi-command reply) has the shape of a data reply: STX,
station, twelve characters, ETX, sum. Without knowing the request the parser
cannot tell it from an E2 reply of the same width, so it yields
:class:`Fr700Data` for both; :func:`~sj300_async.fr700.decode_multi_reply`
reads a C1 out of the data when the request was a multi-command.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..wire import BadFrame, Discarded
from ._codes import Fr700NakCode

__all__ = ["Fr700Ack", "Fr700Data", "Fr700Nak", "Fr700ParserEvent", "Fr700Reply"]


@dataclass(frozen=True, slots=True)
class Fr700Ack:
    """Format C: the drive accepted a write (``ACK station``)."""

    station: int


@dataclass(frozen=True, slots=True)
class Fr700Nak:
    """Format D: the drive rejected the request (``NAK station code``)."""

    station: int
    code: Fr700NakCode


@dataclass(frozen=True, slots=True)
class Fr700Data:
    """Formats E, E1, E2, E3 and C1: ``STX station data ETX sum``; *data* as sent."""

    station: int
    #: The characters between the station number and ETX (hex digits, or the
    #: model name's text for E3).
    data: bytes


Fr700Reply = Fr700Ack | Fr700Nak | Fr700Data
Fr700ParserEvent = Fr700Ack | Fr700Nak | Fr700Data | BadFrame | Discarded
