"""Mitsubishi FR-700 "computer link" on the same stack as the SJ300.

Open a bus with ``open_bus(url, protocol="fr700")`` (a URL's
``?protocol=fr700`` must agree with it); ``bus.drive(station)`` then
gives an :class:`Fr700Drive` (stations 0..31). The line options (waiting-time field, CR / CR LF, the
host's ACK) are :class:`Fr700Dialect`'s arguments, or the URL's
``wait_field=``, ``terminator=`` (``none``, ``cr``, ``crlf``) and ``ack=``.

The sans-IO core (:mod:`._codec`, :mod:`._parser`, :mod:`._requests`,
:mod:`._payloads`, :mod:`._dialect`, the parameter catalogue
:mod:`._parameters`, the drives' request parser :mod:`._request_parser`
and the whole line's framer :mod:`._line_frames`) imports no asyncio; only
:class:`Fr700Drive` is async. Every decision the reference leaves open is
recorded in the docstring of the module that makes it.

:mod:`sj300_async.fr700.codec` holds every name of the codec (all of this
package's names but the dialect and the drive), for sans-IO code that must
not load the async stack with this package (the simulated drives).
"""

from __future__ import annotations

from ._dialect import Fr700Dialect
from ._drive import Fr700Drive
from .codec import (
    A1_INSTRUCTIONS,
    DEFAULT_LINE_OPTIONS,
    ETX,
    FAULT_HISTORY_DEPTH,
    FR700_PARAMETERS,
    MAX_FRAME,
    MAX_REPLY_DATA,
    MAX_STATION,
    MIN_STATION,
    PARAMETER_RAW_MAX,
    RESET_DATA,
    STX,
    BadRequest,
    Fr700Ack,
    Fr700Data,
    Fr700Fault,
    Fr700FaultHistory,
    Fr700Instruction,
    Fr700LineOptions,
    Fr700Monitor,
    Fr700MultiReceive,
    Fr700MultiReply,
    Fr700Nak,
    Fr700NakCode,
    Fr700OperationMode,
    Fr700ParameterInfo,
    Fr700ParserEvent,
    Fr700Reply,
    Fr700ReplyParser,
    Fr700Request,
    Fr700RequestKind,
    Fr700Status,
    Fr700StatusBits,
    HostAnswer,
    HostRequest,
    RequestParser,
    decode_fault_history,
    decode_frame,
    decode_hex,
    decode_multi_reply,
    encode_ack,
    encode_data_reply,
    encode_host_ack,
    encode_nak,
    encode_reoutput_request,
    encode_request,
    fr700_parameter_info,
    parameter_number,
    parse_station,
    requests,
    sum_check,
    terminator_bytes,
)

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
    "Fr700Dialect",
    "Fr700Drive",
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
