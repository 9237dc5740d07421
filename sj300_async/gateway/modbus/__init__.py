"""The Modbus TCP northbound: every drive a unit id, its register map served from the cache.

Configured by ``[modbus] listen = "HOST:PORT"`` or ``--modbus HOST:PORT``,
and the listener's limits ``max_connections`` (default 64) and
``idle_timeout_s`` (default 60). Reads are served from each drive's latest
snapshot (no read reaches a line); writes go through the gateway's write
path, and a refusal is answered with the Modbus exception its meaning is
closest to (:data:`REFUSAL_CODES`). The register map is docs/GATEWAY.md's
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
)
from ._clients import MAX_CLIENTS, OTHER_CLIENT, ClientCounters, client_families
from ._framing import Exc
from ._registers import REFUSAL_CODES, Field, RegisterMap, describe, parameter_address

__all__ = [
    "DEFAULT_LIMITS",
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


#: The listener's limits when ``[modbus]`` sets none: 64 connections (a plant's SCADA,
#: HMIs and engineering tools, with room to spare, and far below a small descriptor
#: limit), closed after 60 s without a request (SCADA polls every few seconds).
DEFAULT_LIMITS: Final = ListenerLimits(max_connections=64, idle_timeout_s=60.0)


@dataclass(frozen=True, slots=True)
class ModbusConfig:
    """``[modbus]``: where the Modbus TCP server listens, and its limits."""

    listen: Endpoint
    limits: ListenerLimits = DEFAULT_LIMITS


class _Spec:
    section = "modbus"
    keys = ("listen", *LIMIT_KEYS)
    flag = Flag("--modbus", "listen", "HOST:PORT", "serve Modbus TCP there (port 0: any)")
    requires = ()
    #: Drives are Modbus units: the configuration checks every unit id (1..247, unique).
    unit_ids = True

    def parse(self, table: ConfigTable, context: SectionContext) -> ModbusConfig:
        return ModbusConfig(table.required_endpoint("listen"), DEFAULT_LIMITS.parse(table))

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, ModbusConfig)
        return [("listen", config.listen)]

    def create(self, config: object) -> Northbound:
        from ._northbound import ModbusNorthbound

        assert isinstance(config, ModbusConfig)
        return ModbusNorthbound(config)


#: The registry's entry (``sj300_async.gateway.modbus:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
