"""The FR-700 codec's public face: every name of :mod:`sj300_async.fr700` but the async ones.

Requests and their builders, the frame encoders (the drives' replies
included), the reply parser and its events, the payload decoders, codes,
the parameter catalogue, and the drives' request parser. All of it is
sans-IO, and so is this module: it imports the codec's modules and nothing
else of ours but :mod:`sj300_async.wire`. The package re-exports every name
here, plus :class:`~sj300_async.fr700.Fr700Dialect` and
:class:`~sj300_async.fr700.Fr700Drive`, which bring the async stack with them.
(:mod:`._codec`, a private module, is the frame layer: sum check, stations,
frame encoders.)

Users import from the package. Other sans-IO code of the library (the
simulated drives of :mod:`sj300_async.simulator.fr700`) imports from here,
so that what it depends on stays sans-IO module by module (the sans-IO
scans in ``tests/`` check it).
"""

from __future__ import annotations

from . import _requests as requests
from ._codec import (
    DEFAULT_LINE_OPTIONS,
    MAX_REPLY_DATA,
    MAX_STATION,
    MIN_STATION,
    Fr700LineOptions,
    encode_ack,
    encode_data_reply,
    encode_host_ack,
    encode_nak,
    encode_reoutput_request,
    encode_request,
    parse_station,
    sum_check,
    terminator_bytes,
)
from ._codes import (
    A1_INSTRUCTIONS,
    ETX,
    RESET_DATA,
    STX,
    Fr700Instruction,
    Fr700NakCode,
    Fr700OperationMode,
    Fr700StatusBits,
)
from ._events import Fr700Ack, Fr700Data, Fr700Nak, Fr700ParserEvent, Fr700Reply
from ._faults import FAULT_HISTORY_DEPTH, Fr700Fault, Fr700FaultHistory, decode_fault_history
from ._parameters import (
    FR700_PARAMETERS,
    PARAMETER_RAW_MAX,
    Fr700ParameterInfo,
    fr700_parameter_info,
    parameter_number,
)
from ._parser import MAX_FRAME, Fr700ReplyParser, decode_frame
from ._payloads import Fr700Monitor, Fr700MultiReply, Fr700Status, decode_hex, decode_multi_reply
from ._request_parser import BadRequest, HostAnswer, HostRequest, RequestParser
from ._requests import Fr700MultiReceive, Fr700Request, Fr700RequestKind

__all__ = [
    "A1_INSTRUCTIONS",
    "DEFAULT_LINE_OPTIONS",
    "ETX",
    "FAULT_HISTORY_DEPTH",
    "FR700_PARAMETERS",
    "MAX_FRAME",
    "MAX_REPLY_DATA",
    "MAX_STATION",
    "MIN_STATION",
    "PARAMETER_RAW_MAX",
    "RESET_DATA",
    "STX",
    "BadRequest",
    "Fr700Ack",
    "Fr700Data",
    "Fr700Fault",
    "Fr700FaultHistory",
    "Fr700Instruction",
    "Fr700LineOptions",
    "Fr700Monitor",
    "Fr700MultiReceive",
    "Fr700MultiReply",
    "Fr700Nak",
    "Fr700NakCode",
    "Fr700OperationMode",
    "Fr700ParameterInfo",
    "Fr700ParserEvent",
    "Fr700Reply",
    "Fr700ReplyParser",
    "Fr700Request",
    "Fr700RequestKind",
    "Fr700Status",
    "Fr700StatusBits",
    "HostAnswer",
    "HostRequest",
    "RequestParser",
    "decode_fault_history",
    "decode_frame",
    "decode_hex",
    "decode_multi_reply",
    "encode_ack",
    "encode_data_reply",
    "encode_host_ack",
    "encode_nak",
    "encode_reoutput_request",
    "encode_request",
    "fr700_parameter_info",
    "parameter_number",
    "parse_station",
    "requests",
    "sum_check",
    "terminator_bytes",
]
