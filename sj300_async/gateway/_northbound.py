"""The northbound seam: how the gateway serves its drives, one small interface per way.

A northbound is one way of serving the drives to the outside: Modbus TCP,
MQTT (JSON and Home Assistant), Sparkplug B, OPC UA, HTTP (the workbench,
its API, metrics and health), and whatever comes next. Each is one
package that registers a :class:`NorthboundSpec` under the name of its
configuration section; the gateway knows none of them by name:

- the configuration: the spec owns its section (its keys, their parsing
  and validation through :class:`~._toml.ConfigTable`, so its errors name
  the file, line and key like every other) and, optionally, one command
  line flag (:class:`Flag`: ``--modbus HOST:PORT`` sets ``modbus.listen``);
- the running part, a :class:`Northbound` the spec creates: ``start`` (given
  a :class:`GatewayView`), ``publish`` (a drive's new snapshot as served,
  handed over in the gateway's 50 ms batch: it must never block, the
  batch runs on the event loop every door and the poll share), an
  optional ``flush`` (the batch is whole), ``metrics`` (its own
  Prometheus families, e.g. its clients' counters), ``close``.

Writes arrive from a northbound's clients and go through
:meth:`GatewayView.write` as neutral :data:`~._writes.WriteRequest` values;
the answer is a neutral :class:`~._writes.WriteResult` that each northbound
words its own way. A northbound that refuses a request before it reaches
the gateway (it could not parse it) records that through
:meth:`GatewayView.refused`, so the audit log has every refusal.

Adding a northbound is one package plus one :func:`register_northbound`
call (the tests define one of their own: a JSON-lines writer). The built-in
ones are listed in :data:`_BUILT_IN`, imported on first use; a spec module
must import nothing heavy (the command line loads every spec to build the
``sj300 gateway`` flags): the server libraries are imported by ``create``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final, Protocol

from ..bus import load_object
from ..wire import LocalProtocolError
from ._drive import GatewayDrive
from ._model import Endpoint, GatewayConfig
from ._served import ServedDrive
from ._toml import ConfigTable
from ._writes import WriteRequest, WriteResult

if TYPE_CHECKING:
    from prometheus_client.core import Metric

    from ..profiles import Profile
    from ._audit import AuditLog
    from ._line_health import LineHealth
    from ._line_traffic import LineTraffic
    from ._model import LineConfig
    from .recorder._store import TripStore

__all__ = [
    "Flag",
    "GatewayView",
    "Northbound",
    "NorthboundSpec",
    "SectionContext",
    "ServedLine",
    "UnitScope",
    "get_northbound",
    "northbound_extra",
    "northbound_names",
    "parse_borrowed",
    "register_northbound",
    "section_aliases",
    "section_borrows",
    "unit_scopes",
    "unregister_northbound",
]


class ServedLine(Protocol):
    """What a northbound sees of a line (a :class:`~._gateway.GatewayLine`): its settings,
    drives, health and traffic; never its bus, poller or controller (issue 42)."""

    @property
    def config(self) -> LineConfig: ...

    @property
    def profile(self) -> Profile:
        """The line's protocol profile (its parameters, its words)."""

    @property
    def drives(self) -> Mapping[int, GatewayDrive]:
        """The line's drives by node."""

    def health(self, now: float | None = None) -> LineHealth:
        """The line's link, counters and utilisation at *now* (loop time; default: now)."""

    def traffic(self) -> LineTraffic:
        """The line's traffic, recorded from now until the recording is closed."""


class GatewayView(Protocol):
    """What a northbound sees of the gateway (the :class:`~._gateway.Gateway` itself)."""

    @property
    def config(self) -> GatewayConfig: ...

    @property
    def audit(self) -> AuditLog:
        """The audit log of every write, whichever door it came through."""

    @property
    def trip_records(self) -> TripStore | None:
        """The trip records kept (.recorder), None when the recorder is off."""

    @property
    def lines(self) -> Sequence[ServedLine]:
        """Every line, in the configuration's order: its settings, drives, health, traffic."""

    @property
    def drives(self) -> Sequence[GatewayDrive]:
        """Every drive, lines in the configuration's order, nodes ascending."""

    def drive(self, line: str, node: int) -> GatewayDrive | None:
        """The drive *node* of line *line*, None when the gateway has no such drive."""

    async def write(
        self,
        client: str,
        drive: GatewayDrive,
        request: WriteRequest,
        *,
        connection: str | None = None,
    ) -> WriteResult:
        """Judge and carry out *client*'s write (audited); never raises for a refusal.

        *connection* names the client's connection (``"10.0.0.5:50123"``, an
        MQTT session) when the northbound has one: a line whose lease is
        connection-scoped (``lease_scope = "connection"``) lapses the lease
        when that connection closes (:meth:`disconnected`).
        """

    async def read_parameter_raw(self, drive: GatewayDrive, code: str) -> int:
        """Parameter *code* of *drive* read now, beside the poll, through its line's
        controller (raises the bus's errors: a NAK, a time-out)."""

    def disconnected(self, connection: str) -> None:
        """*connection* closed: the connection-scoped leases it holds lapse now."""

    def refused(
        self, client: str, drive: GatewayDrive, what: str, value: object, result: WriteResult
    ) -> None:
        """Audit a request the northbound refused before handing it over."""

    def metrics(self) -> Iterable[Metric]:
        """Every metric family of the gateway, every northbound's included, built now."""

    def problems(self) -> list[str]:
        """Why the gateway is not healthy now, one line each (empty: healthy)."""


class Northbound(Protocol):
    """One way of serving the drives, running (see the module docstring)."""

    async def start(self, gateway: GatewayView) -> None:
        """Start serving (listen, connect); raise if it cannot (nothing is left running)."""

    def announce(self) -> str | None:
        """One line saying where it serves, once started (``modbus on 127.0.0.1:1502``)."""

    def publish(self, drive: ServedDrive) -> None:
        """A drive's new snapshot as served (after each sample and write): what to serve
        of it is decided there (``drive.values()``, ``drive.quality(...)``); the
        snapshot itself is ``drive.snapshot``. Must not block."""

    def metrics(self) -> Iterable[Metric]:
        """Its own metric families (its clients, its connection), built now."""

    async def close(self) -> None:
        """Stop serving: no client request starts any more once this returns."""

    # Optional: ``problems() -> list[str]``, why it does not serve fully now, one line
    # each (MQTT: a subscription the broker refused); the gateway adds them to its own
    # for /healthz. Read through getattr, so a northbound written before it needs no change.
    #
    # Optional, for a reload (:mod:`._reload`; without them the gateway restarts the
    # northbound, and its clients reconnect):
    # ``reconfigure(config) -> Sequence[str]``: its section changed, where it listens did
    # not: take *config* for the next request (users, tokens, limits) and return the keys
    # it could not take live (kept as they were until a restart; the gateway says so).
    # ``async lines_changed(added, removed) -> None``: lines were added to the gateway or
    # removed from it (``ServedLine`` each, with their drives; a line changed otherwise is
    # removed and added): serve the new drives, forget the old. No snapshot of a removed
    # drive is published after it, and none of an added drive before it.
    #
    # Optional: ``flush() -> None``, called once the batch just published is whole
    # (after every ``publish`` of it): a northbound that sends samples on sends what it
    # gathered now, with no timer of its own (the gateway's batch did the gathering).
    # Must not block. Read through getattr, as ``problems``.
    #
    # Optional: ``recorded(summary, drive) -> None``, a trip record was kept (.recorder:
    # a ``RecordSummary``, and the drive as served now): announce it on the door's wire
    # (MQTT's …/trip, Sparkplug's Trip Record metrics, an OPC UA event). Must not block.


@dataclass(frozen=True, slots=True)
class Flag:
    """A northbound's command-line flag: ``--modbus HOST:PORT`` sets ``modbus.listen``."""

    #: The option, ``"--modbus"``.
    option: str
    #: The key of the northbound's section the flag's value sets.
    key: str
    metavar: str
    help: str
    #: Older spellings of the option that still set the same key (``--metrics``).
    aliases: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class SectionContext:
    """What a section's parser may need of the rest of the configuration."""

    #: The gateway's id (``[gateway] id``, else the host name's).
    gateway_id: str
    #: Relative paths in the file are relative to this (the file's directory).
    base_dir: Path
    #: Where a northbound keeps what it makes itself when the file names no place (OPC
    #: UA's generated certificate): systemd's ``$STATE_DIRECTORY`` when the gateway runs
    #: as its service (contrib/systemd), else *base_dir*.
    state_dir: Path | None = None

    @property
    def state(self) -> Path:
        """:attr:`state_dir`, else :attr:`base_dir`."""
        return self.base_dir if self.state_dir is None else self.state_dir


class NorthboundSpec(Protocol):
    """A registered northbound: its section, its flag, and how to make it run."""

    #: The name it is registered under, and its configuration section's.
    @property
    def section(self) -> str: ...

    #: The keys its section may hold.
    @property
    def keys(self) -> Sequence[str]: ...

    @property
    def flag(self) -> Flag | None: ...

    #: Modules it needs that an extra brings (``("pymodbus",)``), checked before it starts.
    @property
    def requires(self) -> Sequence[str]: ...

    def parse(self, table: ConfigTable, context: SectionContext) -> object:
        """Its configuration from its section.

        Raises:
            GatewayConfigError: through *table*'s getters and ``table.error``.
        """

    # Optional: ``unit_scopes(config)``, the groups of lines within which it addresses
    # drives by unit id (Modbus: one per listener): only then does the configuration
    # hold each drive of a group to a unique id in 1..247. Read by :func:`unit_scopes`.
    # Optional: ``extra``, the package extra that brings ``requires`` (default
    # ``"gateway"``; OPC UA's is ``"opcua"``), read through :func:`northbound_extra`.
    # Optional: ``aliases``, a sequence of older section names the spec still takes
    # (the HTTP northbound's ``[metrics]``); read through :func:`section_aliases`, so a
    # spec written before it existed needs no change.
    # Optional: ``borrows``, another northbound's section some of whose keys configure
    # this one too (Sparkplug's deprecated ``[mqtt] sparkplug = true``), with
    # ``parse_borrowed(table, context) -> object | None``: given that section's table
    # (its keys are its owner's to check), this spec's configuration, or None when the
    # keys configure nothing of it. Its own section and the borrowed keys at once are an
    # error. Read through :func:`section_borrows`; the owner need not know the borrower.

    # Optional: ``check(config) -> Sequence[str]``, for ``sj300 gateway --check-config``
    # (:mod:`._check`): what its start would refuse beyond the parser and its ports (its
    # files that do not load: OPC UA's certificate), raised as the ``GatewayStartError``
    # the start gives, without starting or writing anything; else a few words for the
    # summary (``"HTTPS, writes by 2 user(s)"``). Read through getattr.

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        """The sockets it listens on, with the key that names each (two may not collide)."""

    def create(self, config: object) -> Northbound:
        """The northbound for *config*, not started."""


@dataclass(frozen=True, slots=True)
class UnitScope:
    """Lines whose drives one server addresses by unit id: each id once, in 1..247."""

    #: Where the configuration names it (``modbus.listeners[0]``), for errors.
    where: str
    #: The lines' names; None: every line no other scope of the northbound names.
    lines: frozenset[str] | None


def unit_scopes(spec: NorthboundSpec, config: object) -> Sequence[UnitScope]:
    """The unit-id scopes of *spec* with *config* (its optional ``unit_scopes``; none)."""
    scopes = getattr(spec, "unit_scopes", None)
    return () if scopes is None else tuple(scopes(config))


def northbound_extra(spec: NorthboundSpec) -> str:
    """The package extra that brings *spec*'s ``requires`` (optional ``extra``; ``gateway``)."""
    return str(getattr(spec, "extra", "gateway"))


def section_aliases(spec: NorthboundSpec) -> tuple[str, ...]:
    """The older section names *spec* still takes (``("metrics",)`` for ``[http]``)."""
    return tuple(getattr(spec, "aliases", ()))


def section_borrows(spec: NorthboundSpec) -> str | None:
    """The other section whose keys may configure *spec* too (optional ``borrows``)."""
    borrows = getattr(spec, "borrows", None)
    return None if borrows is None else str(borrows)


def parse_borrowed(spec: NorthboundSpec, table: ConfigTable, context: SectionContext) -> object:
    """*spec*'s configuration from its ``borrows`` section's *table*, None: nothing of it."""
    parse = getattr(spec, "parse_borrowed", None)
    return None if parse is None else parse(table, context)


#: The library's northbounds, in the order they start (and announce themselves).
_BUILT_IN: Final = {
    "modbus": "sj300_async.gateway.modbus:NORTHBOUND",
    "http": "sj300_async.gateway.http:NORTHBOUND",
    "mqtt": "sj300_async.gateway.mqtt:NORTHBOUND",
    "sparkplug": "sj300_async.gateway.sparkplug:NORTHBOUND",
    "opcua": "sj300_async.gateway.opcua:NORTHBOUND",
}
_NAME: Final = re.compile(r"[a-z][a-z0-9_]*\Z")
_entries: dict[str, str | NorthboundSpec] = dict(_BUILT_IN)
_loaded: dict[str, NorthboundSpec] = {}
#: Sections the gateway's own schema uses: no northbound may take them.
RESERVED_SECTIONS: Final = frozenset({"gateway", "lines"})


def register_northbound(name: str, spec: str | NorthboundSpec) -> None:
    """Make *name* a northbound the gateway can be configured with (section ``[name]``).

    Args:
        name: lower-case letters, digits and ``_``: its section's name.
        spec: ``"module:attribute"`` of a :class:`NorthboundSpec`, imported on
            first use, or the spec itself.

    Raises:
        LocalProtocolError: a bad name, a reserved one, or one already registered.
    """
    if not isinstance(name, str) or not _NAME.match(name) or name in RESERVED_SECTIONS:
        raise LocalProtocolError(f"a northbound name is a free section name, got {name!r}")
    if name in _entries:
        raise LocalProtocolError(f"northbound {name!r} is already registered")
    _entries[name] = spec


def unregister_northbound(name: str) -> None:
    """Forget a northbound added with :func:`register_northbound` (the built-in ones stay)."""
    if name not in _BUILT_IN:
        _entries.pop(name, None)
        _loaded.pop(name, None)


def northbound_names() -> tuple[str, ...]:
    """Every registered northbound, in the order they start."""
    return tuple(_entries)


def get_northbound(name: str) -> NorthboundSpec:
    """The spec of northbound *name*.

    Raises:
        LocalProtocolError: no such northbound, or it names another section.
    """
    spec = _loaded.get(name)
    if spec is not None:
        return spec
    entry = _entries.get(name)
    if entry is None:
        raise LocalProtocolError(f"unknown northbound {name!r} (use {', '.join(_entries)})")
    loaded: NorthboundSpec = load_object(entry) if isinstance(entry, str) else entry
    if loaded.section != name:
        raise LocalProtocolError(f"northbound {name!r} is registered to section {loaded.section!r}")
    _loaded[name] = loaded
    return loaded
