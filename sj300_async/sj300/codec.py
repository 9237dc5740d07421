"""The SJ300 codec's public face: every name of :mod:`sj300_async.sj300` but the async ones.

Requests and their builders, the reply parser and its events, the payload
decoders and the simulator's encoders, codes, terminals, parameters, and
the drives' request parser. All of it is sans-IO, and so is this module:
it imports the codec's modules and nothing else of ours but
:mod:`sj300_async.wire`. The package re-exports every name here, plus the
dialect (:class:`~sj300_async.sj300.SJ300Dialect`) and the drive classes,
which bring the async stack with them.

Users import from the package. Other sans-IO code of the library (the
simulated drives of :mod:`sj300_async.simulator.sj300`) imports from here,
so that what it depends on stays sans-IO module by module (the sans-IO
scans in ``tests/`` check it).
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
from ._terminals import ASSIGNED_INPUT_BITS, InputMonitor, InputTerminal, OutputTerminal

__all__ = [
    "ASSIGNED_INPUT_BITS",
    "BROADCAST",
    "COMMAND_SPECS",
    "MAX_NODE",
    "MIN_NODE",
    "NAK_FOR_BAD_REQUEST",
    "PARAMETERS",
    "AckDataReply",
    "AckReply",
    "Command",
    "CommandSpec",
    "DataReply",
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
