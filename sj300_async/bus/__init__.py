"""The protocol-neutral async stack: bus, arbiter, link, protocol adapter, timing, URLs.

It imports no protocol package: it finds a protocol's dialect by name in
the registry (:func:`get_dialect`, :func:`register_protocol`), and the
dialect tells it everything protocol-specific (see :class:`Dialect`).
"""

from __future__ import annotations

from ._bus import Bus
from ._capture import CaptureFile
from ._channel import Channel
from ._dialect import Dialect, LineFramer, LineParser, LineRequest, SimulatorFactory
from ._link import ReconnectPolicy
from ._listen import Sniffing, sniff
from ._open import make_dialect, open_bus
from ._registry import (
    DEFAULT_PROTOCOL,
    get_dialect,
    protocol_names,
    register_protocol,
    unregister_protocol,
)
from ._sniffer import Anomaly, LineSniffer, SniffedFrame, Unanswered
from ._stats import BusStats, StatsSnapshot, TransactionStats
from ._timing import BusTiming
from ._trace import TraceHook, TraceRecord
from ._url import BusAddress, format_node_list, parse_bus_url, parse_flag, parse_node_list

__all__ = [
    "DEFAULT_PROTOCOL",
    "Anomaly",
    "Bus",
    "BusAddress",
    "BusStats",
    "BusTiming",
    "CaptureFile",
    "Channel",
    "Dialect",
    "LineFramer",
    "LineParser",
    "LineRequest",
    "LineSniffer",
    "ReconnectPolicy",
    "SimulatorFactory",
    "SniffedFrame",
    "Sniffing",
    "StatsSnapshot",
    "TraceHook",
    "TraceRecord",
    "TransactionStats",
    "Unanswered",
    "format_node_list",
    "get_dialect",
    "make_dialect",
    "open_bus",
    "parse_bus_url",
    "parse_flag",
    "parse_node_list",
    "protocol_names",
    "register_protocol",
    "sniff",
    "unregister_protocol",
]
