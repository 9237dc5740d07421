"""The neutral wire pieces every protocol's codec shares.

Frame events for what a parser rejects (:class:`BadFrame`, :class:`Discarded`),
parser statistics, the tolerant code-enum base, the run direction, the serial
line settings, and the library's error tree; the whole line's frames
(:class:`LineFrame`, :class:`FrameRole`) and the pcapng writer and reader of
captures; the decoders' speed tricks (:func:`slot_setters`,
:func:`unfrozen_twin`). Nothing here knows a protocol, and nothing here
imports asyncio.
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
from ._fast_construct import slot_setters, unfrozen_twin
from ._frames import FrameRole, LineFrame
from ._line import INSTANT_LINE, LineSettings
from ._parser_stats import ParserStats
from ._pcapng import (
    FLAG_CHECK_ERROR,
    FLAG_NOISE,
    CapturedPacket,
    CaptureFormatError,
    PacketDirection,
    PcapngCapture,
    PcapngInterface,
    PcapngWriter,
    read_pcapng,
)

__all__ = [
    "FLAG_CHECK_ERROR",
    "FLAG_NOISE",
    "INSTANT_LINE",
    "BadFrame",
    "BadFrameReason",
    "BusClosedError",
    "CaptureFormatError",
    "CapturedPacket",
    "Direction",
    "DiscardReason",
    "Discarded",
    "FrameRole",
    "LineFrame",
    "LineSettings",
    "LocalProtocolError",
    "NakError",
    "PacketDirection",
    "ParserStats",
    "PcapngCapture",
    "PcapngInterface",
    "PcapngWriter",
    "ProtocolError",
    "ReadOnlyError",
    "RemoteProtocolError",
    "ReplyTimeoutError",
    "SJ300Error",
    "TolerantIntEnum",
    "TransportError",
    "read_pcapng",
    "slot_setters",
    "unfrozen_twin",
]
