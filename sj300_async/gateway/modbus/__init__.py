"""The Modbus TCP northbound: every drive a unit id, its register map served from the cache.

Configured by ``[modbus] listen = "HOST:PORT"`` or ``--modbus HOST:PORT``,
and the listeners' limits ``max_connections`` (default 64, all listeners
together) and ``idle_timeout_s`` (default 60). A plant of more drives than
one Modbus server can address (247 unit ids) gives groups of lines their
own listeners, each with its own unit ids::

    [[modbus.listeners]]
    listen = "0.0.0.0:5021"
    lines = ["hall-a", "hall-b"]

``listen`` then serves the lines no listener names (it may be left out
when every line has one). Unit ids are unique within a listener, not
across them (:class:`UnitScope`). Unit 255 of every listener is its
summary (:mod:`._summary`): a record of each of its drives side by side,
for a SCADA that reads a whole plant. Reads are served from each drive as
served (its latest snapshot, with the gateway's judgement of what is fresh
and who holds the lease: :class:`~sj300_async.gateway.ServedDrive`; no read
reaches a line); writes go through the gateway's write path, and a refusal
is answered with the Modbus exception its meaning is closest to
(:data:`REFUSAL_CODES`). The register map is docs/GATEWAY.md's
(:func:`describe` generates its tables). The server is our own (a sans-IO
framer, :mod:`._framing`, under an asyncio protocol, :mod:`._server`): it
needs no library of the ``gateway`` extra.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from .. import (
    LIMIT_KEYS,
    ConfigTable,
    Endpoint,
    Flag,
    ListenerLimits,
    Northbound,
    SectionContext,
    UnitScope,
    valid_name,
)
from ._clients import MAX_CLIENTS, OTHER_CLIENT, ClientCounters, client_families
from ._framing import Exc
from ._registers import REFUSAL_CODES, Field, RegisterMap, describe, parameter_address
from ._summary import (
    SUMMARY_RECORD,
    SUMMARY_SLOTS,
    SUMMARY_UNIT,
    Summary,
    SummaryBits,
    SummaryField,
)

__all__ = [
    "DEFAULT_LIMITS",
    "MAX_CLIENTS",
    "NORTHBOUND",
    "OTHER_CLIENT",
    "REFUSAL_CODES",
    "SUMMARY_RECORD",
    "SUMMARY_SLOTS",
    "SUMMARY_UNIT",
    "ClientCounters",
    "Exc",
    "Field",
    "ModbusConfig",
    "ModbusListener",
    "RegisterMap",
    "Summary",
    "SummaryBits",
    "SummaryField",
    "client_families",
    "describe",
    "parameter_address",
]


#: The listener's limits when ``[modbus]`` sets none: 64 connections (a plant's SCADA,
#: HMIs and engineering tools, with room to spare, and far below a small descriptor
#: limit), closed after 60 s without a request (SCADA polls every few seconds).
DEFAULT_LIMITS: Final = ListenerLimits(max_connections=64, idle_timeout_s=60.0)


@dataclass(frozen=True, slots=True)
class ModbusListener:
    """``[[modbus.listeners]]``: a listener of its own for some lines, with their unit ids."""

    listen: Endpoint
    lines: frozenset[str]


@dataclass(frozen=True, slots=True)
class ModbusConfig:
    """``[modbus]``: where the Modbus TCP servers listen, and their limits."""

    #: The listener of every line no listener below names (None: every line has one).
    listen: Endpoint | None
    limits: ListenerLimits = DEFAULT_LIMITS
    listeners: tuple[ModbusListener, ...] = ()


def _listeners(table: ConfigTable) -> tuple[ModbusListener, ...]:
    found: list[ModbusListener] = []
    named: dict[str, str] = {}
    for i, item in enumerate(table.tables("listeners", "modbus.listeners")):
        path = f"{table.path}.listeners[{i}]"
        entry = ConfigTable(table.ctx, path, item, ("listen", "lines"))
        listen = entry.required_endpoint("listen")
        lines = entry.strings("lines")
        if not lines:
            raise entry.error("lines", "name the lines this listener serves")
        for name in lines:
            if not valid_name(name):
                raise entry.error("lines", f"not a line name: {name!r}")
            if name in named:
                raise entry.error("lines", f"line {name!r} is also {named[name]}'s")
            named[name] = f"modbus.listeners[{i}]"
        found.append(ModbusListener(listen, frozenset(lines)))
    return tuple(found)


class _Spec:
    section = "modbus"
    keys = ("listen", *LIMIT_KEYS, "listeners")
    flag = Flag("--modbus", "listen", "HOST:PORT", "serve Modbus TCP there (port 0: any)")
    requires = ()

    def parse(self, table: ConfigTable, context: SectionContext) -> ModbusConfig:
        listeners = _listeners(table)
        listen = table.required_endpoint("listen") if table.has("listen") or not listeners else None
        return ModbusConfig(listen, DEFAULT_LIMITS.parse(table), listeners)

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, ModbusConfig)
        out = [] if config.listen is None else [("listen", config.listen)]
        out += [(f"listeners[{i}].listen", x.listen) for i, x in enumerate(config.listeners)]
        return out

    def unit_scopes(self, config: object) -> Sequence[UnitScope]:
        """Drives are Modbus units: unique ids (1..247) within each listener."""
        assert isinstance(config, ModbusConfig)
        scopes = [
            UnitScope(f"modbus.listeners[{i}]", x.lines) for i, x in enumerate(config.listeners)
        ]
        if config.listen is not None:
            scopes.append(UnitScope("modbus.listen", None))
        return scopes

    def create(self, config: object) -> Northbound:
        from ._northbound import ModbusNorthbound

        assert isinstance(config, ModbusConfig)
        return ModbusNorthbound(config)


#: The registry's entry (``sj300_async.gateway.modbus:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
