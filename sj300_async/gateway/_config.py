"""The gateway's configuration: a TOML file (or the command line's flags) → :class:`GatewayConfig`.

Everything is checked here, before the gateway opens a line or a port, and
a refusal is a :class:`GatewayConfigError` whose one-line message says
where (file, line, dotted key) and why, the way a compiler reports::

    gateway.toml:12: lines[1].nodes: node 40 is outside 1..32

Decisions:

- The first error found stops the load: one precise message beats a list
  whose later entries are often consequences of the first.
- A table's unknown keys are checked before its values, so a misspelt key
  is reported as itself (with a did-you-mean), not as the required key it
  was meant to be.
- tomllib gives no positions, so :func:`_key_lines` scans the raw text for
  table headers and ``key =`` lines. It only places errors: its limits
  (documented there) can cost a line number, never change a verdict.
- The command line's simple case goes through the same rules, as a
  one-line configuration whose keys are renamed to the flags
  (``lines[0].nodes`` → ``--nodes``): one set of rules, one set of messages.
- Nodes, parameter codes and broadcast support come from the line's
  dialect (:mod:`sj300_async.bus._registry`), so FR-700 stations 0..31 and
  ``Pr.7`` are checked as such.
- A relative ``audit_log`` is relative to the configuration file's
  directory, so the gateway can be started from anywhere.
- Writes are confirmed against the poll cache, so a write grant may only
  name parameters the line polls; Modbus unit ids must be unique across
  all lines, since one Modbus server serves them all.
- The gateway id and the line names are MQTT topic levels
  (:func:`._mqtt_topics.valid_name`), whether or not ``[mqtt]`` is
  configured: adding a broker later never means renaming a line. The
  ``[mqtt]`` URL is ``mqtt://HOST[:PORT]`` or ``mqtts://``; credentials have
  their own keys (a URL ends up in logs). A ``tls_ca`` must exist now: a
  missing file found at connect time would be a retry loop, not an error.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import re
import tomllib
import urllib.parse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import date, datetime, time
from pathlib import Path
from typing import Final, TypeVar

from ..bus._registry import DEFAULT_PROTOCOL, AnyDialect, get_dialect, protocol_names
from ..bus._url import BusAddress, format_node_list, parse_bus_url, parse_node_list
from ..wire import LocalProtocolError
from ._model import (
    DEFAULT_STALE_AFTER_S,
    LAPSE_ACTIONS,
    UNIT_RANGE,
    Endpoint,
    GatewayConfig,
    LapseAction,
    LineConfig,
    MqttConfig,
    WriteGrant,
    default_gateway_id,
    default_unit_offset,
)
from ._mqtt_topics import DEFAULT_PREFIX, DISCOVERY_PREFIX, valid_name

__all__ = [
    "GatewayConfigError",
    "config_from_flags",
    "load_config",
    "parse_config",
    "parse_endpoint",
]

T = TypeVar("T")

#: The source of a configuration built by :func:`config_from_flags`.
COMMAND_LINE: Final = "<command line>"
#: The flag each key of the command line's one-line configuration comes from.
_FLAGS: Final = {
    "lines[0].url": "--url",
    "lines[0].nodes": "--nodes",
    "lines[0].protocol": "--protocol",
    "lines[0].interval_s": "--interval",
    "modbus.listen": "--modbus",
    "metrics.listen": "--metrics",
    "gateway.stale_after_s": "--stale-after",
    "gateway.id": "--id",
    "mqtt.url": "--mqtt",
}

_ROOT_KEYS: Final = ("gateway", "modbus", "metrics", "mqtt", "lines")
_GATEWAY_KEYS: Final = ("id", "stale_after_s", "audit_log")
_MQTT_KEYS: Final = (
    *("url", "client_id", "username", "password", "tls_ca", "prefix", "qos"),
    *("discovery", "discovery_prefix", "keepalive_s"),
)
_MQTT_PORTS: Final = {"mqtt": 1883, "mqtts": 8883}
_DEFAULT_MQTT: Final = MqttConfig(host="localhost", port=1883)
_LINE_KEYS: Final = (
    *("name", "url", "protocol", "nodes", "interval_s", "reads", "parameters"),
    *("trips_interval_s", "unit_offset", "timeout_s", "lease_s", "on_lapse", "writes"),
)
_GRANT_KEYS: Final = ("nodes", "parameters", "control")
_READS: Final = ("status", "monitor")
_LAPSE: Final[dict[str, LapseAction]] = {action: action for action in LAPSE_ACTIONS}
#: Protocols with a broadcast stop (FR-700's computer link has no broadcast).
_BROADCAST_STOP: Final = frozenset({"sj300"})
#: The shortest poll interval: a floor against a typo (milliseconds written
#: as seconds) that would leave the line no time for anything but polls.
_MIN_INTERVAL_S: Final = 0.05
_BARE_KEY: Final = re.compile(r"[A-Za-z0-9_-]+\Z")
_HOST: Final = re.compile(r"[A-Za-z0-9_.%:-]+\Z")
_WILDCARD_HOSTS: Final = frozenset({"0.0.0.0", "::"})
_TOML_POSITION: Final = re.compile(r"\s*\((?:at line (\d+), column (\d+)|at end of document)\)\Z")
#: The defaults of a line, read from the model rather than repeated here.
_DEFAULT_LINE: Final = LineConfig(name="line1", url="sim://", protocol="sj300", nodes=(1,))


class GatewayConfigError(LocalProtocolError):
    """A configuration the gateway refuses: where (file, line, key) and why.

    ``str()`` is one line, ``SOURCE[:LINE]: [KEY: ]REASON``, the form editors
    and CI logs recognise.
    """

    def __init__(self, source: str, line: int | None, key: str | None, reason: str) -> None:
        # All four in args: the error pickles and reprs as it was built.
        super().__init__(source, line, key, reason)
        #: The file name as given, or ``"<command line>"``.
        self.source = source
        #: 1-based line in the file (None: unknown, or not from a file).
        self.line = line
        #: The dotted key, e.g. ``lines[1].writes[0].nodes``, or the flag.
        self.key = key
        self.reason = reason

    def __str__(self) -> str:
        where = self.source if self.line is None else f"{self.source}:{self.line}"
        return f"{where}: {self.key}: {self.reason}" if self.key else f"{where}: {self.reason}"


# -- public entry points --------------------------------------------------------------------


def load_config(path: str | os.PathLike[str]) -> GatewayConfig:
    """Read and validate the gateway's TOML configuration file *path*.

    Raises:
        GatewayConfigError: the file cannot be read, is not TOML, or is not a
            valid configuration; the message names the file, line and key.
    """
    source = os.fspath(path)
    try:
        raw = Path(source).read_bytes()
    except OSError as exc:
        raise GatewayConfigError(source, None, None, exc.strerror or str(exc)) from None
    try:
        text = raw.decode("utf-8-sig")  # tolerate the BOM some Windows editors write
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise GatewayConfigError(source, line, None, f"not UTF-8 text: {exc.reason}") from None
    return parse_config(text, source)


def parse_config(text: str, source: str) -> GatewayConfig:
    """Validate the TOML configuration *text*; *source* names it in errors.

    A relative ``audit_log`` is taken relative to *source*'s directory.

    Raises:
        GatewayConfigError: see :func:`load_config`.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _syntax_error(source, text, exc) from None
    return _build(_Context(source, text), data, base_dir=Path(source).parent)


def config_from_flags(
    *,
    url: str,
    nodes: str,
    protocol: str | None,
    modbus: str | None,
    metrics: str | None,
    stale_after_s: float = DEFAULT_STALE_AFTER_S,
    interval_s: float = 0.5,
    mqtt: str | None = None,
    gateway_id: str | None = None,
) -> GatewayConfig:
    """The command line's simple case: one read-only line, checked like a file.

    Raises:
        GatewayConfigError: source ``"<command line>"``, key the flag at fault.
    """
    line: dict[str, object] = {"url": url, "nodes": nodes, "interval_s": interval_s}
    if protocol is not None:
        line["protocol"] = protocol
    gateway: dict[str, object] = {"stale_after_s": stale_after_s}
    if gateway_id is not None:
        gateway["id"] = gateway_id
    data: dict[str, object] = {"gateway": gateway, "lines": [line]}
    if mqtt is not None:
        data["mqtt"] = {"url": mqtt}
    if modbus is not None:
        data["modbus"] = {"listen": modbus}
    if metrics is not None:
        data["metrics"] = {"listen": metrics}
    return _build(_Context(COMMAND_LINE, rename=_FLAGS), data, base_dir=Path())


def parse_endpoint(text: str) -> Endpoint:
    """Parse a listening address: ``"HOST:PORT"``, ``"[::1]:502"`` or ``":502"`` (every interface).

    Port 0 asks the system for a free port.

    Raises:
        LocalProtocolError: not one of those forms, or a port outside 0..65535.
    """
    value = text.strip()
    if value.startswith("["):
        host, bracket, port = value[1:].partition("]:")
        if not bracket:
            raise LocalProtocolError(f"expected [IPV6]:PORT, got {text!r}")
    else:
        host, colon, port = value.rpartition(":")
        if not colon:
            raise LocalProtocolError(f"expected HOST:PORT, got {text!r}")
        if ":" in host:
            raise LocalProtocolError(f"put an IPv6 address in brackets: [{host}]:{port}")
        host = host or "0.0.0.0"
    if not _HOST.match(host):
        raise LocalProtocolError(f"bad host {host!r} in {text!r}")
    if not (port.isascii() and port.isdigit() and int(port) <= 65535):
        raise LocalProtocolError(f"port must be 0..65535, got {port!r}")
    return Endpoint(host, int(port))


# -- where errors are ----------------------------------------------------------------------


class _Context:
    """Where the values come from: turns a key and a reason into a :class:`GatewayConfigError`."""

    def __init__(self, source: str, text: str = "", rename: Mapping[str, str] | None = None):
        self.source = source
        self._text = text
        self._rename = rename or {}
        self._lines: dict[str, int] | None = None

    def error(self, key: str, reason: str) -> GatewayConfigError:
        if self._lines is None:  # scanned on the first error only
            self._lines = _key_lines(self._text)
        return GatewayConfigError(
            self.source, _line_of(self._lines, key), self._rename.get(key, key) or None, reason
        )


def _syntax_error(source: str, text: str, exc: tomllib.TOMLDecodeError) -> GatewayConfigError:
    """tomllib's message, with its ``(at line N, column M)`` moved to where our format puts it."""
    message = str(exc)
    found = _TOML_POSITION.search(message)
    if found is None:
        return GatewayConfigError(source, None, None, f"invalid TOML: {message}")
    if found[1] is None:  # "at end of document": the last line
        line, where = text.count("\n") + 1, "at end of file"
    else:
        line, where = int(found[1]), f"column {found[2]}"
    return GatewayConfigError(
        source, line, None, f"invalid TOML: {message[: found.start()]} ({where})"
    )


# The locator. It reads the text line by line, tracking the current table:
# ``[name]`` and ``[[name]]`` headers (an array of tables counts its elements,
# per parent, so the second ``[[lines.writes]]`` under the second ``[[lines]]``
# is ``lines[1].writes[1]``) and ``key = value`` lines, skipping the
# continuation lines of a value whose brackets or braces are still open.
# Limits, all costing only precision (an error then points at the enclosing
# table, or at the first line of the value):
# - the lines inside a multi-line string are read like any others;
# - a quoted key containing "." or "=", or a header containing "]", is misread;
# - keys inside an inline table or an array of inline tables are not
#   located: their errors point at the line of the key holding the value.
_HEADER: Final = re.compile(r"\s*(\[\[?)\s*([^\[\]]+?)\s*\]\]?\s*(?:#.*)?\Z")
_KEY: Final = re.compile(r"\s*([A-Za-z0-9_\-. \"']+?)\s*=")
_STRING: Final = re.compile(r"\"(?:[^\"\\]|\\.)*\"|'[^']*'")
_LAST_PART: Final = re.compile(r"[.\[][^.\[]*\Z")


def _key_lines(text: str) -> dict[str, int]:
    """Map each key path (``lines[1].writes[0].nodes``) and table to the line that writes it."""
    found: dict[str, int] = {}
    counts: dict[str, int] = {}  # array-of-tables path → elements so far
    table = ""
    depth = 0  # brackets and braces still open in a value spanning lines
    for number, raw in enumerate(text.split("\n"), start=1):  # tomllib counts "\n" only
        if depth > 0:
            depth += _balance(raw)
        elif header := _HEADER.match(raw):
            table = _table_path(header[2], counts, is_array=header[1] == "[[")
            found.setdefault(table, number)
        elif key := _KEY.match(raw):
            path = table
            for part in _dotted(key[1]):
                path = _join(path, part)
            found.setdefault(path, number)
            depth = _balance(raw[key.end() :])
    return found


def _table_path(name: str, counts: dict[str, int], *, is_array: bool) -> str:
    """The key path of a table header; an array's parent is its last element so far."""
    path = ""
    *parents, last = _dotted(name)
    for part in parents:
        path = _join(path, part)
        if path in counts:
            path = f"{path}[{counts[path] - 1}]"
    path = _join(path, last)
    if is_array:
        counts[path] = counts.get(path, 0) + 1
        path = f"{path}[{counts[path] - 1}]"
    return path


def _dotted(name: str) -> list[str]:
    return [part.strip().strip("\"'") for part in name.split(".")]


def _balance(code: str) -> int:
    """Brackets and braces opened minus closed, outside strings and comments."""
    code = _STRING.sub("", code).partition("#")[0]
    return code.count("[") + code.count("{") - code.count("]") - code.count("}")


def _line_of(lines: Mapping[str, int], key: str) -> int | None:
    """The line of *key*, else of its nearest enclosing table that has one."""
    while key not in lines:
        parent = _LAST_PART.sub("", key)
        if parent == key:  # a top-level key that is not written anywhere
            return None
        key = parent
    return lines[key]


def _join(path: str, name: str) -> str:
    """``lines[0]`` + ``url`` → ``lines[0].url``; a name that is not a bare key is quoted."""
    part = name if _BARE_KEY.match(name) else json.dumps(name)
    return f"{path}.{part}" if path else part


# -- typed reading of one table --------------------------------------------------------------


def _type_name(value: object) -> str:
    """The TOML name of *value*'s type, for "expected a number, got string"."""
    for kind, name in (
        (bool, "boolean"),  # before int: a bool is an int to Python, never to TOML
        (int, "integer"),
        (float, "float"),
        (str, "string"),
        (list, "array"),
        (dict, "table"),
        (datetime, "date-time"),  # before date, its base class
        (date, "date"),
        (time, "time"),
    ):
        if isinstance(value, kind):
            return name
    return type(value).__name__


def _unknown(kind: str, value: str, choices: Sequence[str]) -> str:
    """``unknown key 'listn' (did you mean 'listen'?)``, else the choices."""
    close = difflib.get_close_matches(value, choices, n=1)
    hint = f"did you mean {close[0]!r}?" if close else f"use {', '.join(choices)}"
    return f"unknown {kind} {value!r} ({hint})"


def _or(value: T | None, default: T) -> T:
    return default if value is None else value


class _Table:
    """One table being validated: typed getters whose errors name the key; no unknown keys."""

    def __init__(self, ctx: _Context, path: str, data: object, allowed: Sequence[str]) -> None:
        self.ctx = ctx
        self.path = path
        if not isinstance(data, dict):
            raise ctx.error(path, f"expected a table, got {_type_name(data)}")
        self.data: dict[str, object] = data
        for name in data:
            if name not in allowed:
                raise self.error(name, _unknown("key", name, allowed))

    def error(self, name: str, reason: str) -> GatewayConfigError:
        return self.ctx.error(_join(self.path, name) if name else self.path, reason)

    def has(self, name: str) -> bool:
        return name in self.data

    def required(self, name: str) -> object:
        if name not in self.data:
            raise self.error(name, f"missing required key {name!r}")
        return self.data[name]

    def string(self, name: str) -> str | None:
        value = self.data.get(name)  # TOML has no null: None means absent
        if value is None or isinstance(value, str):
            return value
        raise self.error(name, f"expected a string, got {_type_name(value)}")

    def required_string(self, name: str) -> str:
        self.required(name)
        return _or(self.string(name), "")

    def boolean(self, name: str) -> bool | None:
        value = self.data.get(name)
        if value is None or isinstance(value, bool):
            return value
        raise self.error(name, f"expected true or false, got {_type_name(value)}")

    def integer(self, name: str) -> int | None:
        value = self.data.get(name)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, f"expected an integer, got {_type_name(value)}")
        return value

    def number(self, name: str, *, minimum: float, inclusive: bool) -> float | None:
        """A finite int or float >= *minimum* (> when not *inclusive*); None when absent."""
        value = self.data.get(name)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(name, f"expected a number, got {_type_name(value)}")
        try:
            number = float(value)
        except OverflowError:  # TOML integers are unbounded to tomllib
            number = math.inf
        if not math.isfinite(number):
            raise self.error(name, f"expected a finite number, got {value}")
        if number < minimum or (number == minimum and not inclusive):
            bound = ">=" if inclusive else ">"
            raise self.error(name, f"must be {bound} {minimum:g}, got {number:g}")
        return number

    def strings(self, name: str) -> tuple[str, ...] | None:
        value = self.data.get(name)
        if value is None:
            return None
        if not isinstance(value, list):
            raise self.error(name, f"expected an array of strings, got {_type_name(value)}")
        for item in value:
            if not isinstance(item, str):
                raise self.error(
                    name, f"expected an array of strings, got {_type_name(item)} {item!r} in it"
                )
        return tuple(value)

    def tables(self, name: str, header: str) -> list[object]:
        """An array of tables (``[[header]]``); empty when absent."""
        value = self.data.get(name, [])
        if not isinstance(value, list):
            raise self.error(
                name, f"expected an array of tables ([[{header}]]), got {_type_name(value)}"
            )
        return value


# -- the whole configuration -----------------------------------------------------------------


def _build(ctx: _Context, data: object, *, base_dir: Path) -> GatewayConfig:
    root = _Table(ctx, "", data, _ROOT_KEYS)
    gateway = _Table(ctx, "gateway", root.data.get("gateway", {}), _GATEWAY_KEYS)
    stale_after_s = gateway.number("stale_after_s", minimum=0, inclusive=False)
    audit_log = _audit_log(gateway, base_dir)
    modbus = _listen(ctx, root, "modbus")
    metrics = _listen(ctx, root, "metrics")
    if modbus and metrics and _same_socket(modbus, metrics):
        raise ctx.error("metrics.listen", f"the Modbus server already listens on {modbus}")
    gateway_id = _gateway_id(gateway)
    mqtt = _mqtt(ctx, root, gateway_id, base_dir)
    return GatewayConfig(
        lines=_lines(ctx, root),
        modbus=modbus,
        metrics=metrics,
        stale_after_s=_or(stale_after_s, DEFAULT_STALE_AFTER_S),
        audit_log=audit_log,
        source=ctx.source,
        mqtt=mqtt,
        gateway_id=gateway_id,
    )


def _audit_log(gateway: _Table, base_dir: Path) -> Path | None:
    text = gateway.string("audit_log")
    if text is None:
        return None
    if not text.strip():
        raise gateway.error("audit_log", "expected a file name, got an empty string")
    return base_dir / text  # an absolute path stays as it is


def _listen(ctx: _Context, root: _Table, section: str) -> Endpoint | None:
    """``[modbus]`` / ``[metrics]``: absent means not served."""
    if not root.has(section):
        return None
    table = _Table(ctx, section, root.data[section], ("listen",))
    text = table.required_string("listen")
    try:
        return parse_endpoint(text)
    except LocalProtocolError as exc:
        raise table.error("listen", str(exc)) from None


def _gateway_id(gateway: _Table) -> str:
    name = gateway.string("id")
    if name is None:
        return default_gateway_id()
    if not valid_name(name):
        raise gateway.error(
            "id", f"a gateway id is letters, digits, '_', '.' and '-', got {name!r}"
        )
    return name


def _mqtt(ctx: _Context, root: _Table, gateway_id: str, base_dir: Path) -> MqttConfig | None:
    """``[mqtt]``: absent means no MQTT."""
    if not root.has("mqtt"):
        return None
    table = _Table(ctx, "mqtt", root.data["mqtt"], _MQTT_KEYS)
    host, port, tls = _mqtt_url(table)
    client_id = table.string("client_id")
    if client_id is not None and not client_id.strip():
        raise table.error("client_id", "expected a client id, got an empty string")
    username, password = table.string("username"), table.string("password")
    if password is not None and username is None:
        raise table.error("password", "a password needs a username")
    tls_ca = None
    if (ca := table.string("tls_ca")) is not None:
        tls_ca = base_dir / ca
        if not ca.strip() or not tls_ca.is_file():
            raise table.error("tls_ca", f"no such file: {str(tls_ca)!r}")
    qos = table.integer("qos")
    if qos is not None and qos not in (0, 1):
        raise table.error("qos", f"must be 0 or 1, got {qos}")
    keepalive_s = table.integer("keepalive_s")
    if keepalive_s is not None and not 1 <= keepalive_s <= 65535:
        raise table.error("keepalive_s", f"must be 1..65535 seconds, got {keepalive_s}")
    tls = tls or tls_ca is not None  # a CA to verify the broker with means TLS
    return MqttConfig(
        host=host,
        port=_or(port, _MQTT_PORTS["mqtts" if tls else "mqtt"]),
        tls=tls,
        client_id=_or(client_id, f"sj300-{gateway_id}"),
        username=username,
        password=password,
        tls_ca=tls_ca,
        prefix=_topic_prefix(table, "prefix", DEFAULT_PREFIX),
        qos=_or(qos, _DEFAULT_MQTT.qos),
        discovery=_or(table.boolean("discovery"), _DEFAULT_MQTT.discovery),
        discovery_prefix=_topic_prefix(table, "discovery_prefix", DISCOVERY_PREFIX),
        keepalive_s=_or(keepalive_s, _DEFAULT_MQTT.keepalive_s),
    )


def _mqtt_url(table: _Table) -> tuple[str, int | None, bool]:
    """``mqtt://HOST[:PORT]`` or ``mqtts://``: (host, port or None, TLS)."""
    text = table.required_string("url")
    expected = f"expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], got {text!r}"
    try:
        parts = urllib.parse.urlsplit(text.strip())
        port = parts.port
    except ValueError:  # a port that is not a number or out of 0..65535, a bad IPv6 literal
        raise table.error("url", expected) from None
    scheme = parts.scheme.lower()
    if scheme not in _MQTT_PORTS or not parts.hostname:
        raise table.error("url", expected)
    if parts.username is not None or parts.password is not None:
        raise table.error("url", "give the credentials as username and password, not in the URL")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise table.error("url", expected)
    if port == 0:
        raise table.error("url", f"port must be 1..65535, got 0 in {text!r}")
    return parts.hostname, port, scheme == "mqtts"


def _topic_prefix(table: _Table, name: str, default: str) -> str:
    """Topic levels (``sj300``, ``plant/sj300``): each a valid name, no wildcards."""
    prefix = table.string(name)
    if prefix is None:
        return default
    if not all(valid_name(level) for level in prefix.split("/")):
        raise table.error(
            name,
            "expected topic levels of letters, digits, '_', '.' and '-' separated by '/', "
            f"got {prefix!r}",
        )
    return prefix


def _same_socket(a: Endpoint, b: Endpoint) -> bool:
    """Would binding both fail? (Port 0 never collides: each gets its own free port.)"""
    if a.port != b.port or a.port == 0:
        return False
    return a.host == b.host or bool({a.host, b.host} & _WILDCARD_HOSTS)


# -- lines ---------------------------------------------------------------------------------


@dataclass
class _Claims:
    """What the lines read so far have taken, for the checks across lines."""

    #: line name → its key path (``lines[0]``)
    names: dict[str, str] = field(default_factory=dict)
    #: transport (``tcp://HOST:PORT``, a serial device) → line name
    transports: dict[str, str] = field(default_factory=dict)
    #: Modbus unit id → (line name, ``"node 5"``)
    units: dict[int, tuple[str, str]] = field(default_factory=dict)


def _lines(ctx: _Context, root: _Table) -> tuple[LineConfig, ...]:
    items = root.tables("lines", "lines")
    if not items:
        raise ctx.error("lines", "no lines: add a [[lines]] table with a url and nodes")
    claims = _Claims()
    return tuple(_line(ctx, index, item, claims) for index, item in enumerate(items))


def _line(ctx: _Context, index: int, data: object, claims: _Claims) -> LineConfig:
    table = _Table(ctx, f"lines[{index}]", data, _LINE_KEYS)
    name = _line_name(table, index, claims)
    url, protocol = _transport(table, name, claims)
    dialect = get_dialect(protocol)
    nodes = _nodes(table, "nodes", dialect)
    interval_s = table.number("interval_s", minimum=_MIN_INTERVAL_S, inclusive=True)
    parameters = _parameter_codes(table, dialect)
    trips_interval_s = table.number("trips_interval_s", minimum=0, inclusive=True)
    unit_offset = _unit_offset(table, name, nodes, dialect, claims)
    timeout_s = table.number("timeout_s", minimum=0, inclusive=False)
    lease_s = table.number("lease_s", minimum=0, inclusive=False)
    reads, on_lapse = _reads(table), _on_lapse(table, protocol)
    grants = tuple(
        _grant(ctx, f"{table.path}.writes[{i}]", item, name, nodes, parameters, dialect)
        for i, item in enumerate(table.tables("writes", "lines.writes"))
    )
    return LineConfig(
        name=name,
        url=url,
        protocol=protocol,
        nodes=nodes,
        interval_s=_or(interval_s, _DEFAULT_LINE.interval_s),
        reads=reads,
        parameters=parameters,
        trips_interval_s=_or(trips_interval_s, _DEFAULT_LINE.trips_interval_s),
        unit_offset=unit_offset,
        timeout_s=timeout_s,
        grants=grants,
        lease_s=_or(lease_s, _DEFAULT_LINE.lease_s),
        on_lapse=on_lapse,
    )


def _line_name(table: _Table, index: int, claims: _Claims) -> str:
    name = _or(table.string("name"), f"line{index + 1}")
    if not valid_name(name):  # a topic level on MQTT (see the module docstring)
        raise table.error("name", f"a line name is letters, digits, '_', '.' and '-', got {name!r}")
    if name in claims.names:
        raise table.error("name", f"duplicate line name {name!r} (also {claims.names[name]})")
    claims.names[name] = table.path
    return name


def _transport(table: _Table, name: str, claims: _Claims) -> tuple[str, str]:
    """The line's url and protocol: the ``protocol`` key, else the URL's ``protocol=``."""
    protocol = table.string("protocol")
    if protocol is not None and protocol not in protocol_names():
        raise table.error("protocol", _unknown("protocol", protocol, sorted(protocol_names())))
    url = table.required_string("url")
    try:
        # Refuses a URL whose protocol= differs from *protocol*, and options of another protocol.
        address = parse_bus_url(url, protocol=protocol)
    except LocalProtocolError as exc:
        raise table.error("url", str(exc)) from None
    transport = _transport_id(address, url)
    if transport in claims.transports:
        raise table.error(
            "url",
            f"{transport} is already line {claims.transports[transport]}'s "
            "(a line is one [[lines]] with all its nodes)",
        )
    claims.transports[transport] = name
    return url, address.protocol or DEFAULT_PROTOCOL


def _transport_id(address: BusAddress, url: str) -> str:
    """What two lines may not share: a TCP endpoint, a serial device (each sim:// is its own)."""
    return url.strip() if address.scheme == "sim" else address.description


def _nodes(table: _Table, name: str, dialect: AnyDialect) -> tuple[int, ...]:
    """A node list, ``"1-8,12"`` or ``[1, 2, 12]``, in the dialect's range; sorted, unique."""
    value = table.required(name)
    low, high = dialect.node_range
    if isinstance(value, str):
        try:
            return parse_node_list(value, low=low, high=high)
        except LocalProtocolError as exc:
            raise table.error(name, str(exc)) from None
    if not isinstance(value, list):
        raise table.error(
            name,
            f'expected a node list ("1-8,12") or an array of integers, got {_type_name(value)}',
        )
    if not value:
        raise table.error(name, f"no {dialect.node_noun}s")
    for node in value:
        if isinstance(node, bool) or not isinstance(node, int):
            raise table.error(
                name, f"expected an array of integers, got {_type_name(node)} {node!r} in it"
            )
        if not low <= node <= high:
            raise table.error(name, f"{dialect.node_noun} {node} is outside {low}..{high}")
    return tuple(sorted(set(value)))


def _reads(table: _Table) -> tuple[str, ...]:
    reads = table.strings("reads")
    if reads is None:
        return _DEFAULT_LINE.reads
    for read in reads:
        if read not in _READS:
            raise table.error("reads", _unknown("read", read, _READS))
    return tuple(dict.fromkeys(reads))  # without repeats, in the order given


def _parameter_codes(table: _Table, dialect: AnyDialect) -> tuple[str, ...]:
    """Parameter codes normalised by the dialect (``"a004"`` → ``"A004"``), without repeats."""
    codes: dict[str, None] = {}
    for text in _or(table.strings("parameters"), ()):
        code = dialect.parameter_code(text.strip())
        if code is None:
            raise table.error("parameters", f"unknown parameter {text!r} for {dialect.name}")
        codes[code] = None
    return tuple(codes)


def _unit_offset(
    table: _Table, name: str, nodes: tuple[int, ...], dialect: AnyDialect, claims: _Claims
) -> int:
    """unit = node + offset: every unit a valid Modbus id, none taken by another line."""
    offset = _or(table.integer("unit_offset"), default_unit_offset(dialect.name))
    # Blame the offset when the file sets it, else the nodes.
    key = "unit_offset" if table.has("unit_offset") else "nodes"
    low, high = UNIT_RANGE[0], UNIT_RANGE[-1]
    for node in nodes:
        unit, drive = node + offset, f"{dialect.node_noun} {node}"
        if unit not in UNIT_RANGE:
            raise table.error(key, f"{drive} would be Modbus unit {unit}, outside {low}..{high}")
        if unit in claims.units:
            other, other_drive = claims.units[unit]
            raise table.error(
                key,
                f"Modbus unit {unit} ({drive}) is also line {other}'s ({other_drive}): "
                "set unit_offset on one of them",
            )
    claims.units.update((node + offset, (name, f"{dialect.node_noun} {node}")) for node in nodes)
    return offset


def _on_lapse(table: _Table, protocol: str) -> LapseAction:
    action = table.string("on_lapse")
    if action is None:
        return _DEFAULT_LINE.on_lapse
    if action not in _LAPSE:
        raise table.error("on_lapse", _unknown("action", action, LAPSE_ACTIONS))
    if action == "broadcast_stop" and protocol not in _BROADCAST_STOP:
        raise table.error("on_lapse", f"broadcast_stop needs a broadcast, which {protocol} has not")
    return _LAPSE[action]


def _grant(
    ctx: _Context,
    path: str,
    data: object,
    line: str,
    line_nodes: tuple[int, ...],
    polled: tuple[str, ...],
    dialect: AnyDialect,
) -> WriteGrant:
    """One ``[[lines.writes]]``: nodes of the line, parameters it polls, control or not."""
    table = _Table(ctx, path, data, _GRANT_KEYS)
    nodes = _nodes(table, "nodes", dialect)
    for node in nodes:
        if node not in line_nodes:
            noun = dialect.node_noun
            raise table.error(
                "nodes",
                f"{noun} {node} is not one of line {line}'s {noun}s "
                f"({format_node_list(line_nodes)})",
            )
    parameters = _parameter_codes(table, dialect)
    for code in parameters:
        if code not in polled:
            # A write is confirmed by reading the value back from the poll cache.
            raise table.error(
                "parameters", f"{code} is not polled on line {line}: add it to parameters"
            )
    control = _or(table.boolean("control"), False)
    if not parameters and not control:
        raise table.error("", "grants nothing: give it parameters, or control = true")
    return WriteGrant(nodes=frozenset(nodes), parameters=frozenset(parameters), control=control)
