"""sj300_async: an asyncio protocol stack for Hitachi SJ300 inverters on RS-485.

The sans-IO core (codec, parsers, payload decoders, parameter catalogue)
imports no asyncio and touches no I/O; the async layers build on it.
"""

from __future__ import annotations

from . import _requests as requests
from ._bcc import bcc
from ._bus import MUTATING_COMMANDS, Bus, open_bus
from ._codes import (
    Direction,
    NakCode,
    StatusA,
    StatusB,
    StatusC,
    TripStatusB,
    TripStatusC,
)
from ._commands import COMMAND_SPECS, Command, CommandSpec, ReplyKind, RequestData
from ._constants import BROADCAST, MAX_NODE, MIN_NODE
from ._drive import Broadcast, Drive
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
from ._events import (
    AckDataReply,
    AckReply,
    BadFrame,
    BadFrameReason,
    DataReply,
    Discarded,
    DiscardReason,
    NakReply,
    ParserEvent,
    Reply,
)
from ._framing import ParserStats
from ._line import LineSettings
from ._link import ReconnectPolicy
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
from ._poller import BusPollStats, DriveHealth, Poller, Sample
from ._reply_encoding import (
    encode_monitor,
    encode_reply,
    encode_status,
    encode_trip_history,
)
from ._request_parser import NAK_FOR_BAD_REQUEST, RequestParser
from ._requests import Request, encode_request
from ._stats import BusStats, StatsSnapshot, TransactionStats
from ._terminals import InputMonitor, InputTerminal, OutputTerminal
from ._timing import BusTiming
from ._trace import TraceHook, TraceRecord
from ._url import BusAddress, parse_bus_url, parse_node_list
from .transports import LineFaults

__version__ = "0.1.0"

__all__ = [
    "BROADCAST",
    "COMMAND_SPECS",
    "MAX_NODE",
    "MIN_NODE",
    "MUTATING_COMMANDS",
    "NAK_FOR_BAD_REQUEST",
    "PARAMETERS",
    "AckDataReply",
    "AckReply",
    "BadFrame",
    "BadFrameReason",
    "Broadcast",
    "Bus",
    "BusAddress",
    "BusClosedError",
    "BusPollStats",
    "BusStats",
    "BusTiming",
    "Command",
    "CommandSpec",
    "DataReply",
    "Direction",
    "DiscardReason",
    "Discarded",
    "Drive",
    "DriveHealth",
    "InputMonitor",
    "InputTerminal",
    "InverterStatus",
    "LineFaults",
    "LineSettings",
    "LocalProtocolError",
    "MonitorData",
    "NakCode",
    "NakError",
    "NakReply",
    "OutputTerminal",
    "ParameterInfo",
    "ParserEvent",
    "ParserStats",
    "Poller",
    "ProtocolError",
    "ReadOnlyError",
    "ReconnectPolicy",
    "RemoteProtocolError",
    "Reply",
    "ReplyKind",
    "ReplyParser",
    "ReplyTimeoutError",
    "Request",
    "RequestData",
    "RequestParser",
    "SJ300Error",
    "Sample",
    "StatsSnapshot",
    "StatusA",
    "StatusB",
    "StatusC",
    "TraceHook",
    "TraceRecord",
    "TransactionStats",
    "TransportError",
    "TripHistory",
    "TripRecord",
    "TripStatusB",
    "TripStatusC",
    "__version__",
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
    "open_bus",
    "parameter_info",
    "parse_bus_url",
    "parse_node_list",
    "requests",
]
