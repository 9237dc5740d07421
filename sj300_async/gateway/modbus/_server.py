"""Modbus TCP: pymodbus's server, with the gateway's register map as its datastore.

pymodbus (the ``gateway`` extra) parses and frames Modbus TCP, calls its
datastore for each request and answers. The datastore here is
:class:`GatewayDatastore`: per unit id, the drive's
:class:`~._registers.RegisterMap` over its latest snapshot for reads
(served from the gateway's cache: no read reaches the line), and the
gateway's write path for writes (which do, through the line's arbiter);
a refusal is answered with :data:`~._registers.REFUSAL_CODES`' exception.

Coupling to pymodbus, on purpose and pinned (``pymodbus>=3.10,<4``): a
``ModbusServerContext`` subclass whose ``async_getValues`` /
``async_setValues`` return a list or an ``ExcCodes`` (the 3.x datastore
interface, which lets a datastore answer any exception code, 0x0B
included), and a ``ServerRequestHandler`` subclass that knows the client
it serves (its IP address: the audit log's "who", the lease holder, and
the per-client metrics). tests/gateway checks both with pymodbus's client
and with mbpoll.
"""

from __future__ import annotations

import asyncio
import contextvars
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler

from .. import Endpoint, GatewayDrive, GatewayView, WriteResult
from ._clients import ClientCounters
from ._registers import REFUSAL_CODES, EncodingCache, Exc, RegisterMap

__all__ = ["GatewayDatastore", "ModbusGatewayServer", "Unit", "serve_modbus"]

_log = logging.getLogger("sj300_async.gateway.modbus")

#: The client the current request came from (set by the request handler).
_CLIENT: contextvars.ContextVar[str] = contextvars.ContextVar("modbus_client", default="?")
#: The values a function-6 write just set: pymodbus reads the register back
#: to build its answer, which must echo the request (a heartbeat register
#: reads 1, not what was written to it).
_ECHO: contextvars.ContextVar[list[int] | None] = contextvars.ContextVar(
    "modbus_echo", default=None
)

_READ_FUNCTIONS = frozenset((3, 4, 23))
_WRITE_FUNCTIONS = frozenset((6, 16, 23))


@dataclass(frozen=True, slots=True)
class Unit:
    """What a unit id stands for: a drive, its line's map, and its encodings."""

    drive: GatewayDrive
    registers: RegisterMap
    cache: EncodingCache


class GatewayDatastore(ModbusServerContext):
    """pymodbus's datastore interface over the gateway's units (see the module docstring)."""

    def __init__(self, units: dict[int, Unit], gateway: GatewayView) -> None:
        # No super().__init__(): that builds pymodbus's own register blocks.
        self.units = units
        self.gateway = gateway
        self.stale_after_s = gateway.config.stale_after_s
        self.old_simulator = True  # pymodbus: "call my async_getValues / async_setValues"
        self.simdevices = []

    def device_ids(self) -> list[int]:
        return sorted(self.units)

    async def async_getValues(
        self, device_id: int, func_code: int, address: int, count: int = 1
    ) -> list[int] | list[bool] | ExcCodes:
        unit = self.units.get(device_id)
        if unit is None:
            return ExcCodes.GATEWAY_PATH_UNAVIABLE
        if func_code == 6 and (echo := _ECHO.get()) is not None:
            return echo
        if func_code not in _READ_FUNCTIONS:
            return ExcCodes.ILLEGAL_FUNCTION  # coils and discrete inputs: none here
        now = asyncio.get_running_loop().time()
        result = unit.registers.read(
            unit.drive, address, count, now, self.stale_after_s, unit.cache
        )
        return ExcCodes(int(result)) if isinstance(result, Exc) else result

    async def async_setValues(
        self,
        device_id: int,
        func_code: int,
        address: int,
        values: Sequence[int] | Sequence[bool],
    ) -> ExcCodes | None:
        unit = self.units.get(device_id)
        if unit is None:
            return ExcCodes.GATEWAY_PATH_UNAVIABLE
        if func_code not in _WRITE_FUNCTIONS:
            return ExcCodes.ILLEGAL_FUNCTION
        words = [int(v) for v in values]
        request = unit.registers.decode_write(address, words)
        if isinstance(request, WriteResult):  # no write at all: audited here, refused
            self.gateway.refused(_CLIENT.get(), unit.drive, f"register {address}", words, request)
            result = request
        else:
            result = await self.gateway.write(_CLIENT.get(), unit.drive, request)
        if result.refusal is not None:
            return ExcCodes(int(REFUSAL_CODES[result.refusal]))
        if func_code == 6:
            _ECHO.set(words)
        return None


class _ClientHandler(ServerRequestHandler):
    """pymodbus's per-connection handler, knowing its client (see the module docstring)."""

    counters: ClientCounters

    def _client(self) -> str:
        transport = getattr(self, "transport", None)
        peer = transport.get_extra_info("peername") if transport is not None else None
        return str(peer[0]) if peer else "?"

    async def handle_request(self) -> None:
        client = self._client()
        self.counters.request(client)
        token = _CLIENT.set(client)
        echo = _ECHO.set(None)
        try:
            await super().handle_request()  # type: ignore[no-untyped-call]
        finally:
            _ECHO.reset(echo)
            _CLIENT.reset(token)

    def server_send(self, pdu: ModbusPDU | None, addr: Any) -> None:
        if isinstance(pdu, ExceptionResponse):
            self.counters.exception(_CLIENT.get(), int(pdu.exception_code))
        super().server_send(pdu, addr)  # type: ignore[no-untyped-call]


class ModbusGatewayServer(ModbusTcpServer):
    """pymodbus's TCP server with the client-aware handler."""

    def __init__(
        self, datastore: GatewayDatastore, endpoint: Endpoint, counters: ClientCounters
    ) -> None:
        super().__init__(datastore, address=(endpoint.host, endpoint.port))
        self.counters = counters

    def callback_new_connection(self) -> _ClientHandler:
        handler = _ClientHandler(  # type: ignore[no-untyped-call]
            self, self.trace_packet, self.trace_pdu, self.trace_connect
        )
        handler.counters = self.counters
        return handler

    @property
    def port(self) -> int:
        """The port it listens on (the real one when asked for port 0)."""
        sockets = getattr(self.transport, "sockets", None)
        return int(sockets[0].getsockname()[1]) if sockets else 0


async def serve_modbus(
    units: dict[int, Unit], gateway: GatewayView, endpoint: Endpoint, counters: ClientCounters
) -> ModbusGatewayServer:
    """Start serving *units* on *endpoint*; the server runs until its ``shutdown()``."""
    server = ModbusGatewayServer(GatewayDatastore(units, gateway), endpoint, counters)
    await server.serve_forever(background=True)
    _log.info("Modbus TCP on %s:%d, units %s", endpoint.host, server.port, sorted(units))
    return server
