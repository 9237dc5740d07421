"""``sj300 gateway``: one process owns the lines, polls the drives and serves them.

The core is protocol-neutral and knows no northbound by name: it opens
the lines, polls them, keeps each drive's readings and latest
:class:`~sj300_async.profiles.DriveSnapshot`, judges and carries out writes
(write grants, control leases, the audit log), and hands every snapshot to
the configured northbounds. The built-in northbounds are packages of their
own behind :class:`Northbound`: :mod:`.modbus` (Modbus TCP for SCADA),
:mod:`.mqtt` (state, Home Assistant discovery, commands; and the fleet
view's subscriber), :mod:`.http` (Prometheus metrics and a health check).
Needs the ``gateway`` extra (``pip install 'sj300-async[gateway]'``; from
a checkout, ``make gateway`` installs it into ``.venv``). The
user's view is docs/GATEWAY.md; docs/ARCHITECTURE.md shows how to add a
northbound.
"""

from __future__ import annotations

from ._audit import AuditLog, excerpt
from ._budget import KeyedBudget
from ._check import ConfigCheck, check_config
from ._config import config_from_flags, load_config, parse_config, valid_name
from ._control import Controller
from ._drive import GatewayDrive, Lease
from ._errors import GatewayStartError
from ._fastjson import compact_json
from ._gateway import Gateway, GatewayLine
from ._line_health import LineHealth
from ._line_traffic import LineTraffic
from ._listeners import (
    LIMIT_KEYS,
    ConnectionLimit,
    Listener,
    ListenerLimits,
    RateLimitedLog,
    Slot,
    listener_families,
)
from ._metrics import (
    DriveView,
    LineView,
    busy_seconds,
    cumulative_buckets,
    drive_view,
    gateway_metrics,
    line_problems,
)
from ._model import (
    DEFAULT_LEASE_S,
    DEFAULT_STALE_AFTER_S,
    LAPSE_ACTIONS,
    POLL_READS,
    UNIT_RANGE,
    Endpoint,
    GatewayConfig,
    LapseAction,
    LineConfig,
    PollRead,
    WriteGrant,
    default_gateway_id,
    parse_endpoint,
)
from ._northbound import (
    Flag,
    GatewayView,
    Northbound,
    NorthboundSpec,
    SectionContext,
    ServedLine,
    UnitScope,
    get_northbound,
    northbound_extra,
    northbound_names,
    register_northbound,
    unregister_northbound,
)
from ._parameter_values import parameter_request
from ._passwords import (
    PasswordChecks,
    User,
    hash_password,
    named_entries,
    parse_password_hash,
    parse_users,
    verify_password,
)
from ._sdnotify import ServiceManager
from ._served import DIRECTION_WORDS, Quality, ServedDrive, ServedValues
from ._toml import COMMAND_LINE, ConfigContext, ConfigTable, GatewayConfigError, unknown_choice
from ._trend import BLOCK as TREND_BLOCK
from ._trend import SAMPLE_BYTES as TREND_SAMPLE_BYTES
from ._trend import VALUES as TREND_VALUES
from ._trend import Trend, trend_capacity
from ._writes import (
    DROPPED_BY_STOP,
    Heartbeat,
    ParameterValue,
    ParameterWrite,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
    needs_lease,
)

__all__ = [
    "COMMAND_LINE",
    "DEFAULT_LEASE_S",
    "DEFAULT_STALE_AFTER_S",
    "DIRECTION_WORDS",
    "DROPPED_BY_STOP",
    "LAPSE_ACTIONS",
    "LIMIT_KEYS",
    "POLL_READS",
    "TREND_BLOCK",
    "TREND_SAMPLE_BYTES",
    "TREND_VALUES",
    "UNIT_RANGE",
    "AuditLog",
    "ConfigCheck",
    "ConfigContext",
    "ConfigTable",
    "ConnectionLimit",
    "Controller",
    "DriveView",
    "Endpoint",
    "Flag",
    "Gateway",
    "GatewayConfig",
    "GatewayConfigError",
    "GatewayDrive",
    "GatewayLine",
    "GatewayStartError",
    "GatewayView",
    "Heartbeat",
    "KeyedBudget",
    "LapseAction",
    "Lease",
    "LineConfig",
    "LineHealth",
    "LineTraffic",
    "LineView",
    "Listener",
    "ListenerLimits",
    "Northbound",
    "NorthboundSpec",
    "ParameterValue",
    "ParameterWrite",
    "PasswordChecks",
    "PollRead",
    "Quality",
    "RateLimitedLog",
    "Refusal",
    "RunCommand",
    "SectionContext",
    "ServedDrive",
    "ServedLine",
    "ServedValues",
    "ServiceManager",
    "SetFrequency",
    "Slot",
    "Trend",
    "UnitScope",
    "User",
    "WriteGrant",
    "WriteRequest",
    "WriteResult",
    "busy_seconds",
    "check_config",
    "compact_json",
    "config_from_flags",
    "cumulative_buckets",
    "default_gateway_id",
    "drive_view",
    "excerpt",
    "gateway_metrics",
    "get_northbound",
    "hash_password",
    "line_problems",
    "listener_families",
    "load_config",
    "named_entries",
    "needs_lease",
    "northbound_extra",
    "northbound_names",
    "parameter_request",
    "parse_config",
    "parse_endpoint",
    "parse_password_hash",
    "parse_users",
    "register_northbound",
    "trend_capacity",
    "unknown_choice",
    "unregister_northbound",
    "valid_name",
    "verify_password",
]
