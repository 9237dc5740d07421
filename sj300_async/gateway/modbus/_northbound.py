"""The Modbus TCP northbound, running: one server for every drive of every line."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

from .. import (
    ConnectionLimit,
    Endpoint,
    GatewayView,
    ServedDrive,
    ServedLine,
    listener_families,
)
from . import ModbusConfig
from ._clients import ClientCounters, bad_frames_family, client_families
from ._registers import RegisterMap
from ._server import ModbusServer, Unit

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["ModbusNorthbound"]

_log = logging.getLogger("sj300_async.gateway.modbus")


class ModbusNorthbound:
    """Serves the drives on Modbus TCP (a :class:`~sj300_async.gateway.Northbound`).

    One server per listener: ``[modbus] listen`` for the lines no listener names,
    each ``[[modbus.listeners]]`` for its own lines, with their own unit ids. They
    share one connection limit (``max_connections`` is for them all) and the
    client counters.
    """

    def __init__(self, config: ModbusConfig) -> None:
        self.config = config
        #: Requests and exception replies per client, for the exporter.
        self.clients = ClientCounters()
        #: The running servers, the main listener's first: (its endpoint, its server).
        self.servers: list[tuple[Endpoint, ModbusServer]] = []
        self._gateway: GatewayView | None = None

    @property
    def server(self) -> ModbusServer | None:
        """The first server (the main listener's when there is one), None when not started."""
        return self.servers[0][1] if self.servers else None

    async def start(self, gateway: GatewayView) -> None:
        self._gateway = gateway
        limit: ConnectionLimit | None = None
        try:
            for endpoint, units in zip(self._endpoints(), self._units(gateway), strict=True):
                server = ModbusServer(units, gateway, self.config.limits, self.clients, limit)
                limit = server.limit
                await server.start(endpoint)
                self.servers.append((endpoint, server))
        except BaseException:
            await self.close()
            raise

    async def lines_changed(
        self, added: Sequence[ServedLine], removed: Sequence[ServedLine]
    ) -> None:
        """A reload added or removed lines: each listener's units again, its connections
        kept (a request for a removed drive's unit is answered as for no drive)."""
        assert self._gateway is not None
        for (_, server), units in zip(self.servers, self._units(self._gateway), strict=True):
            server.set_units(units)

    def reconfigure(self, config: object) -> list[str]:
        """A reload changed ``[modbus]``, not where it listens: its limits from the next
        connection (idle time from the next request); which lines a listener serves
        waits for a restart (returned)."""
        assert isinstance(config, ModbusConfig)
        kept = ["modbus.listeners"] if config.listeners != self.config.listeners else []
        limits = config.limits
        if self.servers:
            self.servers[0][1].limit.retune(limits)  # one limit for every listener
        for _, server in self.servers:
            server.idle_timeout_s = limits.idle_timeout_s
        self.config = dataclasses.replace(self.config, limits=limits)
        return kept

    def _endpoints(self) -> list[Endpoint]:
        config = self.config
        main = [] if config.listen is None else [config.listen]
        return main + [listener.listen for listener in config.listeners]

    def _units(self, gateway: GatewayView) -> list[dict[int, Unit]]:
        """Each listener's units (the main listener's first): the lines no listener names
        are the main listener's."""
        config = self.config
        named = {name for listener in config.listeners for name in listener.lines}
        groups: list[set[str]] = []
        if config.listen is not None:
            groups.append({line.config.name for line in gateway.lines} - named)
        groups += [set(listener.lines) for listener in config.listeners]
        known = {
            id(unit.drive): unit for _, server in self.servers for unit in server.units.values()
        }
        maps: dict[int, RegisterMap] = {}
        out = []
        for lines in groups:
            units = {}
            for drive in gateway.drives:
                line = drive.line
                if line.name not in lines:
                    continue
                unit = known.get(id(drive))
                if unit is None:  # a new drive (at start: every one)
                    if id(line) not in maps:
                        maps[id(line)] = RegisterMap(drive.profile, line.parameters)
                    unit = Unit(drive, maps[id(line)], {})
                units[drive.unit] = unit
            out.append(units)
        return out

    @property
    def port(self) -> int:
        """The first server's port (the real one when asked for port 0), 0 when not started."""
        return 0 if self.server is None else self.server.port

    def announce(self) -> str | None:
        """``modbus on HOST:PORT``, and a line per listener naming its lines."""
        lines = []
        first = 0 if self.config.listen is None else 1
        for i, (endpoint, server) in enumerate(self.servers):
            line = f"modbus on {endpoint.host}:{server.port}"
            if i >= first:
                names = ", ".join(sorted(self.config.listeners[i - first].lines))
                line += f" (modbus.listeners[{i - first}]: {names})"
            lines.append(line)
        return "\n".join(lines)

    def publish(self, served: ServedDrive) -> None:
        """Nothing to do: a read is served from its drive's latest view (``drive.served``)."""

    def metrics(self) -> Iterator[Metric]:
        yield from client_families(self.clients)
        if self.server is not None:
            yield from listener_families("sj300_modbus", self.server.limit)
            yield bad_frames_family(sum(server.bad_frames for _, server in self.servers))

    async def close(self) -> None:
        servers, self.servers = self.servers, []
        for _, server in servers:
            await server.close()
