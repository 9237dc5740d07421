"""The Modbus TCP northbound, running: one server for every drive of every line."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import TYPE_CHECKING

from ...profiles import DriveSnapshot
from .. import GatewayView, LineConfig, listener_families
from . import ModbusConfig
from ._clients import ClientCounters, bad_frames_family, client_families
from ._registers import RegisterMap
from ._server import ModbusServer, Unit

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["ModbusNorthbound"]

_log = logging.getLogger("sj300_async.gateway.modbus")


class ModbusNorthbound:
    """Serves the drives on Modbus TCP (a :class:`~sj300_async.gateway.Northbound`)."""

    def __init__(self, config: ModbusConfig) -> None:
        self.config = config
        #: Requests and exception replies per client, for the exporter.
        self.clients = ClientCounters()
        self.server: ModbusServer | None = None

    async def start(self, gateway: GatewayView) -> None:
        maps: dict[int, tuple[LineConfig, RegisterMap]] = {}
        units = {}
        for drive in gateway.drives:
            line = drive.line
            if id(line) not in maps:
                maps[id(line)] = (line, RegisterMap(drive.profile, line.parameters))
            units[drive.unit] = Unit(drive, maps[id(line)][1], {})
        server = ModbusServer(units, gateway, self.config.limits, self.clients)
        await server.start(self.config.listen)
        self.server = server

    @property
    def port(self) -> int:
        """The port it listens on (the real one when asked for port 0), 0 when not started."""
        return 0 if self.server is None else self.server.port

    def announce(self) -> str | None:
        return f"modbus on {self.config.listen.host}:{self.port}"

    def publish(self, snapshot: DriveSnapshot) -> None:
        """Nothing to do: reads are served from each drive's latest snapshot."""

    def metrics(self) -> Iterator[Metric]:
        yield from client_families(self.clients)
        if self.server is not None:
            yield from listener_families("sj300_modbus", self.server.limit)
            yield bad_frames_family(self.server.bad_frames)

    async def close(self) -> None:
        if self.server is not None:
            await self.server.close()
            self.server = None
