"""The neutral wire pieces every protocol's codec shares.

Frame events for what a parser rejects (:class:`BadFrame`, :class:`Discarded`),
parser statistics, the tolerant code-enum base, the run direction, the serial
line settings, and the library's error tree. Nothing here knows a protocol,
and nothing here imports asyncio.
"""

from __future__ import annotations

from ._enums import Direction, TolerantIntEnum
from ._errors import (
    BusClosedError,
    LocalProtocolError,
    NakError,
    ProtocolError,
    ReadOnlyError,
    RemoteProtocolError,
    ReplyTimeoutError,
    SJ300Error,
    TransportError,
)
from ._events import BadFrame, BadFrameReason, Discarded, DiscardReason
from ._line import LineSettings
from ._parser_stats import ParserStats

__all__ = [
    "BadFrame",
    "BadFrameReason",
    "BusClosedError",
    "Direction",
    "DiscardReason",
    "Discarded",
    "LineSettings",
    "LocalProtocolError",
    "NakError",
    "ParserStats",
    "ProtocolError",
    "ReadOnlyError",
    "RemoteProtocolError",
    "ReplyTimeoutError",
    "SJ300Error",
    "TolerantIntEnum",
    "TransportError",
]
