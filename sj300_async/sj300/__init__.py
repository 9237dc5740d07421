"""The Hitachi SJ300 ASCII protocol: codec, dialect, drive class and parameter catalogue.

The codec (:mod:`._requests`, :mod:`._parser`, :mod:`._payloads`,
:mod:`._reply_encoding`, :mod:`._request_parser`, ...) is sans-IO: it imports
no asyncio and touches no I/O. :class:`SJ300Dialect` tells the protocol-neutral
bus (:mod:`sj300_async.bus`) what it needs to know about the protocol, and
:class:`Drive` / :class:`Broadcast` are the typed async API on top.
"""

from __future__ import annotations

from . import _requests as requests
from ._bcc import bcc
from ._codes import (
    NakCode,
    StatusA,
    StatusB,
    StatusC,
    TripCode,
    TripStatusB,
    TripStatusC,
)
from ._commands import COMMAND_SPECS, Command, CommandSpec, ReplyKind, RequestData
from ._constants import BROADCAST, MAX_NODE, MIN_NODE
from ._dialect import MUTATING_COMMANDS, SJ300_DIALECT, SJ300Dialect
from ._drive import Broadcast, Drive
from ._events import (
    AckDataReply,
    AckReply,
    DataReply,
    NakReply,
    ParserEvent,
    Reply,
)
from ._matching import answers
from ._parameters import (
    PARAMETERS,
    ParameterInfo,
    motor_capacity_kw,
    normalize_code,
    parameter_info,
)
from ._parser import ReplyParser
from ._payloads import (
    InverterStatus,
    MonitorData,
    TripHistory,
    TripRecord,
    decode_can_store,
    decode_monitor,
    decode_parameter_value,
    decode_status,
    decode_trip_history,
)
from ._reply_encoding import (
    encode_monitor,
    encode_reply,
    encode_status,
    encode_trip_history,
)
from ._request_parser import NAK_FOR_BAD_REQUEST, RequestParser
from ._requests import Request, encode_request
from ._terminals import InputMonitor, InputTerminal, OutputTerminal

__all__ = [
    "BROADCAST",
    "COMMAND_SPECS",
    "MAX_NODE",
    "MIN_NODE",
    "MUTATING_COMMANDS",
    "NAK_FOR_BAD_REQUEST",
    "PARAMETERS",
    "SJ300_DIALECT",
    "AckDataReply",
    "AckReply",
    "Broadcast",
    "Command",
    "CommandSpec",
    "DataReply",
    "Drive",
    "InputMonitor",
    "InputTerminal",
    "InverterStatus",
    "MonitorData",
    "NakCode",
    "NakReply",
    "OutputTerminal",
    "ParameterInfo",
    "ParserEvent",
    "Reply",
    "ReplyKind",
    "ReplyParser",
    "Request",
    "RequestData",
    "RequestParser",
    "SJ300Dialect",
    "StatusA",
    "StatusB",
    "StatusC",
    "TripCode",
    "TripHistory",
    "TripRecord",
    "TripStatusB",
    "TripStatusC",
    "answers",
    "bcc",
    "decode_can_store",
    "decode_monitor",
    "decode_parameter_value",
    "decode_status",
    "decode_trip_history",
    "encode_monitor",
    "encode_reply",
    "encode_request",
    "encode_status",
    "encode_trip_history",
    "motor_capacity_kw",
    "normalize_code",
    "parameter_info",
    "requests",
]
