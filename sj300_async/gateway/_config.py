"""The gateway's configuration: a TOML file (or the command line's flags) -> :class:`GatewayConfig`.

Everything is checked here, before the gateway opens a line or a port, and
a refusal is a :class:`~._toml.GatewayConfigError` whose one-line message
says where (file, line, dotted key) and why (:mod:`._toml` reads the file
and places the errors). This module is the gateway's schema: ``[gateway]``,
``[[lines]]`` with their ``[[lines.writes]]``, and one section per
registered northbound, which that northbound parses itself
(:mod:`._northbound`): the schema names none of them.

Decisions:

- The first error found stops the load: one precise message beats a list
  whose later entries are often consequences of the first.
- The command line's simple case goes through the same rules, as a
  one-line configuration whose keys are renamed to the flags
  (``lines[0].nodes`` -> ``--nodes``, ``modbus.listen`` -> ``--modbus``).
- A line's protocol must have a profile (:mod:`sj300_async.profiles`):
  nodes, parameter codes, the default unit offset and whether a broadcast
  stop exists come from it, so FR-700 stations 0..31 and ``Pr.7`` are
  checked as such, and a protocol the gateway cannot serve is refused here.
- A relative ``audit_log`` is relative to the configuration file's
  directory, so the gateway can be started from anywhere.
- Writes are confirmed against the poll cache, so a write grant may only
  name parameters the line polls; unit ids must be in 1..247 and unique
  across all lines where a northbound addresses drives by them (Modbus:
  one server serves them all), and bind nothing without one, so a plant
  of 2,048 drives on MQTT or OPC UA needs no offsets; two lines may not
  share a TCP endpoint or a serial device, but each ``sim://`` line is a
  simulator of its own whatever its URL; no two northbounds may listen on
  the same socket.
- The gateway id and the line names are topic levels on MQTT (letters,
  digits, ``_``, ``.``, ``-``), whether or not MQTT is configured: adding
  a broker later never means renaming a line.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from ..bus import (
    DEFAULT_PROTOCOL,
    BusAddress,
    format_node_list,
    parse_bus_url,
    parse_node_list,
    protocol_names,
)
from ..profiles import Profile, get_profile
from ..wire import LocalProtocolError
from ._model import (
    DEFAULT_LOOP_LAG_LIMIT_S,
    DEFAULT_STALE_AFTER_S,
    LAPSE_ACTIONS,
    LEASE_SCOPES,
    POLL_READS,
    UNIT_RANGE,
    Endpoint,
    GatewayConfig,
    LapseAction,
    LeaseScope,
    LineConfig,
    PollRead,
    WriteGrant,
    default_gateway_id,
)
from ._northbound import (
    RESERVED_SECTIONS,
    NorthboundSpec,
    SectionContext,
    UnitScope,
    get_northbound,
    northbound_names,
    parse_borrowed,
    section_aliases,
    section_borrows,
    unit_scopes,
)
from ._toml import (
    COMMAND_LINE,
    ConfigContext,
    ConfigTable,
    GatewayConfigError,
    or_default,
    parse_toml,
    read_toml,
    type_name,
    unknown_choice,
)
from .recorder._settings import RECORDER_KEYS, parse_recorder

__all__ = [
    "GatewayConfigError",
    "config_from_flags",
    "load_config",
    "parse_config",
    "valid_name",
]

#: The flag each key of the command line's one-line configuration comes from
#: (each northbound's flag is added from its spec).
_FLAGS: Final = {
    "lines[0].url": "--url",
    "lines[0].nodes": "--nodes",
    "lines[0].protocol": "--protocol",
    "lines[0].interval_s": "--interval",
    "gateway.stale_after_s": "--stale-after",
    "gateway.id": "--id",
}
_GATEWAY_KEYS: Final = ("id", "stale_after_s", "audit_log", "loop_lag_limit_s")
_LINE_KEYS: Final = (
    *("name", "url", "protocol", "nodes", "interval_s", "reads", "parameters"),
    *(
        "trips_interval_s",
        "setpoint_interval_s",
        "unit_offset",
        "timeout_s",
        "lease_s",
        "on_lapse",
        "writes",
    ),
    "lease_scope",
)
_GRANT_KEYS: Final = ("nodes", "parameters", "control")
_READS: Final[dict[str, PollRead]] = {read: read for read in POLL_READS}
_LAPSE: Final[dict[str, LapseAction]] = {action: action for action in LAPSE_ACTIONS}
_SCOPES: Final[dict[str, LeaseScope]] = {scope: scope for scope in LEASE_SCOPES}
#: What Home Assistant's entity ids write as "_" (after lower-casing): see _line_name.
_AS_AN_ID: Final = re.compile(r"[^a-z0-9]")
#: The shortest poll interval: a floor against a typo (milliseconds written
#: as seconds) that would leave the line no time for anything but polls.
_MIN_INTERVAL_S: Final = 0.05
_WILDCARD_HOSTS: Final = frozenset({"0.0.0.0", "::"})
#: A topic level: what a gateway id and a line name may hold.
_NAME: Final = re.compile(r"[A-Za-z0-9_.-]+")
#: The longest line name (a trip record's id holds it: recorder/_store.py RECORD_ID).
MAX_LINE_NAME: Final = 64
#: The defaults of a line, read from the model rather than repeated here.
_DEFAULT_LINE: Final = LineConfig(name="line1", url="sim://", protocol=DEFAULT_PROTOCOL, nodes=(1,))


def valid_name(name: str) -> bool:
    """True when *name* may name a gateway or a line (an MQTT topic level, no wildcard)."""
    return bool(_NAME.fullmatch(name))


# -- public entry points --------------------------------------------------------------------


def load_config(path: str | os.PathLike[str]) -> GatewayConfig:
    """Read and validate the gateway's TOML configuration file *path*.

    Raises:
        GatewayConfigError: the file cannot be read, is not TOML, or is not a
            valid configuration; the message names the file, line and key.
    """
    text, source = read_toml(path)
    return parse_config(text, source, file=True)


def parse_config(text: str, source: str, *, file: bool = False) -> GatewayConfig:
    """Validate the TOML configuration *text*; *source* names it in errors.

    A relative ``audit_log`` is taken relative to *source*'s directory. *file*: *text*
    was read from the file *source* (the trip recorder keeps its records beside it;
    text that is no file keeps them in memory unless it names a directory).

    Raises:
        GatewayConfigError: see :func:`load_config`.
    """
    data = parse_toml(text, source)
    return _build(ConfigContext(source, text), data, base_dir=Path(source).parent, file=file)


def config_from_flags(
    *,
    url: str,
    nodes: str,
    protocol: str | None,
    stale_after_s: float = DEFAULT_STALE_AFTER_S,
    interval_s: float = 0.5,
    gateway_id: str | None = None,
    northbounds: Mapping[str, str] | None = None,
) -> GatewayConfig:
    """The command line's simple case: one read-only line, checked like a file.

    Args:
        northbounds: each northbound's flag value by its section
            (``{"modbus": "127.0.0.1:1502"}``: ``--modbus``), set as the key
            its flag names.

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
    rename = dict(_FLAGS)
    for section, value in (northbounds or {}).items():
        flag = get_northbound(section).flag
        if flag is None:
            raise LocalProtocolError(f"northbound {section!r} has no command-line flag")
        data[section] = {flag.key: value}
        rename[f"{section}.{flag.key}"] = flag.option
    return _build(ConfigContext(COMMAND_LINE, rename=rename), data, base_dir=Path(), file=False)


# -- the whole configuration -----------------------------------------------------------------


def _build(ctx: ConfigContext, data: object, *, base_dir: Path, file: bool) -> GatewayConfig:
    sections = northbound_names()
    aliases = {section: section_aliases(get_northbound(section)) for section in sections}
    # In the order a file is written (and the error's list of keys reads): [gateway], the
    # northbounds' sections (each with the older names it still takes), then the [[lines]].
    names = [name for section in sections for name in (section, *aliases[section])]
    root = ConfigTable(ctx, "", data, ("gateway", *names, "recorder", "lines"))
    gateway = ConfigTable(ctx, "gateway", root.data.get("gateway", {}), _GATEWAY_KEYS)
    stale_after_s = gateway.number("stale_after_s", minimum=0, inclusive=False)
    lag_limit_s = gateway.number("loop_lag_limit_s", minimum=0, inclusive=False)
    audit_log = _audit_log(gateway, base_dir)
    gateway_id = _gateway_id(gateway)
    context = SectionContext(gateway_id, base_dir, state_directory())
    recorder = parse_recorder(
        ConfigTable(ctx, "recorder", root.data["recorder"], RECORDER_KEYS)
        if root.has("recorder")
        else None,
        base_dir,
        context.state_dir,
        file=file,
    )
    northbounds: dict[str, object] = {}
    listening: dict[Endpoint, str] = {}
    for section in sections:
        given = [name for name in (section, *aliases[section]) if root.has(name)]
        if section in RESERVED_SECTIONS:
            continue
        spec = get_northbound(section)
        borrowed = _borrowed(ctx, root, spec, context)
        if given and borrowed is not None:
            raise root.error(
                given[0],
                f"[{given[0]}] and the [{section_borrows(spec)}] keys that configure it too "
                f"are one northbound: keep [{given[0]}]",
            )
        if len(given) > 1:
            raise root.error(given[1], f"[{given[0]}] and [{given[1]}] are one section: keep one")
        if given:
            table = ConfigTable(ctx, given[0], root.data[given[0]], spec.keys)
            config = spec.parse(table, context)
        else:
            config = borrowed
        # None: the section is given for another northbound only (``[mqtt]`` that holds
        # only Sparkplug's deprecated keys): nothing of this one runs.
        if config is None:
            continue
        northbounds[section] = config
        for key, endpoint in spec.endpoints(config):
            for other, where in listening.items():
                if _same_socket(endpoint, other):
                    # A key may be a path within the section (listeners[0].listen).
                    named = given[0] if given else section
                    raise ctx.error(f"{named}.{key}", f"{where} already listens on {other}")
            listening[endpoint] = ctx.display(f"{section}.{key}")
    # Unit ids matter only to a northbound that addresses drives by them (Modbus), within
    # each of its scopes (a listener): a plant without one is not held to them.
    scopes = [
        scope
        for section, config in northbounds.items()
        for scope in unit_scopes(get_northbound(section), config)
    ]
    return GatewayConfig(
        lines=_lines(ctx, root, scopes),
        northbounds=northbounds,
        stale_after_s=or_default(stale_after_s, DEFAULT_STALE_AFTER_S),
        audit_log=audit_log,
        loop_lag_limit_s=or_default(lag_limit_s, DEFAULT_LOOP_LAG_LIMIT_S),
        source=ctx.source,
        gateway_id=gateway_id,
        recorder=recorder,
    )


def _borrowed(
    ctx: ConfigContext, root: ConfigTable, spec: NorthboundSpec, context: SectionContext
) -> object | None:
    """*spec*'s configuration from another section's keys (its ``borrows``), or None."""
    section = section_borrows(spec)
    if section is None or not root.has(section):
        return None
    data = root.data[section]
    keys = tuple(data) if isinstance(data, dict) else ()  # the owner checks its own keys
    return parse_borrowed(spec, ConfigTable(ctx, section, data, keys), context)


def state_directory() -> Path | None:
    """systemd's ``StateDirectory=`` (``$STATE_DIRECTORY``, its first path), None: not set.

    The place the gateway keeps what it makes itself (OPC UA's generated certificate,
    trip records) when the file names no place: under ProtectSystem=strict the
    configuration's directory is read-only (docs/guide/deploy.md).
    """
    first = os.environ.get("STATE_DIRECTORY", "").split(":")[0]
    return Path(first) if first else None


def _audit_log(gateway: ConfigTable, base_dir: Path) -> Path | None:
    text = gateway.string("audit_log")
    if text is None:
        return None
    if not text.strip():
        raise gateway.error("audit_log", "expected a file name, got an empty string")
    return base_dir / text  # an absolute path stays as it is


def _gateway_id(gateway: ConfigTable) -> str:
    name = gateway.string("id")
    if name is None:
        return default_gateway_id()
    if not valid_name(name):
        raise gateway.error(
            "id", f"a gateway id is letters, digits, '_', '.' and '-', got {name!r}"
        )
    return name


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
    #: a line name as Home Assistant's ids write it → (the name, its key path)
    ids: dict[str, tuple[str, str]] = field(default_factory=dict)
    #: transport (``tcp://HOST:PORT``, a serial device) → line name
    transports: dict[str, str] = field(default_factory=dict)
    #: The scopes within which unit ids are checked (a Modbus listener each).
    scopes: Sequence[UnitScope] = ()
    #: Per scope: Modbus unit id → (line name, ``"node 5"``)
    units: dict[int, dict[int, tuple[str, str]]] = field(default_factory=dict)

    def scopes_of(self, line: str) -> list[tuple[int, UnitScope]]:
        """The scopes whose unit ids *line*'s drives take (a named one, else the rest's)."""
        named = [(i, s) for i, s in enumerate(self.scopes) if s.lines and line in s.lines]
        rest = [(i, s) for i, s in enumerate(self.scopes) if s.lines is None]
        return named or rest


def _lines(
    ctx: ConfigContext, root: ConfigTable, scopes: Sequence[UnitScope]
) -> tuple[LineConfig, ...]:
    items = root.tables("lines", "lines")
    if not items:
        raise ctx.error("lines", "no lines: add a [[lines]] table with a url and nodes")
    claims = _Claims(scopes=scopes)
    lines = tuple(_line(ctx, index, item, claims) for index, item in enumerate(items))
    for scope in scopes:  # a scope naming a line that is not there is a typo
        for name in sorted((scope.lines or frozenset()) - {line.name for line in lines}):
            raise ctx.error(f"{scope.where}.lines", f"no line named {name!r}")
    return lines


def _line(ctx: ConfigContext, index: int, data: object, claims: _Claims) -> LineConfig:
    table = ConfigTable(ctx, f"lines[{index}]", data, _LINE_KEYS)
    name = _line_name(table, index, claims)
    url, protocol = _transport(table, name, claims)
    try:
        profile = get_profile(protocol)
    except LocalProtocolError as exc:
        raise table.error("protocol" if table.has("protocol") else "url", str(exc)) from None
    nodes = _nodes(table, "nodes", profile)
    interval_s = table.number("interval_s", minimum=_MIN_INTERVAL_S, inclusive=True)
    parameters = _parameter_codes(table, profile)
    trips_interval_s = table.number("trips_interval_s", minimum=0, inclusive=True)
    setpoint_interval_s = table.number("setpoint_interval_s", minimum=0, inclusive=True)
    unit_offset = _unit_offset(table, name, nodes, profile, claims)
    timeout_s = table.number("timeout_s", minimum=0, inclusive=False)
    lease_s = table.number("lease_s", minimum=0, inclusive=False)
    reads, on_lapse = _reads(table), _on_lapse(table, profile)
    grants = tuple(
        _grant(ctx, f"{table.path}.writes[{i}]", item, name, nodes, parameters, profile)
        for i, item in enumerate(table.tables("writes", "lines.writes"))
    )
    return LineConfig(
        name=name,
        url=url,
        protocol=protocol,
        nodes=nodes,
        interval_s=or_default(interval_s, _DEFAULT_LINE.interval_s),
        reads=reads,
        parameters=parameters,
        trips_interval_s=or_default(trips_interval_s, _DEFAULT_LINE.trips_interval_s),
        setpoint_interval_s=or_default(setpoint_interval_s, _DEFAULT_LINE.setpoint_interval_s),
        unit_offset=unit_offset,
        timeout_s=timeout_s,
        grants=grants,
        lease_s=or_default(lease_s, _DEFAULT_LINE.lease_s),
        on_lapse=on_lapse,
        lease_scope=_lease_scope(table),
    )


def _line_name(table: ConfigTable, index: int, claims: _Claims) -> str:
    name = or_default(table.string("name"), f"line{index + 1}")
    if not valid_name(name):  # a topic level on MQTT (see the module docstring)
        raise table.error("name", f"a line name is letters, digits, '_', '.' and '-', got {name!r}")
    if len(name) > MAX_LINE_NAME:  # in every trip record's id and file name, and in HA's ids
        raise table.error("name", f"a line name is at most {MAX_LINE_NAME} characters, "
                                  f"got {len(name)}")  # fmt: skip
    if name in claims.names:
        raise table.error("name", f"duplicate line name {name!r} (also {claims.names[name]})")
    # Home Assistant's entity ids are lower case with '_' for anything else, and its
    # discovery node ids have '_' for '.': two names alike there share a drive's ids,
    # and one drive's entities take the other's (issue 43).
    written = _AS_AN_ID.sub("_", name.lower())
    if written in claims.ids:
        other, path = claims.ids[written]
        raise table.error(
            "name",
            f"{name!r} and {other!r} ({path}) are one name in Home Assistant's ids "
            f"({written}): name the lines apart",
        )
    claims.names[name] = table.path
    claims.ids[written] = (name, table.path)
    return name


def _transport(table: ConfigTable, name: str, claims: _Claims) -> tuple[str, str]:
    """The line's url and protocol: the ``protocol`` key, else the URL's ``protocol=``."""
    protocol = table.string("protocol")
    if protocol is not None and protocol not in protocol_names():
        raise table.error(
            "protocol", unknown_choice("protocol", protocol, sorted(protocol_names()))
        )
    url = table.required_string("url")
    try:
        # Refuses a URL whose protocol= differs from *protocol*, and options of another protocol.
        address = parse_bus_url(url, protocol=protocol)
    except LocalProtocolError as exc:
        raise table.error("url", str(exc)) from None
    transport = _transport_id(address, url)
    if transport is None:
        return url, address.protocol or DEFAULT_PROTOCOL
    if transport in claims.transports:
        raise table.error(
            "url",
            f"{transport} is already line {claims.transports[transport]}'s "
            "(a line is one [[lines]] with all its nodes)",
        )
    claims.transports[transport] = name
    return url, address.protocol or DEFAULT_PROTOCOL


def _transport_id(address: BusAddress, url: str) -> str | None:
    """What two lines may not share: a TCP endpoint, a serial device; None for ``sim://``,
    which is a simulator of its own on every line, whatever its URL."""
    return None if address.scheme == "sim" else address.description


def _nodes(table: ConfigTable, name: str, profile: Profile) -> tuple[int, ...]:
    """A node list, ``"1-8,12"`` or ``[1, 2, 12]``, in the profile's range, each once; sorted."""
    value = table.required(name)
    low, high = profile.node_range
    noun = profile.node_noun
    if isinstance(value, str):
        try:
            nodes = parse_node_list(value, low=low, high=high, noun=noun)
            # parse_node_list merges what overlaps; a node named twice is a typo here.
            parts = [parse_node_list(p, low=low, high=high) for p in value.split(",") if p.strip()]
        except LocalProtocolError as exc:
            raise table.error(name, str(exc)) from None
        _refuse_repeats(table, name, noun, [node for part in parts for node in part])
        return nodes
    if not isinstance(value, list):
        raise table.error(
            name,
            f'expected a node list ("1-8,12") or an array of integers, got {type_name(value)}',
        )
    if not value:
        raise table.error(name, f"no {noun}s")
    for node in value:
        if isinstance(node, bool) or not isinstance(node, int):
            raise table.error(
                name, f"expected an array of integers, got {type_name(node)} {node!r} in it"
            )
        if not low <= node <= high:
            raise table.error(name, f"{noun} {node} is outside {low}..{high}")
    _refuse_repeats(table, name, noun, value)
    return tuple(sorted(value))


def _refuse_repeats(table: ConfigTable, name: str, noun: str, nodes: list[int]) -> None:
    seen: set[int] = set()
    for node in nodes:
        if node in seen:
            raise table.error(name, f"{noun} {node} is listed twice")
        seen.add(node)


def _reads(table: ConfigTable) -> tuple[PollRead, ...]:
    reads = table.strings("reads")
    if reads is None:
        return _DEFAULT_LINE.reads
    for read in reads:
        if read not in _READS:
            raise table.error("reads", unknown_choice("read", read, POLL_READS))
    return tuple(dict.fromkeys(_READS[read] for read in reads))  # no repeats, in the order given


def _parameter_codes(table: ConfigTable, profile: Profile) -> tuple[str, ...]:
    """Parameter codes normalised by the profile (``"a004"`` -> ``"A004"``), without repeats."""
    codes: dict[str, None] = {}
    catalogue = profile.parameters
    known = frozenset(catalogue.codes())
    for text in or_default(table.strings("parameters"), ()):
        # code() reads the syntax ("F005" is an SJ300 code); the catalogue says what exists.
        code = catalogue.code(text.strip())
        if code is None or code not in known:
            raise table.error("parameters", f"unknown parameter {text!r} for {profile.name}")
        codes[code] = None
    return tuple(codes)


def _unit_offset(
    table: ConfigTable, name: str, nodes: tuple[int, ...], profile: Profile, claims: _Claims
) -> int:
    """unit = node + offset: every unit a valid Modbus id, none taken by another line of
    its scope (checked only where a northbound addresses drives by unit id)."""
    offset = or_default(table.integer("unit_offset"), profile.unit_offset)
    # Blame the offset when the file sets it, else the nodes.
    key = "unit_offset" if table.has("unit_offset") else "nodes"
    low, high = UNIT_RANGE[0], UNIT_RANGE[-1]
    for index, scope in claims.scopes_of(name):
        taken = claims.units.setdefault(index, {})
        # The one listener of a plain [modbus] needs no naming; a group's does.
        plain = scope.lines is None and len(claims.scopes) == 1
        on = "" if plain else f" on {scope.where}"
        for node in nodes:
            unit, drive = node + offset, f"{profile.node_noun} {node}"
            if unit not in UNIT_RANGE:
                raise table.error(
                    key, f"{drive} would be Modbus unit {unit}{on}, outside {low}..{high}"
                )
            if unit in taken:
                other, other_drive = taken[unit]
                raise table.error(
                    key,
                    f"Modbus unit {unit}{on} ({drive}) is also line {other}'s ({other_drive}): "
                    "set unit_offset on one of them",
                )
        taken.update((node + offset, (name, f"{profile.node_noun} {node}")) for node in nodes)
    return offset


def _lease_scope(table: ConfigTable) -> LeaseScope:
    scope = table.string("lease_scope")
    if scope is None:
        return _DEFAULT_LINE.lease_scope
    if scope not in _SCOPES:
        raise table.error("lease_scope", unknown_choice("scope", scope, LEASE_SCOPES))
    return _SCOPES[scope]


def _on_lapse(table: ConfigTable, profile: Profile) -> LapseAction:
    action = table.string("on_lapse")
    if action is None:
        return _DEFAULT_LINE.on_lapse
    if action not in _LAPSE:
        raise table.error("on_lapse", unknown_choice("action", action, LAPSE_ACTIONS))
    if action == "broadcast_stop" and not profile.capabilities.broadcast_stop:
        raise table.error(
            "on_lapse", f"broadcast_stop needs a broadcast, which {profile.name} has not"
        )
    return _LAPSE[action]


def _grant(
    ctx: ConfigContext,
    path: str,
    data: object,
    line: str,
    line_nodes: tuple[int, ...],
    polled: tuple[str, ...],
    profile: Profile,
) -> WriteGrant:
    """One ``[[lines.writes]]``: nodes of the line, parameters it polls, control or not."""
    table = ConfigTable(ctx, path, data, _GRANT_KEYS)
    nodes = _nodes(table, "nodes", profile)
    for node in nodes:
        if node not in line_nodes:
            noun = profile.node_noun
            raise table.error(
                "nodes",
                f"{noun} {node} is not one of line {line}'s {noun}s "
                f"({format_node_list(line_nodes)})",
            )
    parameters = _parameter_codes(table, profile)
    for code in parameters:
        if code not in polled:
            # A write is confirmed by reading the value back from the poll cache.
            raise table.error(
                "parameters", f"{code} is not polled on line {line}: add it to parameters"
            )
    control = or_default(table.boolean("control"), False)
    if not parameters and not control:
        raise table.error("", "grants nothing: give it parameters, or control = true")
    return WriteGrant(nodes=frozenset(nodes), parameters=frozenset(parameters), control=control)
