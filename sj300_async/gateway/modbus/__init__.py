"""The Modbus TCP northbound: every drive a unit id, its register map served from the cache.

Configured by ``[modbus] listen = "HOST:PORT"`` or ``--modbus HOST:PORT``.
Reads are served from each drive's latest snapshot (no read reaches a
line); writes go through the gateway's write path, and a refusal is
answered with the Modbus exception its meaning is closest to
(:data:`REFUSAL_CODES`). The register map is docs/GATEWAY.md's
(:func:`describe` generates its tables). pymodbus, the server under it, is
imported only when the northbound starts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from .. import ConfigTable, Endpoint, Flag, Northbound, SectionContext
from ._clients import MAX_CLIENTS, OTHER_CLIENT, ClientCounters, client_families
from ._registers import REFUSAL_CODES, Exc, Field, RegisterMap, describe, parameter_address

__all__ = [
    "MAX_CLIENTS",
    "NORTHBOUND",
    "OTHER_CLIENT",
    "REFUSAL_CODES",
    "ClientCounters",
    "Exc",
    "Field",
    "ModbusConfig",
    "RegisterMap",
    "client_families",
    "describe",
    "parameter_address",
]


@dataclass(frozen=True, slots=True)
class ModbusConfig:
    """``[modbus]``: where the Modbus TCP server listens."""

    listen: Endpoint


class _Spec:
    section = "modbus"
    keys = ("listen",)
    flag = Flag("--modbus", "listen", "HOST:PORT", "serve Modbus TCP there (port 0: any)")
    requires = ("pymodbus",)

    def parse(self, table: ConfigTable, context: SectionContext) -> ModbusConfig:
        return ModbusConfig(table.required_endpoint("listen"))

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, ModbusConfig)
        return [("listen", config.listen)]

    def create(self, config: object) -> Northbound:
        from ._northbound import ModbusNorthbound

        assert isinstance(config, ModbusConfig)
        return ModbusNorthbound(config)


#: The registry's entry (``sj300_async.gateway.modbus:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
