"""The gateway process: open the lines, poll them, serve Modbus TCP and metrics, stop cleanly.

:class:`Gateway` is an async context manager. Entering it opens every line
(one :class:`~sj300_async.Bus` each, the only master on its wire), starts a
:class:`~sj300_async.Poller` per line with the line's poll plan, feeds each
sample into the drive's :class:`~._state.DriveState`, and serves: Modbus
TCP (:mod:`._modbus`), /metrics + /healthz (:mod:`._http`) and MQTT
(:mod:`._mqtt`: each sample is handed to the bridge after the state took
it). Nothing is written to a drive on start-up: the poller only reads, and
writes come only from clients.

Leaving it (SIGTERM in ``sj300 gateway``) stops in this order: the MQTT
bridge (no MQTT command starts any more; it says "offline" and
disconnects), the Modbus server (so no client write starts any more), the
leases still held (their
lapse action runs and is waited for: the one case a command is sent on
the way out), the trip-history readers and pollers, the HTTP server, the
lines, the audit log.

The trip history (SJ300) is not part of the poll cycle: 446 characters
would take most of a 19200-baud cycle. Each drive's is read every
``trips_interval_s`` and as soon as its status shows a trip.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from .._open import open_bus
from .._poller import Poller, Read, Sample
from ..bus import Bus
from ..bus._capture import CaptureFile
from ..wire import SJ300Error
from ._control import AuditLog, Controller, raw_of
from ._http import serve_http
from ._metrics import ClientCounters, DriveView, LineView, line_problems, make_registry
from ._modbus import ModbusGatewayServer, Unit, serve_modbus
from ._model import GatewayConfig, LineConfig
from ._mqtt import MqttBridge
from ._registers import RegisterMap
from ._state import DriveState, Lease

__all__ = ["Gateway", "GatewayLine"]

_log = logging.getLogger("sj300_async.gateway")


@dataclass(slots=True)
class GatewayLine:
    """One line while the gateway runs: its bus, poller, drives and controller."""

    config: LineConfig
    bus: Bus[Any, Any]
    poller: Poller
    controller: Controller
    registers: RegisterMap
    states: dict[int, DriveState]


class Gateway:
    """The whole gateway (see the module docstring)."""

    def __init__(self, config: GatewayConfig, *, capture: str | None = None) -> None:
        self.config = config
        #: Where every line's frames go (``--capture``: one pcapng, one interface
        #: per line in the configuration's order), or None.
        self.capture_path = capture
        self._capture: CaptureFile | None = None
        self.lines: list[GatewayLine] = []
        self.clients = ClientCounters()
        self.audit = AuditLog(config.audit_log)
        self.modbus: ModbusGatewayServer | None = None
        self.http: asyncio.Server | None = None
        self.mqtt: MqttBridge | None = None
        self._stack = contextlib.AsyncExitStack()
        self._tasks: list[asyncio.Task[None]] = []

    # -- what the servers read -------------------------------------------------

    @property
    def units(self) -> dict[int, Unit]:
        """Every drive by its Modbus unit id."""
        return {
            state.unit: Unit(state, line.registers, line.controller)
            for line in self.lines
            for state in line.states.values()
        }

    def state(self, line: str, node: int) -> DriveState:
        """The state of *node* on the line named *line*."""
        for each in self.lines:
            if each.config.name == line:
                return each.states[node]
        raise KeyError(line)

    # MetricsSource
    def line_views(self) -> Iterator[LineView]:
        for line in self.lines:
            yield LineView(line.config.name, line.bus)

    def drives(self) -> Iterator[DriveView]:
        now = asyncio.get_running_loop().time()
        for line in self.lines:
            for state in line.states.values():
                monitor = state.monitor
                fresh = monitor is not None and now - state.monitor_at <= self.config.stale_after_s
                yield DriveView(
                    line=state.line,
                    node=state.node,
                    online=state.online,
                    sample_age_s=state.sample_age_s(now),
                    output_frequency_hz=monitor.output_frequency_hz if fresh and monitor else None,
                    output_current_a=monitor.output_current_a if fresh and monitor else None,
                )

    def problems(self) -> list[str]:
        """Why the gateway is not healthy (empty: every line is up)."""
        return line_problems(_Source(self))

    # -- running -----------------------------------------------------------------

    async def __aenter__(self) -> Gateway:
        try:
            if self.capture_path is not None:
                self._capture = CaptureFile(self.capture_path)
                self._stack.callback(self._capture.close)
            for config in self.config.lines:
                self.lines.append(await self._open_line(config))
            if self.config.mqtt is not None:  # before the pollers: it gets the first samples
                self.mqtt = MqttBridge(
                    self.config.mqtt, self.config.gateway_id, self.lines, self.config.stale_after_s
                )
                self.mqtt.start()
            for line in self.lines:
                await self._stack.enter_async_context(line.poller)
                if line.config.protocol == "sj300" and line.config.trips_interval_s > 0:
                    self._tasks.append(asyncio.create_task(self._read_trips(line)))
            if self.config.modbus is not None:
                self.modbus = await serve_modbus(
                    self.units, self.config.modbus, self.config.stale_after_s, self.clients
                )
            if self.config.metrics is not None:
                registry = make_registry(
                    _Source(self),
                    self.clients,
                    lambda: None if self.mqtt is None else self.mqtt.stats,
                )
                self.http = await serve_http(self.config.metrics, registry, self.problems)
        except BaseException:
            await self._shutdown()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._shutdown()

    async def _open_line(self, config: LineConfig) -> GatewayLine:
        bus: Bus[Any, Any] = await self._stack.enter_async_context(
            open_bus(
                config.url,
                protocol=config.protocol,
                timeout=config.timeout_s,
                capture=self._capture,
            )
        )
        reads: tuple[Read, ...] = tuple(r for r in config.reads if r in ("status", "monitor"))  # type: ignore[misc]
        poller = Poller(interval_s=config.interval_s, reads=reads, parameters=config.parameters)
        poller.add(bus, config.nodes)
        states = {
            node: DriveState(
                config.name, node, config.unit(node), config.protocol, Lease(config.lease_s)
            )
            for node in config.nodes
        }
        line = GatewayLine(
            config,
            bus,
            poller,
            Controller(config, bus, self.audit),
            RegisterMap(config.protocol, config.parameters),
            states,
        )
        poller.on_sample(lambda sample: self._on_sample(line, sample))
        _log.info("line %s: %s, %s %s", config.name, config.url, bus.dialect.node_noun,
                  ",".join(map(str, config.nodes)))  # fmt: skip
        return line

    def _on_sample(self, line: GatewayLine, sample: Sample) -> None:
        protocol = line.config.protocol
        raw = {code: raw_of(protocol, code, value) for code, value in sample.parameters.items()}
        state = line.states[sample.node]
        state.update(sample, raw)
        if self.mqtt is not None:
            self.mqtt.on_sample(state, sample)

    async def _read_trips(self, line: GatewayLine) -> None:
        loop = asyncio.get_running_loop()
        seen_trip: dict[int, bool] = {}
        while True:
            await asyncio.sleep(max(line.config.interval_s, 0.05))
            for state in line.states.values():
                if not state.online:
                    continue
                tripped = bool(state.tripped)
                new_trip = tripped and not seen_trip.get(state.node, False)
                due = loop.time() - state.trips_at >= line.config.trips_interval_s
                if not (new_trip or due):
                    continue
                try:
                    state.trips = await line.bus.drive(state.node).read_trip_history()
                except SJ300Error as exc:
                    _log.debug("line %s node %d: trip history: %s", state.line, state.node, exc)
                    continue
                state.trips_at = loop.time()
                seen_trip[state.node] = tripped

    async def _shutdown(self) -> None:
        if self.mqtt is not None:
            await self.mqtt.close()
            self.mqtt = None
        if self.modbus is not None:
            await self.modbus.shutdown()  # type: ignore[no-untyped-call]
            self.modbus = None
        for line in self.lines:
            await line.controller.close(list(line.states.values()))
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()
        if self.http is not None:
            self.http.close()
            await self.http.wait_closed()
            self.http = None
        await self._stack.aclose()
        self.audit.close()


class _Source:
    """The gateway as the metrics collector sees it."""

    def __init__(self, gateway: Gateway) -> None:
        self._gateway = gateway

    def lines(self) -> Iterable[LineView]:
        return list(self._gateway.line_views())

    def drives(self) -> Iterable[DriveView]:
        return list(self._gateway.drives())
