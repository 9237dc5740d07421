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
from collections.abc import Mapping
from pathlib import Path
from typing import Final

from ..wire import LocalProtocolError
from ._config_lines import parse_lines, valid_name
from ._model import (
    DEFAULT_LOOP_LAG_LIMIT_S,
    DEFAULT_STALE_AFTER_S,
    Endpoint,
    GatewayConfig,
    default_gateway_id,
)
from ._northbound import (
    RESERVED_SECTIONS,
    NorthboundSpec,
    SectionContext,
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
_WILDCARD_HOSTS: Final = frozenset({"0.0.0.0", "::"})


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
        lines=parse_lines(ctx, root, scopes),
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
