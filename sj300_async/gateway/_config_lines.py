"""The gateway configuration's ``[[lines]]``: each table -> a checked :class:`LineConfig`.

Part of the gateway's schema (:mod:`._config`, whose docstring holds the
decisions): a line's name, transport, protocol and nodes, its poll, its
unit ids within each northbound's scopes, its lease and its write grants,
and the checks across lines (names, Home Assistant's ids, transports,
unit ids).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
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
    LAPSE_ACTIONS,
    LEASE_SCOPES,
    POLL_READS,
    UNIT_RANGE,
    LapseAction,
    LeaseScope,
    LineConfig,
    PollRead,
    WriteGrant,
)
from ._northbound import UnitScope
from ._toml import (
    ConfigContext,
    ConfigTable,
    or_default,
    type_name,
    unknown_choice,
)

__all__ = ["MAX_LINE_NAME", "parse_lines", "valid_name"]

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
#: A topic level: what a gateway id and a line name may hold.
_NAME: Final = re.compile(r"[A-Za-z0-9_.-]+")
#: The longest line name (a trip record's id holds it: recorder/_store.py RECORD_ID).
MAX_LINE_NAME: Final = 64
#: The defaults of a line, read from the model rather than repeated here.
_DEFAULT_LINE: Final = LineConfig(name="line1", url="sim://", protocol=DEFAULT_PROTOCOL, nodes=(1,))


def valid_name(name: str) -> bool:
    """True when *name* may name a gateway or a line (an MQTT topic level, no wildcard)."""
    return bool(_NAME.fullmatch(name))


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


def parse_lines(
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
