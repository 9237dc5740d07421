"""The Modbus TCP northbound, running: one server for every drive of every line."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import TYPE_CHECKING

from ...profiles import DriveSnapshot
from .. import GatewayView, LineConfig
from . import ModbusConfig
from ._clients import ClientCounters, client_families
from ._registers import RegisterMap

if TYPE_CHECKING:
    from prometheus_client.core import Metric

    from ._server import ModbusGatewayServer

__all__ = ["ModbusNorthbound"]

_log = logging.getLogger("sj300_async.gateway.modbus")


class ModbusNorthbound:
    """Serves the drives on Modbus TCP (a :class:`~sj300_async.gateway.Northbound`)."""

    def __init__(self, config: ModbusConfig) -> None:
        self.config = config
        #: Requests and exception replies per client, for the exporter.
        self.clients = ClientCounters()
        self.server: ModbusGatewayServer | None = None

    async def start(self, gateway: GatewayView) -> None:
        from ._server import Unit, serve_modbus

        maps: dict[int, tuple[LineConfig, RegisterMap]] = {}
        units = {}
        for drive in gateway.drives:
            line = drive.line
            if id(line) not in maps:
                maps[id(line)] = (line, RegisterMap(drive.profile, line.parameters))
            units[drive.unit] = Unit(drive, maps[id(line)][1], {})
        self.server = await serve_modbus(units, gateway, self.config.listen, self.clients)

    @property
    def port(self) -> int:
        """The port it listens on (the real one when asked for port 0), 0 when not started."""
        return 0 if self.server is None else self.server.port

    def announce(self) -> str | None:
        return f"modbus on {self.config.listen.host}:{self.port}"

    def publish(self, snapshot: DriveSnapshot) -> None:
        """Nothing to do: reads are served from each drive's latest snapshot."""

    def metrics(self) -> Iterator[Metric]:
        return client_families(self.clients)

    async def close(self) -> None:
        if self.server is not None:
            await self.server.shutdown()  # type: ignore[no-untyped-call]
            self.server = None
