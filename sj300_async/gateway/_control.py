"""Writes from the plant's clients: judged, carried out through the line's arbiter, read back.

A write reaches a drive only when the configuration allows it (the line's
write grants: the parameter allow-list, ``control`` for run/stop/frequency)
and, for run and frequency commands, when the writing client holds the
drive's lease. A stop needs no lease: any client the configuration lets
control the drive may stop it, even while another holds the lease (stop is
the safe direction). Values are validated by the drive classes before
anything reaches the wire; a set frequency outside 0..the drive's maximum
is refused before the lease is looked at (no client may send it), naming
the maximum and where it comes from (the drive's own, A004 / Pr.1 when
polled, else its protocol's highest), and so is one finer than
:data:`FREQUENCY_STEP_HZ` (every protocol's step), or not a number. A run,
a frequency or a parameter for a drive the poller holds offline is refused
unsent (no answer: nothing could confirm it); a stop is always tried. The
order, the same whichever door the write came by (issue 42): the
configuration's grants, the value, then (all but a stop) the drive
offline, then the lease. Every write goes through the same
:class:`~sj300_async.Bus` as the polls, so the arbiter never interleaves it
with them, and is confirmed by a read-back whose value also goes into the
drive's readings (and so into its next snapshot, built at once). Every
write, heartbeats included, is one line of the audit log with the neutral
result (:class:`~._writes.WriteResult`: ``ok`` or a refusal's reason).

The lease: a client takes a drive's lease by a heartbeat and keeps it by
another within ``lease_s``. Another client's heartbeat is refused (lease
held) while it is held. With ``lease_scope = "connection"`` the lease also
lapses the moment the connection the last heartbeat came by closes
(:meth:`Controller.disconnected`). When it lapses, the line's ``on_lapse``
action runs (:mod:`._lapse`: retried until the drive is confirmed stopped).

A command must not outlive its lease. The holder's run and frequency
commands still waiting (for the drive's write lock, or for the line behind
a poll) or under way when the lease lapses are cancelled at the lapse, and
the lapse action waits for them to end before it takes the drive's write
lock; every write to a drive holds that lock from its command to its
read-back. So the last command a drive gets from a lapsed controller is the
lapse action, whatever the timing. A lease whose time is up is lapsed
as soon as any write to the drive sees it, even before its timer has run
(a loaded loop runs timers late). But the gateway's own stall is not lease
time: the seconds its event loop could not run anything (measured by
:class:`~._looplag.LoopMonitor`) move the lease's end (up to
:data:`MAX_STALL_CREDIT_S` per heartbeat), so a holder whose heartbeat sat
unread in a socket while the loop was stuck keeps its lease. While a lapse is pending, nobody can
take the drive's lease (busy): the stop comes first.

Decisions: a command's read-back is a status read; after a run command the
drive must report running (else "not confirmed"); after a stop it may still
be decelerating, so the status read only has to succeed. The monitor is
read back too (its failure does not fail the command): the state shown
right after a command pairs its status with a direction and a frequency
read after it, not before. The set frequency
is read back the way the drive's profile says (SJ300: F001). A client is
known by the name its northbound gives it (a Modbus client by its IP
address: a SCADA that reconnects from a new port keeps its lease, unless
the lease is connection-scoped).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable, Callable, Iterable
from typing import Any, Final

from ..bus import Bus
from ..wire import Direction, LocalProtocolError, NakError, ReadOnlyError, SJ300Error
from ._audit import AuditLog
from ._drive import GatewayDrive, Lease
from ._lapse import LapseRunner, LineGate, PollHold
from ._model import LineConfig
from ._parameter_values import parameter_request, raw_refusal
from ._writes import (
    DONE,
    Heartbeat,
    ParameterValue,
    ParameterWrite,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
    needs_lease,
)

__all__ = ["Controller"]

_log = logging.getLogger("sj300_async.gateway")
#: The set frequency's step, every protocol's (SJ300 F001, FR-700's frequency: 0.01 Hz).
FREQUENCY_STEP_HZ: Final = 0.01
#: Seconds of the loop's stall a lease is extended by at most, per heartbeat (_credit_stall).
MAX_STALL_CREDIT_S: Final = 10.0
#: How long stopping the gateway waits for pending lapses to be confirmed.
CLOSE_LAPSE_S: Final = 5.0
_COMMAND_NAMES: Final = {
    Direction.STOP: "stop",
    Direction.FORWARD: "run forward",
    Direction.REVERSE: "run reverse",
}


_LAPSED: Final = WriteResult(
    Refusal.NO_LEASE,
    "the control lease lapsed before the command was confirmed; the lapse action follows it",
)
_NOT_CONFIRMED: Final = WriteResult(Refusal.NOT_CONFIRMED, "the drive read back something else")


class _Audit:
    """Whether a write's carrying out began (and so audits it, however it ends)."""

    __slots__ = ("done",)

    def __init__(self) -> None:
        self.done = False


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
        polls: what holds the line's polls while a lapse's stop waits for
            the link (the line's poller).
    """

    def __init__(
        self,
        config: LineConfig,
        bus: Bus[Any, Any],
        audit: AuditLog,
        changed: Callable[[GatewayDrive], None] = lambda drive: None,
        *,
        polls: PollHold | None = None,
        stalled: Callable[[], float] = lambda: 0.0,
    ) -> None:
        self.config = config
        #: Seconds the event loop has been stalled so far (._looplag.LoopMonitor.stalled).
        self._stalled = stalled
        self.bus = bus
        self.audit = audit
        self._changed = changed
        self._locks: dict[int, asyncio.Lock] = {}
        self._timers: dict[int, asyncio.TimerHandle] = {}
        # Run and frequency commands under way, per node: cancelled when the lease lapses.
        self._commands: dict[int, set[asyncio.Task[WriteResult]]] = {}
        self._lapses: dict[int, asyncio.Task[None]] = {}
        # The drive of each lease timer (a connection's close finds its leases here).
        self._timer_drives: dict[int, GatewayDrive] = {}
        #: Held for a pending stop from a reconnect until its try ends: writes wait.
        self.gate = LineGate(bus, polls)
        self.lapse = LapseRunner(config, bus, audit, self._lock, changed, self.gate)

    def retune(self, config: LineConfig, drives: Iterable[GatewayDrive]) -> None:
        """The line's new settings (a reload, :mod:`._reload`): the next request is judged
        by *config*'s grants. A held lease keeps its holder (its new ``lease_s`` from the
        next heartbeat), unless its drive lost its control grant: that lease lapses now,
        its action run, since the holder may no longer command the drive it runs."""
        self.config = config
        self.lapse.config = config
        for drive in drives:
            drive.line = config
            drive.lease.duration_s = config.lease_s
            if drive.lease.holder is not None and not config.control_allowed(drive.node):
                _log.warning("line %s node %d: the control grant of %s's lease was withdrawn",
                             config.name, drive.node, drive.lease.holder)  # fmt: skip
                self._expire(drive)

    @property
    def lapses(self) -> int:
        """Lapse actions started (each counted once, whatever its result)."""
        return self.lapse.lapses

    def _lock(self, drive: GatewayDrive) -> asyncio.Lock:
        """The drive's write lock: a write and its read-back, or a lapse's try, hold it."""
        return self._locks.setdefault(drive.node, asyncio.Lock())

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
        now = asyncio.get_running_loop().time()
        lease = drive.lease
        self._credit_stall(lease)
        if lease.holder is not None and now >= lease.expires_at:
            self._expire(drive)  # its time is up: lapse it before judging (module docstring)
        judged = self._judge(client, drive, request, now)
        if isinstance(judged, WriteResult):
            self.audit.write(client, drive, *self._describe(drive, request), judged)
            return judged
        request = judged  # a parameter in its unit is the drive's integer now
        if isinstance(request, Heartbeat):
            what, old, _ = self._describe(drive, request)
            self._renew(client, drive, connection)
            self.audit.write(client, drive, what, old, client, DONE)
            return DONE
        if not needs_lease(request):
            return await self._carry_out_locked(client, drive, request, _Audit())
        # Its own task, so that the lapse can cancel it without cancelling the caller.
        audit = _Audit()
        task = asyncio.get_running_loop().create_task(
            self._carry_out_locked(client, drive, request, audit, lease_bound=True)
        )
        commands = self._commands.setdefault(drive.node, set())
        commands.add(task)
        try:
            return await task
        except asyncio.CancelledError:
            if not audit.done:  # cancelled before it started: audited here
                self.audit.write(client, drive, *self._describe(drive, request),
                                 self._cancelled(client, drive, lease_bound=True))  # fmt: skip
            current = asyncio.current_task()
            if not task.cancelled() or (current is not None and current.cancelling()):
                raise  # the caller's own cancellation
            return _LAPSED
        finally:
            commands.discard(task)

    async def _carry_out_locked(
        self,
        client: str,
        drive: GatewayDrive,
        request: WriteRequest,
        audit: _Audit,
        *,
        lease_bound: bool = False,
    ) -> WriteResult:
        """Carry out a judged write under the drive's write lock; audited however it ends.

        Cancelled (the lease lapsed, or the caller went away) it is audited
        too, before the cancellation goes on: the audit log has every write
        that may have reached the drive.
        """
        audit.done = True
        what, old, new = self._describe(drive, request)
        result: WriteResult | None = None
        try:
            await self.gate.wait_open()  # a pending stop has the line first
            async with self._lock(drive):  # a write and its read-back stay together
                what, old, new = self._describe(drive, request)  # as it is now
                now = asyncio.get_running_loop().time()
                if lease_bound and not drive.lease.held_by(client, now):
                    # It waited for the lock past the lease: the lapse owns the drive now.
                    result = WriteResult(
                        Refusal.NO_LEASE, "the control lease lapsed while it waited"
                    )
                    return result
                try:
                    confirmed = await self._carry_out(drive, request)
                except SJ300Error as exc:
                    result = _failure(exc)
                    return result
                result = DONE if confirmed else _NOT_CONFIRMED
                return result
        except asyncio.CancelledError:
            result = self._cancelled(client, drive, lease_bound=lease_bound)
            raise
        finally:
            if result is None:  # a bug of ours: the caller gets the exception, the log its line
                result = WriteResult(Refusal.NO_ANSWER, "the gateway failed carrying it out")
            self.audit.write(client, drive, what, old, new, result)

    @staticmethod
    def _cancelled(client: str, drive: GatewayDrive, *, lease_bound: bool) -> WriteResult:
        """The result of a write cancelled before it was confirmed."""
        now = asyncio.get_running_loop().time()
        if lease_bound and not drive.lease.held_by(client, now):
            return _LAPSED
        return WriteResult(
            Refusal.NO_ANSWER,
            "cancelled before the drive confirmed it (the client went away, or the gateway "
            "stopped); it may have reached the drive",
        )

    def _judge(
        self, client: str, drive: GatewayDrive, request: WriteRequest, now: float
    ) -> WriteRequest | WriteResult:
        """*request* refused (the result), or what to carry out: *request* itself, or a
        parameter in its unit as the drive's integer (judged and converted once)."""
        if isinstance(request, ParameterWrite | ParameterValue):
            if request.code not in self.config.writable_parameters(drive.node):
                return WriteResult(
                    Refusal.NOT_ALLOWED,
                    f"the configuration does not allow writing {request.code} to this drive",
                )
            raw: ParameterWrite | WriteResult
            if isinstance(request, ParameterValue):
                raw = parameter_request(drive.profile, request.code, request.value, request.text)
            else:
                raw = raw_refusal(drive.profile, request) or request
            return raw if isinstance(raw, WriteResult) else _offline(drive) or raw
        refused = self._judge_control(client, drive, request, now)
        return request if refused is None else refused

    def _judge_control(
        self, client: str, drive: GatewayDrive, request: WriteRequest, now: float
    ) -> WriteResult | None:
        if not self.config.control_allowed(drive.node):
            return WriteResult(
                Refusal.NOT_ALLOWED, "the configuration does not allow control of this drive"
            )
        if isinstance(request, SetFrequency):  # before the lease: nobody may send it
            refused = self._frequency_refusal(drive, request.hz)
            if refused is not None:
                return refused
        if isinstance(request, RunCommand) and request.direction == Direction.STOP:
            return None  # the safe direction: no lease needed (module docstring)
        if not isinstance(request, Heartbeat) and (offline := _offline(drive)) is not None:
            return offline
        lease = drive.lease
        if lease.held(now) and not lease.held_by(client, now):
            return WriteResult(
                Refusal.LEASE_HELD, f"another client ({lease.holder}) holds the control lease"
            )
        if isinstance(request, Heartbeat):
            if drive.node in self._lapses or drive.lapse_pending:
                return WriteResult(
                    Refusal.BUSY, "the lapse of the last lease is not confirmed yet (its stop)"
                )
            return None
        if not lease.held_by(client, now):
            return WriteResult(Refusal.NO_LEASE, "take the control lease first")
        return None

    def _frequency_refusal(self, drive: GatewayDrive, hz: float) -> WriteResult | None:
        """A set frequency that is no number, above the drive's maximum (or below 0), refused
        with both named, or finer than the step."""
        if not math.isfinite(hz):
            return WriteResult(Refusal.INVALID_VALUE, f"{hz} Hz is no frequency")
        highest, source = self._max_hz(drive)
        if not 0 <= hz <= highest:
            return WriteResult(
                Refusal.INVALID_VALUE, f"{hz:g} Hz is outside 0..{highest:g} Hz ({source})"
            )
        steps = hz / FREQUENCY_STEP_HZ
        if abs(round(steps) - steps) > 1e-6:
            return WriteResult(
                Refusal.INVALID_VALUE, f"{hz:g} Hz is finer than {FREQUENCY_STEP_HZ:g} Hz"
            )
        return None

    def _max_hz(self, drive: GatewayDrive) -> tuple[float, str]:
        """The drive's maximum frequency, and where it comes from: its own setting when
        polled (``the drive's maximum frequency, A004``), else its protocol's highest."""
        profile = drive.profile
        highest = f"the highest for {profile.model} drives"
        code = profile.max_frequency_parameter
        if code is None:
            return profile.max_frequency_hz, highest
        raw = drive.readings.parameters.get(code)
        if raw is None:
            if code not in self.config.parameters:
                why = "is not polled"
            elif code in drive.readings.unavailable:
                why = "is unavailable"
            else:
                why = "has not been read yet"
            return profile.max_frequency_hz, f"{highest}; this drive's own maximum, {code}, {why}"
        own = float(profile.parameters.spec(code).from_raw(raw))
        if own >= profile.max_frequency_hz:
            return profile.max_frequency_hz, highest
        return own, f"the drive's maximum frequency, {code}"

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
        if isinstance(request, ParameterValue):
            return f"parameter {request.code}", old, request.value
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

    # -- reads beside the poll -----------------------------------------------------

    async def read_parameter_raw(self, drive: GatewayDrive, code: str) -> int:
        """Parameter *code* of *drive* as the drive holds it (a northbound's read beside the
        poll, such as the workbench's parameter backup).

        Through the line like every other request of a northbound: it waits while a
        pending stop holds the line, and raises the bus's errors (a NAK, a time-out).
        """
        await self.gate.wait_open()  # a pending stop has the line first
        return int(await self.bus.drive(drive.node).read_parameter_raw(code))

    # -- the lease ---------------------------------------------------------------

    def disconnected(self, connection: str) -> None:
        """*connection* closed: the connection-scoped leases it holds lapse now."""
        if self.config.lease_scope != "connection":
            return
        for drive in list(self._timer_drives.values()):
            if drive.lease.connection == connection:
                _log.info("line %s node %d: the lease holder's connection %s closed",
                          *drive.key, connection)  # fmt: skip
                self._expire(drive)

    def release(self, client: str, drive: GatewayDrive) -> bool:
        """*client* hands *drive*'s lease back: it ends now, with no lapse action.

        A holder that is present and says it is done (an operator switching the
        drive to local control, a test resetting a drive), not one that went
        silent: the motor keeps what it was last told, and the next client may
        take the lease at once. Not a door's request (yet): the library's.
        False (nothing changed) when *client* does not hold the lease.
        """
        lease = drive.lease
        if lease.holder != client:
            return False
        self._disarm(drive)
        lease.holder = None
        lease.connection = None
        _log.info("line %s node %d: %s released the control lease", *drive.key, client)
        return True

    def _renew(self, client: str, drive: GatewayDrive, connection: str | None) -> None:
        loop = asyncio.get_running_loop()
        lease = drive.lease
        if lease.holder != client:
            _log.info("line %s node %d: %s takes the control lease", drive.line.name, drive.node,
                      client)  # fmt: skip
        lease.holder = client
        lease.connection = connection
        lease.expires_at = loop.time() + lease.duration_s
        lease.stalled_at = self._stalled()
        lease.credited_s = 0.0
        self._arm(drive)

    def _disarm(self, drive: GatewayDrive) -> None:
        timer = self._timers.pop(drive.node, None)
        if timer is not None:
            timer.cancel()
        self._timer_drives.pop(drive.node, None)

    def _arm(self, drive: GatewayDrive) -> None:
        self._disarm(drive)
        loop = asyncio.get_running_loop()
        self._timers[drive.node] = loop.call_at(drive.lease.expires_at, self._due, drive)
        self._timer_drives[drive.node] = drive

    def _credit_stall(self, lease: Lease) -> None:
        """Move *lease*'s end by the loop's stall since its last heartbeat.

        A holder that heartbeats within ``lease_s`` must not lose the lease
        because the gateway could not read its heartbeat: the seconds the loop
        was stalled (._looplag) are not lease time: the lease's clock stops
        while the loop is stuck, and a silent holder's lease lapses at most
        the rest of its ``lease_s`` after the loop runs again. A loop that
        lags on and on would stretch a silent holder's lease for as long, so
        at most :data:`MAX_STALL_CREDIT_S` (or ``lease_s``, if longer) is
        added per heartbeat.
        """
        if lease.holder is None:
            return
        stalled = self._stalled()
        cap = max(lease.duration_s, MAX_STALL_CREDIT_S)
        credit = min(stalled - lease.stalled_at, cap - lease.credited_s)
        lease.stalled_at = stalled
        if credit > 0:
            lease.expires_at += credit
            lease.credited_s += credit
            _log.info("lease of %s: %.3f s added for the event loop's stall", lease.holder,
                      credit)  # fmt: skip

    def _due(self, drive: GatewayDrive) -> None:
        """The lease timer: lapse, unless a stall moved the lease's end (then wait for it)."""
        self._timers.pop(drive.node, None)
        lease = drive.lease
        self._credit_stall(lease)
        if lease.holder is not None and asyncio.get_running_loop().time() < lease.expires_at:
            self._arm(drive)
            return
        self._expire(drive)

    def _expire(self, drive: GatewayDrive) -> None:
        self._disarm(drive)
        holder = drive.lease.holder
        if holder is None:
            return
        drive.lease.holder = None
        drive.lease.connection = None
        _log.warning(
            "line %s node %d: the control lease of %s lapsed: %s",
            drive.line.name, drive.node, holder, self.config.on_lapse,
        )  # fmt: skip
        if self.config.on_lapse != "hold":
            drive.lapse_pending = True  # from now: no new lease before its stop is confirmed
        # The holder's commands end first (cancelled), then the lapse action runs.
        commands = list(self._commands.get(drive.node, ()))
        for command in commands:
            command.cancel()
        self._lapses[drive.node] = asyncio.get_running_loop().create_task(
            self._lapse(holder, drive, commands)
        )

    async def _lapse(
        self, holder: str, drive: GatewayDrive, commands: list[asyncio.Task[WriteResult]]
    ) -> None:
        try:
            await self.lapse.run(holder, drive, commands)
        finally:
            if self._lapses.get(drive.node) is asyncio.current_task():
                del self._lapses[drive.node]

    async def close(self, drives: list[GatewayDrive]) -> None:
        """Stop: every lease still held lapses now (its action runs), then wait for all lapses.

        A lapse not confirmed within :data:`CLOSE_LAPSE_S` is given up (audited,
        and logged with what its drive confirmed: at ERROR when it never took
        the stop, at WARNING when it did and is still ramping down): the
        gateway is stopping, nothing will retry it.
        """
        for drive in drives:
            if drive.lease.holder is not None:
                self._expire(drive)
        pending = list(self._lapses.values())
        if not pending:
            return
        _, late = await asyncio.wait(pending, timeout=CLOSE_LAPSE_S)
        if late:
            # Not an ERROR of its own: a drive that took the stop and ramps down for
            # longer than this wait is a clean stop; each lapse's give-up has the level.
            _log.warning("line %s: %d lapse stops not confirmed within %g s of the gateway "
                         "stopping: given up", self.config.name, len(late),
                         CLOSE_LAPSE_S)  # fmt: skip
        while late:  # cancelled until they end: a cancellation may be lost on the way
            for task in late:
                task.cancel()
            _, late = await asyncio.wait(late, timeout=0.1)

    @property
    def pending_lapses(self) -> int:
        """Lapse actions not finished (their stop not confirmed yet)."""
        return len(self._lapses)


def _offline(drive: GatewayDrive) -> WriteResult | None:
    """Refused unsent while the poller holds *drive* offline (None: it is not)."""
    readings = drive.readings
    if readings.online or not readings.polled:  # no verdict before the first poll: try it
        return None
    return WriteResult(Refusal.NO_ANSWER, "the drive is offline: nothing was sent")
