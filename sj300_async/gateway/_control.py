"""Writes from the plant's clients: judged, carried out through the line's arbiter, read back.

A write reaches a drive only when the configuration allows it (the line's
write grants: the parameter allow-list, ``control`` for run/stop/frequency)
and, for control, when the writing client holds the drive's lease. Values
are validated by the drive classes before anything reaches the wire. Every
write goes through the same :class:`~sj300_async.Bus` as the polls, so the
arbiter never interleaves it with them, and is confirmed by a read-back
whose value also goes into the drive's readings (and so into its next
snapshot, built at once). Every write but a granted heartbeat is one line
of the audit log, with the neutral result (:class:`~._writes.WriteResult`).

The lease: a client takes a drive's lease by a heartbeat and keeps it by
another within ``lease_s``. Another client's heartbeat is refused (lease
held) while it is held. When it lapses, the line's ``on_lapse`` action runs
at once: ``stop`` (the drive's stop, which jumps the line's queue),
``broadcast_stop`` (every drive of the line), or ``hold`` (nothing is sent;
logged). So a drive is stopped within the lease time plus one transaction
of a controller's last heartbeat. The lapse action also runs when the
gateway stops while a lease is held.

Decisions: a command's read-back is a status read; after a run command the
drive must report running (else "not confirmed"); after a stop it may still
be decelerating, so the status read only has to succeed. The monitor is
read back too (its failure does not fail the command): the state shown
right after a command pairs its status with a direction and a frequency
read after it, not before. The set frequency
is read back the way the drive's profile says (SJ300: F001). A client is
known by the name its northbound gives it (a Modbus client by its IP
address: a SCADA that reconnects from a new port keeps its lease).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from typing import Any, Final

from ..bus import Bus
from ..wire import Direction, LocalProtocolError, NakError, ReadOnlyError, SJ300Error
from ._audit import AuditLog
from ._drive import GatewayDrive
from ._model import LineConfig
from ._writes import (
    DONE,
    Heartbeat,
    ParameterWrite,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
)

__all__ = ["Controller"]

_log = logging.getLogger("sj300_async.gateway")
#: How often a lapse action is tried before the gateway gives up (each try has the bus's retries).
LAPSE_TRIES: Final = 3
_COMMAND_NAMES: Final = {
    Direction.STOP: "stop",
    Direction.FORWARD: "run forward",
    Direction.REVERSE: "run reverse",
}


def _failure(exc: SJ300Error) -> WriteResult:
    """The neutral result of a drive call that raised."""
    if isinstance(exc, ReadOnlyError):
        return WriteResult(Refusal.NOT_ALLOWED, "the line is read-only")
    if isinstance(exc, LocalProtocolError):  # validated before the wire: nothing was sent
        return WriteResult(Refusal.INVALID_VALUE, str(exc))
    if isinstance(exc, NakError):
        return WriteResult(Refusal.DRIVE_REFUSED, str(exc))
    return WriteResult(Refusal.NO_ANSWER, str(exc))  # time-out, corrupted answers, link down


class Controller:
    """The writes and leases of one line (see the module docstring).

    Args:
        changed: called with a drive whose readings a write's read-back
            changed (the gateway rebuilds and publishes its snapshot).
    """

    def __init__(
        self,
        config: LineConfig,
        bus: Bus[Any, Any],
        audit: AuditLog,
        changed: Callable[[GatewayDrive], None] = lambda drive: None,
    ) -> None:
        self.config = config
        self.bus = bus
        self.audit = audit
        self._changed = changed
        self._locks: dict[int, asyncio.Lock] = {}
        self._timers: dict[int, asyncio.TimerHandle] = {}
        self._lapses: set[asyncio.Task[None]] = set()
        #: Lapse actions run (each counted once, whatever its result).
        self.lapses = 0

    # -- writes ------------------------------------------------------------------

    async def write(
        self,
        client: str,
        drive: GatewayDrive,
        request: WriteRequest,
        *,
        connection: str | None = None,
    ) -> WriteResult:
        """Judge and carry out one write; its result (audited)."""
        refused = self._judge(client, drive, request)
        if refused is not None:
            self.audit.write(client, drive, *self._describe(drive, request), refused)
            return refused
        if isinstance(request, Heartbeat):
            self._renew(client, drive)
            return DONE
        lock = self._locks.setdefault(drive.node, asyncio.Lock())
        async with lock:  # a write and its read-back stay together
            what, old, new = self._describe(drive, request)
            try:
                confirmed = await self._carry_out(drive, request)
            except SJ300Error as exc:
                result = _failure(exc)
            else:
                result = (
                    DONE
                    if confirmed
                    else WriteResult(Refusal.NOT_CONFIRMED, "the drive read back something else")
                )
            self.audit.write(client, drive, what, old, new, result)
            return result

    def _judge(self, client: str, drive: GatewayDrive, request: WriteRequest) -> WriteResult | None:
        now = asyncio.get_running_loop().time()
        if isinstance(request, ParameterWrite):
            if request.code in self.config.writable_parameters(drive.node):
                return None
            return WriteResult(
                Refusal.NOT_ALLOWED,
                f"the configuration does not allow writing {request.code} to this drive",
            )
        if not self.config.control_allowed(drive.node):
            return WriteResult(
                Refusal.NOT_ALLOWED, "the configuration does not allow control of this drive"
            )
        lease = drive.lease
        if lease.held(now) and not lease.held_by(client, now):
            return WriteResult(
                Refusal.LEASE_HELD, f"another client ({lease.holder}) holds the control lease"
            )
        if not isinstance(request, Heartbeat) and not lease.held_by(client, now):
            return WriteResult(Refusal.NO_LEASE, "take the control lease first")
        if isinstance(request, SetFrequency):
            highest = self._max_hz(drive)
            if not 0 <= request.hz <= highest:
                return WriteResult(
                    Refusal.INVALID_VALUE,
                    f"{request.hz:g} Hz is outside 0..{highest:g} Hz (the drive's maximum)",
                )
        return None

    def _max_hz(self, drive: GatewayDrive) -> float:
        """The drive's maximum frequency: its own setting when polled, else its protocol's."""
        profile = drive.profile
        code = profile.max_frequency_parameter
        raw = None if code is None else drive.readings.parameters.get(code)
        if code is None or raw is None:
            return profile.max_frequency_hz
        return min(profile.max_frequency_hz, float(profile.parameters.spec(code).from_raw(raw)))

    def _describe(self, drive: GatewayDrive, request: WriteRequest) -> tuple[str, object, object]:
        if isinstance(request, Heartbeat):
            return "heartbeat", drive.lease.holder, "renewed"
        if isinstance(request, RunCommand):
            return "command", None, _COMMAND_NAMES.get(request.direction, str(request.direction))
        if isinstance(request, SetFrequency):
            return "set frequency (Hz)", drive.readings.set_frequency_hz, request.hz
        spec = drive.profile.parameters.spec(request.code)
        old_raw = drive.readings.parameters.get(request.code)
        old = None if old_raw is None else float(spec.from_raw(old_raw))
        return f"parameter {request.code}", old, float(spec.from_raw(request.raw))

    async def _carry_out(self, drive: GatewayDrive, request: WriteRequest) -> bool:
        target = self.bus.drive(drive.node)
        loop = asyncio.get_running_loop()
        readings, profile = drive.readings, drive.profile
        if isinstance(request, RunCommand):
            calls: dict[Direction, Callable[[], Awaitable[None]]] = {
                Direction.STOP: target.stop,
                Direction.FORWARD: target.run_forward,
                Direction.REVERSE: target.run_reverse,
            }
            await calls[request.direction]()
            readings.set_status(await target.read_status(), loop.time(), profile)
            view = readings.status_view
            confirmed = request.direction == Direction.STOP or bool(
                view is not None and view.running
            )
            # The monitor too, so that the state published now does not pair the new
            # status with the direction of a monitor read before the command (SJ300).
            try:
                readings.set_monitor(await target.read_monitor(), loop.time(), profile)
            except SJ300Error as exc:  # the status confirmed it: the next poll catches up
                _log.debug("line %s node %d: no monitor read-back: %s", *drive.key, exc)
            self._changed(drive)
            return confirmed
        if isinstance(request, SetFrequency):
            await target.set_frequency(request.hz)
            read_back = await profile.read_set_frequency(target)
            readings.set_frequency(read_back, loop.time())
            self._changed(drive)
            return abs(read_back - request.hz) < 0.005
        assert isinstance(request, ParameterWrite)
        spec = profile.parameters.spec(request.code)
        await target.write_parameter(request.code, spec.from_raw(request.raw))
        raw = int(await target.read_parameter_raw(request.code))
        readings.set_parameter(request.code, raw, loop.time())
        self._changed(drive)
        return raw == request.raw

    # -- the lease ---------------------------------------------------------------

    def disconnected(self, connection: str) -> None:
        """*connection* closed: its connection-scoped leases lapse now (not yet: see issue 26)."""

    def _renew(self, client: str, drive: GatewayDrive) -> None:
        loop = asyncio.get_running_loop()
        lease = drive.lease
        if lease.holder != client:
            _log.info("line %s node %d: %s takes the control lease", drive.line.name, drive.node,
                      client)  # fmt: skip
        lease.holder = client
        lease.expires_at = loop.time() + lease.duration_s
        old = self._timers.pop(drive.node, None)
        if old is not None:
            old.cancel()
        self._timers[drive.node] = loop.call_at(lease.expires_at, self._expire, drive)

    def _expire(self, drive: GatewayDrive) -> None:
        self._timers.pop(drive.node, None)
        holder = drive.lease.holder
        if holder is None:
            return
        drive.lease.holder = None
        _log.warning(
            "line %s node %d: the control lease of %s lapsed: %s",
            drive.line.name, drive.node, holder, self.config.on_lapse,
        )  # fmt: skip
        task = asyncio.get_running_loop().create_task(self._lapse(holder, drive))
        self._lapses.add(task)
        task.add_done_callback(self._lapses.discard)

    async def _lapse(self, holder: str, drive: GatewayDrive) -> None:
        self.lapses += 1
        action = self.config.on_lapse
        if action == "hold":
            self.audit.record(holder, drive, "lease lapsed", holder, None, "hold: nothing sent")
            return
        result = f"{action} failed"
        for attempt in range(1, LAPSE_TRIES + 1):
            try:
                if action == "broadcast_stop":
                    await self.bus.broadcast.stop()
                else:
                    await self.bus.drive(drive.node).stop()
            except SJ300Error as exc:
                _log.error(
                    "line %s node %d: lapse %s failed (try %d of %d): %s",
                    drive.line.name, drive.node, action, attempt, LAPSE_TRIES, exc,
                )  # fmt: skip
                result = f"{action} failed: {exc}"
                continue
            result = f"{action}: ok"
            break
        self.audit.record(holder, drive, "lease lapsed", holder, None, result)

    async def close(self, drives: list[GatewayDrive]) -> None:
        """Stop: every lease still held lapses now (its action runs), then wait for all lapses."""
        by_node = {drive.node: drive for drive in drives}
        for node, timer in list(self._timers.items()):
            timer.cancel()
            self._expire(by_node[node])
        self._timers.clear()
        if self._lapses:
            await asyncio.gather(*self._lapses, return_exceptions=True)

    @property
    def pending_lapses(self) -> int:
        """Lapse actions still running."""
        return len(self._lapses)
