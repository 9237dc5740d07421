"""The public names: every package's ``__all__`` pinned exactly, with the reference's values.

The root package exports the user's API only (open a bus, get its drives,
poll them, handle the typed errors); the codec's names live in
:mod:`sj300_async.sj300`, the neutral ones in :mod:`sj300_async.wire` and
:mod:`sj300_async.bus`, the simulated drives in :mod:`sj300_async.simulator`.
Adding or removing a public name is a decision: it changes a pin here.
(The FR-700 packages are pinned by tests/fr700/test_fr700_public_api.py.)
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import inspect
import pickle
from types import ModuleType
from typing import cast

import pytest

import sj300_async
import sj300_async.sj300 as sj300
from sj300_async import (
    BusClosedError,
    InputTerminal,
    LocalProtocolError,
    NakCode,
    NakError,
    ProtocolError,
    ReadOnlyError,
    RemoteProtocolError,
    ReplyTimeoutError,
    SJ300Error,
    TransportError,
)
from sj300_async.sj300 import BROADCAST, Command

#: The root's ``__all__``: the user's API, and nothing else.
ROOT_NAMES = (
    "Broadcast", "Bus", "BusClosedError", "BusPollStats", "BusStats", "BusTiming", "Direction",
    "Drive", "DriveHealth", "Fr700Drive", "Fr700Monitor", "Fr700Status", "InputMonitor",
    "InputTerminal", "InverterStatus", "LineSettings", "LocalProtocolError", "MonitorData",
    "NakCode", "NakError", "OutputTerminal", "Poller", "ProtocolError", "ReadOnlyError",
    "ReconnectPolicy", "RemoteProtocolError", "ReplyTimeoutError", "SJ300Error", "Sample",
    "StatusA", "StatusB", "StatusC", "TransportError", "TripHistory", "TripRecord",
    "TripStatusB", "TripStatusC", "__version__", "open_bus",
)  # fmt: skip
#: The user's API stays small enough to read in one go.
MAX_ROOT_NAMES = 40

SJ300_NAMES = (
    "ASSIGNED_INPUT_BITS", "BROADCAST", "COMMAND_SPECS", "MAX_NODE", "MIN_NODE",
    "MUTATING_COMMANDS",
    "NAK_FOR_BAD_REQUEST", "PARAMETERS", "SJ300_DIALECT", "AckDataReply", "AckReply",
    "Broadcast", "Command", "CommandSpec", "DataReply", "Drive", "InputMonitor", "InputTerminal",
    "InverterStatus", "MonitorData", "NakCode", "NakReply", "OutputTerminal", "ParameterInfo",
    "ParserEvent", "Reply", "ReplyKind", "ReplyParser", "Request", "RequestData", "RequestParser",
    "SJ300Dialect", "StatusA", "StatusB", "StatusC", "TripCode", "TripHistory", "TripRecord",
    "TripStatusB", "TripStatusC", "answers", "bcc", "decode_can_store", "decode_monitor",
    "decode_parameter_value", "decode_status", "decode_trip_history", "encode_monitor",
    "encode_reply", "encode_request", "encode_status", "encode_trip_history",
    "motor_capacity_kw", "normalize_code", "parameter_info", "requests",
)  # fmt: skip
#: The package's names that load the async stack: not in its sans-IO face, ``sj300.codec``.
SJ300_ASYNC_NAMES = ("Broadcast", "Drive", "MUTATING_COMMANDS", "SJ300Dialect", "SJ300_DIALECT")
SJ300_CODEC_NAMES = tuple(n for n in SJ300_NAMES if n not in SJ300_ASYNC_NAMES)
WIRE_NAMES = (
    "BadFrame", "BadFrameReason", "BusClosedError", "Direction", "DiscardReason", "Discarded",
    "LineSettings", "LocalProtocolError", "NakError", "ParserStats", "ProtocolError",
    "ReadOnlyError", "RemoteProtocolError", "ReplyTimeoutError", "SJ300Error",
    "TolerantIntEnum", "TransportError",
    # the whole line's frames, captures (pcapng) and the decoders' speed tricks
    "FrameRole", "LineFrame", "INSTANT_LINE", "CaptureFormatError", "CapturedPacket",
    "FLAG_CHECK_ERROR", "FLAG_NOISE", "PacketDirection", "PcapngCapture", "PcapngInterface",
    "PcapngWriter", "read_pcapng", "slot_setters", "unfrozen_twin",
)  # fmt: skip
BUS_NAMES = (
    "DEFAULT_PROTOCOL", "Bus", "BusAddress", "BusStats", "BusTiming", "Channel", "Dialect",
    "LineParser", "LineRequest", "ReconnectPolicy", "SimulatorFactory", "StatsSnapshot",
    "TraceHook", "TraceRecord", "TransactionStats", "format_node_list", "get_dialect",
    "make_dialect", "open_bus", "parse_bus_url", "parse_flag", "parse_node_list",
    "protocol_names", "register_protocol", "unregister_protocol",
    # a task's cap on its calls' retries (the poller's)
    "cap_retries", "retries_at_most",
    # open_bus's keyword arguments, the URL's protocol, the URL schemes' registry (sim://)
    "BusOptions", "url_protocol", "SchemeConnection", "SchemeConnector", "load_object",
    # the latency histogram's bucket bounds (the gateway's metrics)
    "LATENCY_BUCKETS_S",
    # captures and the passive sniffer
    "CaptureFile", "LineFramer", "Anomaly", "LineSniffer", "SniffedFrame", "Sniffing",
    "Unanswered", "sniff",
    # several trace hooks on one bus (a capture and the caller's own)
    "combine",
    # a bus's recorder: its recent chunks, without a trace record each (the workbench's)
    "ChunkLog", "Kept",
)  # fmt: skip
SIMULATOR_NAMES = (
    "BusModel", "Faults", "LineCounters", "LinePacing", "PacedLine", "PlausibleLine",
    "PtyServer", "RunState", "SerialDeviceServer", "SimulatorEndpoint", "SimulatorServer",
    "Transmission",
    "open_pty_server", "precise_event_loop", "serve_serial_device", "serve_tcp",
    # the listen-only tap (sj300 simulate --tap); a protocol's part of sj300 simulate
    "TapServer", "serve_tap", "SimulateCommandLine", "SimulateOption", "SimulateSettings",
)  # fmt: skip
SIMULATOR_SJ300_NAMES = (
    "DEFAULT_EEPROM_WRITE_S", "DEFAULT_PROCESSING_S", "Country", "SimulatedBus",
    "SimulatedDrive", "SimulatorStats", "TripCode", "simulate", "COMMAND_LINE",
)  # fmt: skip
#: The neutral drive model and the profile interface.
PROFILES_NAMES = (
    "Capabilities", "DriveReadings", "DriveSnapshot", "MonitorView", "NEVER",
    "ParameterCatalogue", "ParameterReading", "ParameterSpec", "PollResult", "Profile",
    "ReadGroup", "RegisterField", "RegisterLayout", "StatusView", "Trip", "TripLog",
    "build_snapshot", "frame_text", "get_profile", "in_counts", "is_fresh", "profiled_protocols",
    "raw_value", "read_time", "words",
    # the parameter backup file (sj300 params, the workbench)
    "BACKUP_FORMAT", "BACKUP_VERSION", "BackupFormatError", "ParameterBackup", "catalogued",
    "parameter_code", "utc_now",
)  # fmt: skip
#: The gateway's core, and each built-in northbound's face.
GATEWAY_NAMES = (
    "AuditLog", "COMMAND_LINE", "ConfigContext", "ConfigTable", "Controller", "DEFAULT_LEASE_S",
    "DEFAULT_STALE_AFTER_S", "DriveView", "Endpoint", "Flag", "Gateway", "GatewayConfig",
    "GatewayConfigError", "GatewayDrive", "GatewayLine", "GatewayView", "Heartbeat",
    # the doors' shared defences (issue 41)
    "KeyedBudget", "PasswordChecks", "Slot",
    # a drive as served, decided once for every northbound (issue 42)
    "DIRECTION_WORDS", "Quality", "ServedDrive", "ServedValues",
    # each drive's trend, the core's since the trip recorder reads it too (issue 45)
    "TREND_BLOCK", "TREND_SAMPLE_BYTES", "TREND_VALUES", "Trend", "trend_capacity",
    # what a northbound sees of a line: never its bus (issue 42)
    "LineTraffic", "ServedLine",
    # the doors' shared write checks, the core's since Sparkplug rides no other door (issue 42)
    "DROPPED_BY_STOP", "parameter_request", "needs_lease",
    # a northbound that cannot start (its port in use...)
    "GatewayStartError",
    "LAPSE_ACTIONS", "POLL_READS", "LapseAction", "Lease", "LineConfig", "LineHealth", "LineView",
    "Northbound",
    "NorthboundSpec", "ParameterValue", "ParameterWrite", "PollRead", "Refusal", "RunCommand",
    "SectionContext",
    "SetFrequency",
    # the listeners' limits (Modbus and HTTP): issue 26
    "ConnectionLimit", "LIMIT_KEYS", "Listener", "ListenerLimits", "RateLimitedLog",
    "listener_families",
    "UNIT_RANGE", "WriteGrant", "WriteRequest", "WriteResult", "busy_seconds",
    "config_from_flags", "cumulative_buckets", "default_gateway_id", "drive_view", "excerpt",
    "gateway_metrics", "get_northbound", "line_problems", "load_config", "northbound_names",
    "parse_config", "parse_endpoint", "register_northbound", "unregister_northbound",
    "valid_name",
    # who may write, shared by the HTTP and OPC UA northbounds (issue 29)
    "User", "hash_password", "named_entries", "parse_password_hash", "parse_users",
    "verify_password",
    # the JSON a northbound encodes its samples with (issue 30)
    "compact_json",
    # a northbound's own section checks and extra (issue 29)
    "unknown_choice", "northbound_extra",
    # where unit ids are held: a Modbus listener each (issue 30)
    "UnitScope",
    # --check-config, and the service manager's notifications (issue 46)
    "ConfigCheck", "check_config", "ServiceManager",
)  # fmt: skip
GATEWAY_MODBUS_NAMES = (
    "ClientCounters", "DEFAULT_LIMITS", "Exc", "Field", "MAX_CLIENTS", "ModbusConfig",
    "ModbusListener",
    "NORTHBOUND", "OTHER_CLIENT", "REFUSAL_CODES", "RegisterMap", "client_families", "describe",
    "parameter_address",
    # unit 255: a listener's drives side by side, for a SCADA reading a plant (issue 30)
    "SUMMARY_RECORD", "SUMMARY_SLOTS", "SUMMARY_UNIT", "Summary", "SummaryBits", "SummaryField",
)  # fmt: skip
GATEWAY_MQTT_NAMES = (
    "AVAILABLE", "BridgeStats", "BrokerUnreachable", "COMMANDS", "COMMAND_DIRECTIONS",
    "DEFAULT_PREFIX", "DISCOVERY_PREFIX", "FLEET_SCHEMES", "Fleet", "FleetUrl", "Malformed",
    "MqttConfig", "NORTHBOUND", "StateMessage", "SubscriptionRefused", "Topics",
    "UNAVAILABLE", "discovery", "error_text", "follow",
    "is_fleet_url", "mqtt_families", "node_id", "parse_command",
    "parse_fleet_url", "parse_state_topic", "state_message",
    # Sparkplug B's deprecated keys, which [mqtt] takes for one release (issue 42)
    "SPARKPLUG_ALIAS_KEYS",
    # what a gateway id left retained, cleared (issue 43: sj300 gateway --decommission)
    "SweepRefused", "Swept", "sweep",
)  # fmt: skip
#: The MQTT transport both MQTT northbounds ride (issue 42): it knows neither.
GATEWAY_MQTTLINK_NAMES = (
    "BACKOFF_FIRST_S", "BROKER_KEYS", "REFUSED", "BrokerConfig", "BrokerUnreachable",
    "SessionStats", "Subscriptions", "backoff", "broker_fields", "cancel_and_wait",
    "keep_connected", "new_client", "parse_broker", "reader", "refused_subscriptions",
)  # fmt: skip
GATEWAY_SPARKPLUG_NAMES = (
    "BAD_INPUTS", "CLIENT", "DATA_TYPES", "DIRECTION_WORDS", "LAST_REFUSAL", "NAMESPACE",
    "NODE_METRICS", "Decoded", "Device", "DeviceMetric", "EdgeNode", "MalformedPayload",
    "MetricDef", "Property", "ReceivedMetric", "SparkplugStats", "decode_payload", "device_id",
    "encode_payload",
    # its own section (issue 42): the spec, its keys and settings; the flags a metric reads
    "NORTHBOUND", "SPARKPLUG_KEYS", "SparkplugConfig", "DeviceFlags",
)  # fmt: skip
GATEWAY_HTTP_NAMES = (
    "DEFAULT_LIMITS", "DEFAULT_TREND_S", "HttpConfig", "NORTHBOUND",
    # who may write through the workbench, and the hashes their configuration holds
    "ApiToken", "User", "hash_password", "hash_token", "new_token",
    # each drive's trend (its memory is a benchmark's figure)
    "BLOCK", "SAMPLE_BYTES", "Trend", "trend_capacity",
)  # fmt: skip
#: The trip black box (issue 45): its settings, its store and its records (a record's
#: CSV made in a child process: CsvFailed, record_csv).
GATEWAY_RECORDER_NAMES = (
    "FORMAT", "RECORDER_KEYS", "RECORD_ID", "CsvFailed", "RecordSummary", "RecorderConfig",
    "TripRecorder", "TripStore", "record_csv", "record_id", "samples_csv", "trip_fields",
)  # fmt: skip
GATEWAY_OPCUA_NAMES = (
    "DEFAULT_SECURITY", "NORTHBOUND", "OPCUA_KEYS", "SECURITY_MODES", "OpcuaConfig",
    "parse_endpoint_url",
)  # fmt: skip

#: Every package's pinned ``__all__``.
PINNED = {
    "sj300_async": ROOT_NAMES,
    "sj300_async.sj300": SJ300_NAMES,
    "sj300_async.sj300.codec": SJ300_CODEC_NAMES,
    "sj300_async.wire": WIRE_NAMES,
    "sj300_async.bus": BUS_NAMES,
    "sj300_async.simulator": SIMULATOR_NAMES,
    "sj300_async.simulator.sj300": SIMULATOR_SJ300_NAMES,
    "sj300_async.profiles": PROFILES_NAMES,
    "sj300_async.gateway": GATEWAY_NAMES,
    "sj300_async.gateway.modbus": GATEWAY_MODBUS_NAMES,
    "sj300_async.gateway.mqtt": GATEWAY_MQTT_NAMES,
    "sj300_async.gateway.sparkplug": GATEWAY_SPARKPLUG_NAMES,
    "sj300_async.gateway.mqttlink": GATEWAY_MQTTLINK_NAMES,
    "sj300_async.gateway.http": GATEWAY_HTTP_NAMES,
    "sj300_async.gateway.recorder": GATEWAY_RECORDER_NAMES,
    "sj300_async.gateway.opcua": GATEWAY_OPCUA_NAMES,
}

CORE_NAMES = {
    # codec
    "encode_request",
    "bcc",
    "BROADCAST",
    "MIN_NODE",
    "MAX_NODE",
    "Command",
    "CommandSpec",
    "COMMAND_SPECS",
    "ReplyKind",
    "RequestData",
    "Request",
    "requests",
    # parsers and events
    "ReplyParser",
    "RequestParser",
    "NAK_FOR_BAD_REQUEST",
    "ParserStats",
    "AckReply",
    "AckDataReply",
    "DataReply",
    "NakReply",
    "Reply",
    "BadFrame",
    "BadFrameReason",
    "Discarded",
    "DiscardReason",
    "ParserEvent",
    "answers",
    # payloads
    "decode_status",
    "decode_monitor",
    "decode_trip_history",
    "decode_parameter_value",
    "decode_can_store",
    "encode_reply",
    "encode_status",
    "encode_monitor",
    "encode_trip_history",
    "InverterStatus",
    "MonitorData",
    "TripHistory",
    "TripRecord",
    # codes and terminals
    "Direction",
    "NakCode",
    "StatusA",
    "StatusB",
    "StatusC",
    "TripStatusB",
    "TripStatusC",
    "InputTerminal",
    "InputMonitor",
    "OutputTerminal",
    # parameters
    "PARAMETERS",
    "ParameterInfo",
    "parameter_info",
    "normalize_code",
    "motor_capacity_kw",
    # errors
    "SJ300Error",
    "ProtocolError",
    "LocalProtocolError",
    "RemoteProtocolError",
    "ReadOnlyError",
    "NakError",
    "ReplyTimeoutError",
    "TransportError",
    "BusClosedError",
}
#: The core names that are protocol-neutral, and so live in :mod:`sj300_async.wire`.
WIRE_CORE_NAMES = {
    "ParserStats",
    "BadFrame",
    "BadFrameReason",
    "Discarded",
    "DiscardReason",
    "Direction",
    "SJ300Error",
    "ProtocolError",
    "LocalProtocolError",
    "RemoteProtocolError",
    "ReadOnlyError",
    "NakError",
    "ReplyTimeoutError",
    "TransportError",
    "BusClosedError",
}

REQUEST_BUILDERS = {
    "encode_request",
    "run",
    "set_frequency",
    "set_terminals",
    "read_monitor",
    "read_status",
    "read_trip_history",
    "read_parameter",
    "write_parameter",
    "write_parameter_raw",
    "initialize",
    "can_store",
    "store",
    "recalculate",
}


def public_names(module: ModuleType) -> list[str]:
    return cast(list[str], vars(module)["__all__"])


def undocumented(module: ModuleType) -> list[str]:
    """The classes, functions and modules in *module*'s ``__all__`` with no docstring of their own.

    A dataclass's generated signature and an enum's default text do not count.
    """
    missing = []
    for name in public_names(module):
        obj = getattr(module, name)
        if inspect.isclass(obj):
            doc = obj.__dict__.get("__doc__")
            if dataclasses.is_dataclass(obj) and doc and doc.startswith(f"{obj.__name__}("):
                doc = None
            if issubclass(obj, enum.Enum) and doc and doc.startswith("An enumeration"):
                doc = None
        elif inspect.isfunction(obj) or inspect.isbuiltin(obj) or inspect.ismodule(obj):
            doc = obj.__doc__
        else:
            continue  # a constant, an alias or an instance: documented where it is defined
        if not (isinstance(doc, str) and doc.strip()):
            missing.append(name)
    return missing


@pytest.mark.parametrize("package", PINNED)
def test_all_is_pinned(package: str) -> None:
    names = public_names(importlib.import_module(package))
    assert len(names) == len(set(names))
    assert sorted(names) == sorted(PINNED[package])


@pytest.mark.parametrize("package", PINNED)
def test_every_pinned_name_is_importable_and_documented(package: str) -> None:
    module = importlib.import_module(package)
    for name in public_names(module):
        assert getattr(module, name) is not None, name
    assert undocumented(module) == []


def test_the_codec_face_is_the_package_without_its_async_names() -> None:
    # sj300.codec is what sans-IO code imports; the package adds the dialect and the drives.
    import sj300_async.sj300.codec as codec

    assert set(sj300.__all__) == set(codec.__all__) | set(SJ300_ASYNC_NAMES)
    for name in codec.__all__:
        assert getattr(sj300, name) is getattr(codec, name), name


def test_the_root_is_the_users_api_only() -> None:
    assert len(sj300_async.__all__) <= MAX_ROOT_NAMES
    assert sj300_async.__all__ == sorted(sj300_async.__all__, key=lambda n: (n[0].islower(), n))
    assert isinstance(sj300_async.__version__, str)


def test_root_names_are_the_subpackages_objects() -> None:
    # A root name re-exports its home package's object; it is never a second definition,
    # except the root's open_bus: the neutral one, typed with each built-in protocol's drives.
    for package in PINNED:
        module = importlib.import_module(package)
        for name in set(public_names(module)) & set(ROOT_NAMES) - {"open_bus"}:
            assert getattr(sj300_async, name) is getattr(module, name), (package, name)
    assert sj300_async.open_bus.__module__ == "sj300_async._open"


def test_the_undocumented_check_can_fail() -> None:
    module = ModuleType("fake")

    @dataclasses.dataclass
    class Plain:
        x: int

    class Code(enum.IntEnum):
        A = 1

    def bare() -> None:
        pass

    vars(module).update(
        Plain=Plain, Code=Code, bare=bare, VALUE=1, __all__=["Plain", "Code", "bare", "VALUE"]
    )
    assert undocumented(module) == ["Plain", "Code", "bare"]


def test_core_names_are_exported() -> None:
    missing = CORE_NAMES - set(sj300.__all__) - set(sj300_async.wire.__all__)
    assert not missing
    assert set(sj300.__all__) >= CORE_NAMES - WIRE_CORE_NAMES
    assert set(sj300_async.wire.__all__) >= WIRE_CORE_NAMES


def test_every_exported_name_exists_once() -> None:
    assert len(sj300_async.__all__) == len(set(sj300_async.__all__))
    for name in sj300_async.__all__:
        assert hasattr(sj300_async, name), name


def test_star_import_gives_the_core_names() -> None:
    namespace: dict[str, object] = {}
    exec("from sj300_async.sj300 import *\nfrom sj300_async.wire import *", namespace)
    assert set(namespace) >= CORE_NAMES


def test_star_import_of_the_root_gives_the_users_api() -> None:
    namespace: dict[str, object] = {}
    exec("from sj300_async import *", namespace)
    assert set(namespace) - {"__builtins__"} == set(ROOT_NAMES)


def test_request_builders() -> None:
    assert set(sj300.requests.__all__) >= REQUEST_BUILDERS
    for name in REQUEST_BUILDERS:
        assert callable(getattr(sj300.requests, name))


def test_broadcast_is_ff() -> None:
    assert BROADCAST == 0xFF
    assert sj300.MIN_NODE == 1
    assert sj300.MAX_NODE == 32


def test_commands() -> None:
    assert {c.name: c.value for c in Command} == {
        "RUN": 0x00,
        "SET_FREQUENCY": 0x01,
        "SET_TERMINALS": 0x02,
        "READ_MONITOR": 0x03,
        "READ_STATUS": 0x04,
        "READ_TRIP_HISTORY": 0x05,
        "READ_PARAMETER": 0x06,
        "WRITE_PARAMETER": 0x07,
        "INITIALIZE": 0x08,
        "CAN_STORE": 0x09,
        "STORE": 0x0A,
        "RECALCULATE": 0x0B,
    }
    assert [c.wire for c in Command] == [b"%02X" % v for v in range(12)]


def test_command_specs_follow_the_command_table() -> None:
    broadcast = {c for c in Command if c.spec.broadcast}
    assert broadcast == {
        Command.RUN,
        Command.SET_FREQUENCY,
        Command.SET_TERMINALS,
        Command.WRITE_PARAMETER,
        Command.INITIALIZE,
        Command.STORE,
    }
    lengths = {c: c.spec.reply_length for c in Command if c.spec.reply_length}
    assert lengths == {
        Command.READ_MONITOR: 104,
        Command.READ_STATUS: 8,
        Command.READ_TRIP_HISTORY: 440,
        Command.READ_PARAMETER: 8,
        Command.CAN_STORE: 2,
    }


#: The reference's command 02 table, verbatim (bit masks as printed).
INPUT_TERMINAL_TABLE = {
    "FW": "0000000000000001",
    "RV": "0000000000000002",
    "CF1": "0000000000000004",
    "CF2": "0000000000000008",
    "CF3": "0000000000000010",
    "CF4": "0000000000000020",
    "JG": "0000000000000040",
    "DB": "0000000000000080",
    "SET": "0000000000000100",
    "TWO_CH": "0000000000000200",  # "2CH" in the manual
    "FRS": "0000000000000800",
    "EXT": "0000000000001000",
    "USP": "0000000000002000",
    "CS": "0000000000004000",
    "SFT": "0000000000008000",
    "AT": "0000000000010000",
    "SET3": "0000000000020000",
    "RS": "0000000000040000",
    "STA": "0000000000100000",
    "STP": "0000000000200000",
    "FR": "0000000000400000",  # "F/R" in the manual
    "PID": "0000000000800000",
    "PIDC": "0000000001000000",
    "CAS": "0000000004000000",
    "UP": "0000000008000000",
    "DWN": "0000000010000000",
    "UDC": "0000000020000000",
    "OPE": "0000000080000000",
    "SF1": "0000000100000000",
    "SF2": "0000000200000000",
    "SF3": "0000000400000000",
    "SF4": "0000000800000000",
    "SF5": "0000001000000000",
    "SF6": "0000002000000000",
    "SF7": "0000004000000000",
    "OLR": "0000008000000000",
    "TL": "0000010000000000",
    "TRQ1": "0000020000000000",
    "TRQ2": "0000040000000000",
    "PPI": "0000080000000000",
    "BOK": "0000100000000000",
    "ORT": "0000200000000000",
    "LAC": "0000400000000000",
    "PCLR": "0000800000000000",
    "STAT": "0001000000000000",
}


def test_input_terminals_follow_the_reference_table() -> None:
    assert {t.name: b"%016X" % t.value for t in InputTerminal} == {
        name: mask.encode() for name, mask in INPUT_TERMINAL_TABLE.items()
    }


def test_input_terminals_leave_the_unassigned_bits_free() -> None:
    used = 0
    for terminal in InputTerminal:
        used |= terminal.value
    for bit in (10, 19, 25, 30, *range(49, 64)):
        assert not used & (1 << bit)


# -- errors ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("error", "bases"),
    [
        (ProtocolError, (SJ300Error,)),
        (LocalProtocolError, (ProtocolError, ValueError)),
        (ReadOnlyError, (LocalProtocolError,)),
        (RemoteProtocolError, (ProtocolError,)),
        (NakError, (SJ300Error,)),
        (ReplyTimeoutError, (SJ300Error, TimeoutError)),
        (TransportError, (SJ300Error, ConnectionError)),
        (BusClosedError, (TransportError,)),
    ],
)
def test_error_hierarchy(error: type[Exception], bases: tuple[type[Exception], ...]) -> None:
    for base in (*bases, SJ300Error, Exception):
        assert issubclass(error, base)


def test_remote_protocol_error_is_not_a_value_error() -> None:
    # the line's garbage is not the caller's mistake
    assert not issubclass(RemoteProtocolError, ValueError)


def test_nak_error_carries_node_and_code() -> None:
    error = NakError(5, NakCode.ABNORMAL_PARAMETER)
    assert error.node == 5
    assert error.code is NakCode.ABNORMAL_PARAMETER
    assert "16" in str(error)
    assert "05" in str(error)


def test_nak_error_with_unknown_code() -> None:
    error = NakError(1, NakCode(42))
    assert error.code == 42
    assert "42" in str(error)


def test_nak_error_pickles() -> None:
    error = pickle.loads(pickle.dumps(NakError(3, NakCode.CHECKSUM)))
    assert (error.node, error.code) == (3, NakCode.CHECKSUM)
