"""The protocol-neutral async stack: bus, arbiter, link, protocol adapter, timing, URLs.

It imports no protocol package: it finds a protocol's dialect by name in
the registry (:func:`get_dialect`, :func:`register_protocol`), and the
dialect tells it everything protocol-specific (see :class:`Dialect`). Nor
does it import the simulator: a ``sim://`` URL's connector is found by its
scheme in the same registry (a :class:`SchemeConnector`).
"""

from __future__ import annotations

from ._bus import Bus
from ._capture import CaptureFile, combine
from ._channel import Channel, cap_retries, retries_at_most
from ._chunklog import ChunkLog, Kept
from ._dialect import Dialect, LineFramer, LineParser, LineRequest, SimulatorFactory
from ._link import ReconnectPolicy
from ._listen import Sniffing, sniff
from ._open import BusOptions, make_dialect, open_bus
from ._registry import (
    DEFAULT_PROTOCOL,
    SchemeConnection,
    SchemeConnector,
    get_dialect,
    load_object,
    protocol_names,
    register_protocol,
    unregister_protocol,
)
from ._sniffer import Anomaly, LineSniffer, SniffedFrame, Unanswered
from ._stats import LATENCY_BUCKETS_S, BusStats, StatsSnapshot, TransactionStats
from ._timing import BusTiming
from ._trace import TraceHook, TraceRecord
from ._url import (
    BusAddress,
    format_node_list,
    parse_bus_url,
    parse_flag,
    parse_node_list,
    url_protocol,
)

__all__ = [
    "DEFAULT_PROTOCOL",
    "LATENCY_BUCKETS_S",
    "Anomaly",
    "Bus",
    "BusAddress",
    "BusOptions",
    "BusStats",
    "BusTiming",
    "CaptureFile",
    "Channel",
    "ChunkLog",
    "Dialect",
    "Kept",
    "LineFramer",
    "LineParser",
    "LineRequest",
    "LineSniffer",
    "ReconnectPolicy",
    "SchemeConnection",
    "SchemeConnector",
    "SimulatorFactory",
    "SniffedFrame",
    "Sniffing",
    "StatsSnapshot",
    "TraceHook",
    "TraceRecord",
    "TransactionStats",
    "Unanswered",
    "cap_retries",
    "combine",
    "format_node_list",
    "get_dialect",
    "load_object",
    "make_dialect",
    "open_bus",
    "parse_bus_url",
    "parse_flag",
    "parse_node_list",
    "protocol_names",
    "register_protocol",
    "retries_at_most",
    "sniff",
    "unregister_protocol",
    "url_protocol",
]
