"""Writes from the plant's clients: judged, carried out through the line's arbiter, read back.

A write reaches a drive only when the configuration allows it (the line's
write grants: the parameter allow-list, ``control`` for run/stop/frequency)
and, for control, when the writing client holds the drive's lease. Values
are validated by the drive classes before anything reaches the wire. Every
write goes through the same :class:`~sj300_async.Bus` as the polls, so the
arbiter never interleaves it with them, and is confirmed by a read-back
whose value also refreshes the poll cache. Every write, refused or not, is
one line of the audit log.

The lease: a client takes a drive's lease by writing its heartbeat
register and keeps it by writing it again within ``lease_s``. Another
client's heartbeat is refused (busy) while it is held. When it lapses, the
line's ``on_lapse`` action runs at once: ``stop`` (the drive's stop, which
jumps the line's queue), ``broadcast_stop`` (every drive of the line), or
``hold`` (nothing is sent; logged). So a drive is stopped within the lease
time plus one transaction of a controller's last heartbeat. The lapse
action also runs when the gateway stops while a lease is held.

Decisions: a command's read-back is a status read; after a run command the
drive must report running (else 0x04); after a stop it may still be
decelerating, so the status read only has to succeed. A client is known by
its IP address (a SCADA that reconnects from a new port keeps its lease).
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from .. import fr700, sj300
from ..bus import Bus
from ..wire import (
    LocalProtocolError,
    NakError,
    ReadOnlyError,
    SJ300Error,
)
from ._model import LineConfig
from ._registers import Command, Exc, Heartbeat, ParameterWrite, SetFrequency, WriteRequest
from ._state import DriveState

__all__ = ["AuditLog", "Controller", "raw_of", "value_of"]

_log = logging.getLogger("sj300_async.gateway")
_audit_log = logging.getLogger("sj300_async.gateway.audit")
#: How often a lapse action is tried before the gateway gives up (each try has the bus's retries).
LAPSE_TRIES = 3
#: The highest output frequency either protocol's drives can be set to, and
#: the parameter holding a drive's own maximum (used when the line polls it).
MAX_FREQUENCY_HZ = 400.0
MAX_FREQUENCY_PARAMETER = {"sj300": "A004", "fr700": "Pr.1"}


def _info(protocol: str, code: str) -> Any:
    if protocol == "fr700":
        return fr700.fr700_parameter_info(code)
    return sj300.parameter_info(code)


def raw_of(protocol: str, code: str, value: float) -> int:
    """A parameter's value in its unit as the integer the drive holds (its increment count)."""
    info = _info(protocol, code)
    try:
        return int(info.to_raw(value))
    except LocalProtocolError:  # outside the catalogue's range: the drive holds it anyway
        return round(value * int(info.scale))


def value_of(protocol: str, code: str, raw: int) -> float:
    """The value in its unit of a parameter's raw integer."""
    return float(_info(protocol, code).from_raw(raw))


class AuditLog:
    """Every write: who, which drive, what, old -> new, and the result.

    Logged at INFO to ``sj300_async.gateway.audit`` and, when a path is
    given, appended to it as one JSON object per line (flushed each time:
    an audit log that loses its last lines in a crash is not one).
    """

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self._file = None if path is None else path.open("a", encoding="utf-8")
        #: Records written, by result ("ok", or the refusal's name).
        self.counts: dict[str, int] = {}

    def record(
        self, client: str, state: DriveState, what: str, old: object, new: object, result: str
    ) -> None:
        self.counts[result] = self.counts.get(result, 0) + 1
        _audit_log.info(
            "client %s line %s node %d (unit %d): %s %s -> %s: %s",
            client, state.line, state.node, state.unit, what, old, new, result,
        )  # fmt: skip
        if self._file is not None:
            entry = {
                "time": time.time(),
                "client": client,
                "line": state.line,
                "node": state.node,
                "unit": state.unit,
                "what": what,
                "old": old,
                "new": new,
                "result": result,
            }
            self._file.write(json.dumps(entry) + "\n")
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _refusal(exc: BaseException) -> Exc:
    """The Modbus exception for a failed drive call."""
    if isinstance(exc, ReadOnlyError):
        return Exc.ILLEGAL_FUNCTION
    if isinstance(exc, LocalProtocolError):
        return Exc.ILLEGAL_VALUE  # validated before the wire: nothing was sent
    if isinstance(exc, NakError):
        return Exc.DEVICE_FAILURE
    return Exc.TARGET_FAILED  # time-out, corrupted answers, link down, bus closed


class Controller:
    """The writes and leases of one line (see the module docstring)."""

    def __init__(self, config: LineConfig, bus: Bus[Any, Any], audit: AuditLog) -> None:
        self.config = config
        self.bus = bus
        self.audit = audit
        self._locks: dict[int, asyncio.Lock] = {}
        self._timers: dict[int, asyncio.TimerHandle] = {}
        self._lapses: set[asyncio.Task[None]] = set()
        #: Lapse actions run (each counted once, whatever its result).
        self.lapses = 0

    # -- writes ------------------------------------------------------------------

    async def write(self, client: str, state: DriveState, request: WriteRequest) -> Exc | None:
        """Judge and carry out one write; None when it succeeded, else the refusal."""
        refusal = self._judge(client, state, request)
        if refusal is not None:
            what, old, new = self._describe(state, request)
            self.audit.record(client, state, what, old, new, f"refused: {refusal.name}")
            return refusal
        if isinstance(request, Heartbeat):
            self._renew(client, state)
            return None
        lock = self._locks.setdefault(state.node, asyncio.Lock())
        async with lock:  # a write and its read-back stay together
            what, old, new = self._describe(state, request)
            try:
                confirmed = await self._carry_out(state, request)
            except SJ300Error as exc:
                refusal = _refusal(exc)
                self.audit.record(client, state, what, old, new, f"{refusal.name}: {exc}")
                return refusal
            result = "ok" if confirmed else "DEVICE_FAILURE: the read-back differs"
            self.audit.record(client, state, what, old, new, result)
            return None if confirmed else Exc.DEVICE_FAILURE

    def _judge(self, client: str, state: DriveState, request: WriteRequest) -> Exc | None:
        now = asyncio.get_running_loop().time()
        if isinstance(request, ParameterWrite):
            allowed = request.code in self.config.writable_parameters(state.node)
            return None if allowed else Exc.ILLEGAL_FUNCTION
        if not self.config.control_allowed(state.node):
            return Exc.ILLEGAL_FUNCTION
        lease = state.lease
        if lease.held(now) and not lease.held_by(client, now):
            return Exc.DEVICE_BUSY
        if not isinstance(request, Heartbeat) and not lease.held_by(client, now):
            return Exc.ILLEGAL_FUNCTION  # control without the lease
        if isinstance(request, SetFrequency) and not 0 <= request.hz <= self._max_hz(state):
            return Exc.ILLEGAL_VALUE
        return None

    def _max_hz(self, state: DriveState) -> float:
        """The drive's maximum frequency: its own setting when polled, else the protocol's."""
        code = MAX_FREQUENCY_PARAMETER.get(state.protocol)
        raw = None if code is None else state.parameters.get(code)
        if code is None or raw is None:
            return MAX_FREQUENCY_HZ
        return min(MAX_FREQUENCY_HZ, value_of(state.protocol, code, raw))

    def _describe(self, state: DriveState, request: WriteRequest) -> tuple[str, object, object]:
        if isinstance(request, Heartbeat):
            return "heartbeat", state.lease.holder, "renewed"
        if isinstance(request, Command):
            names = ("stop", "run forward", "run reverse")
            return "command", None, names[request.direction]
        if isinstance(request, SetFrequency):
            return "set frequency (Hz)", state.set_frequency_hz, request.hz
        old_raw = state.parameters.get(request.code)
        protocol = state.protocol
        old = None if old_raw is None else value_of(protocol, request.code, old_raw)
        return f"parameter {request.code}", old, value_of(protocol, request.code, request.raw)

    async def _carry_out(self, state: DriveState, request: WriteRequest) -> bool:
        drive = self.bus.drive(state.node)
        loop = asyncio.get_running_loop()
        if isinstance(request, Command):
            calls: tuple[Callable[[], Awaitable[None]], ...] = (
                drive.stop,
                drive.run_forward,
                drive.run_reverse,
            )
            await calls[request.direction]()
            status = await drive.read_status()
            state.status, state.status_at = status, loop.time()
            return request.direction == 0 or bool(state.running)
        if isinstance(request, SetFrequency):
            await drive.set_frequency(request.hz)
            if state.protocol == "fr700":
                read_back = float(await drive.read_set_frequency())
            else:
                read_back = float(await drive.read_parameter("F001"))
            state.set_frequency_hz, state.set_frequency_at = read_back, loop.time()
            return abs(read_back - request.hz) < 0.005
        assert isinstance(request, ParameterWrite)
        await drive.write_parameter(
            request.code, value_of(state.protocol, request.code, request.raw)
        )
        raw = int(await drive.read_parameter_raw(request.code))
        state.parameters[request.code] = raw
        state.parameters_at[request.code] = loop.time()
        return raw == request.raw

    # -- the lease ---------------------------------------------------------------

    def _renew(self, client: str, state: DriveState) -> None:
        loop = asyncio.get_running_loop()
        lease = state.lease
        if lease.holder != client:
            _log.info("line %s node %d: %s takes the control lease", state.line, state.node, client)
        lease.holder = client
        lease.expires_at = loop.time() + lease.duration_s
        old = self._timers.pop(state.node, None)
        if old is not None:
            old.cancel()
        self._timers[state.node] = loop.call_at(lease.expires_at, self._expire, state)

    def _expire(self, state: DriveState) -> None:
        self._timers.pop(state.node, None)
        holder = state.lease.holder
        if holder is None:
            return
        state.lease.holder = None
        _log.warning(
            "line %s node %d: the control lease of %s lapsed: %s",
            state.line, state.node, holder, self.config.on_lapse,
        )  # fmt: skip
        task = asyncio.get_running_loop().create_task(self._lapse(holder, state))
        self._lapses.add(task)
        task.add_done_callback(self._lapses.discard)

    async def _lapse(self, holder: str, state: DriveState) -> None:
        self.lapses += 1
        action = self.config.on_lapse
        if action == "hold":
            self.audit.record(holder, state, "lease lapsed", holder, None, "hold: nothing sent")
            return
        for attempt in range(1, LAPSE_TRIES + 1):
            try:
                if action == "broadcast_stop":
                    await self.bus.broadcast.stop()
                else:
                    await self.bus.drive(state.node).stop()
            except SJ300Error as exc:
                _log.error("line %s node %d: lapse %s failed (try %d of %d): %s",
                           state.line, state.node, action, attempt, LAPSE_TRIES, exc)  # fmt: skip
                result = f"{action} failed: {exc}"
                continue
            result = f"{action}: ok"
            break
        self.audit.record(holder, state, "lease lapsed", holder, None, result)

    async def close(self, states: list[DriveState]) -> None:
        """Stop: every lease still held lapses now (its action runs), then wait for all lapses."""
        for node, timer in list(self._timers.items()):
            timer.cancel()
            state = next(s for s in states if s.node == node)
            self._expire(state)
        self._timers.clear()
        if self._lapses:
            await asyncio.gather(*self._lapses, return_exceptions=True)

    @property
    def pending_lapses(self) -> int:
        """Lapse actions still running."""
        return len(self._lapses)
