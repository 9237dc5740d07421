"""A lapsed lease's action, carried out until the drive is confirmed stopped.

When a control lease lapses (:mod:`._control`), the line's ``on_lapse``
action runs here: ``stop`` (the drive's stop, which jumps the line's
queue), ``broadcast_stop`` (a broadcast stop to every drive of the line,
which no drive acknowledges, then the lapsed drive's own stop, which it
does), or ``hold`` (nothing is sent; audited).

A stop is *confirmed* when a status read after it shows the drive not
running (stopped, or tripped). Until then the lapse is *pending*: the drive
shows it (:attr:`~._drive.GatewayDrive.lapse_pending`, hence a metric,
/healthz and the MQTT state), and the stop is tried again with a growing
pause (:data:`RETRY_FIRST_S` doubling up to :data:`RETRY_MAX_S`), whatever
went wrong: a NAK, a time-out, the link down, even a bug of ours (logged
with its traceback). A drive that acknowledged the stop and still reports
running is decelerating: it is read again every :data:`DECELERATING_READ_S`
until it stops (no back-off: it answers, and a stopping gateway waits only
so long for the confirmation), and sent the stop again only every
:data:`RESEND_S`, and first thing on a new connection (one stop on the
wire per lapse when all goes well).

The stop is the first request on a link that comes back. From the moment
the link is up again (:meth:`~sj300_async.Bus.on_connected`, which runs
before any waiting task can send) the line is held (:class:`LineGate`: the
polls, the clients' writes and the trip-history reads wait) and the lapse
tries at once, whatever pause it was in; the line is released when that
try ends, confirmed or not, so a drive that never confirms (powered off)
does not stop the line's polling or its other drives' writes. While the
link is down nothing is held: the polls fail, and the drives show offline
as they should.

Decisions: the log says the first failure at ERROR and later ones at
DEBUG (a line down for an hour must not write a line per try); the audit
log gets one record when the lapse ends (confirmed after N tries, or given
up when the gateway stops or the line is closed). The runner never gives
up on its own: a drive left running with nobody in control is the failure
this exists to prevent. A lapse given up says what the drive confirmed, at
the level that deserves (issue 41: every clean stop with a motor running
logged "given up ... no answer" at ERROR, though the drive had taken the
stop and was ramping down, which takes the drive's deceleration time, often
longer than the stopping gateway's wait): ERROR when the drive never
acknowledged the stop (the motor may still run, with nobody in control),
WARNING when it took it and only its standstill is not confirmed (it ramps
down by itself), each with the drive's last answer or the try under way.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any, Final, Protocol

from ..bus import Bus
from ..wire import SJ300Error
from ._audit import AuditLog
from ._drive import GatewayDrive
from ._model import LineConfig
from ._writes import DONE, Refusal, WriteResult

__all__ = ["RETRY_FIRST_S", "RETRY_MAX_S", "LapseRunner", "LineGate", "PollHold"]

_log = logging.getLogger("sj300_async.gateway")

#: The pause after a lapse's first failed try; it doubles after each failure...
RETRY_FIRST_S: Final = 0.1
#: ...up to this.
RETRY_MAX_S: Final = 2.0
#: A drive that took the stop and still reports running (decelerating) is only
#: read until it stops; the stop is sent again when it has not within this.
RESEND_S: Final = 10.0
#: The pause between the status reads of a drive that took the stop and is
#: decelerating: it answers, so no back-off; a stopping gateway confirms a
#: standstill that comes within its wait, not one read up to 2 s later.
DECELERATING_READ_S: Final = 0.25
_STILL_RUNNING: Final = "the drive still reports running"


class PollHold(Protocol):
    """What holds a line's polls (the :class:`~sj300_async.Poller`)."""

    def hold(self, bus: Bus[Any, Any]) -> None: ...

    def release(self, bus: Bus[Any, Any]) -> None: ...


class LineGate:
    """Keeps the line for a pending stop: while held, the polls are held and no other
    request of the gateway's (a client's write, a trip-history read) starts.

    Holds nest; each is released once. Requests already under way when it is
    taken go on (on a new connection they fail: a request never moves to
    one, see :meth:`~sj300_async.Bus.on_connected`).
    """

    def __init__(self, bus: Bus[Any, Any], polls: PollHold | None) -> None:
        self._bus = bus
        self._polls = polls
        self._holds = 0
        self._open = asyncio.Event()
        self._open.set()

    @property
    def held(self) -> bool:
        return self._holds > 0

    def hold(self) -> None:
        self._holds += 1
        self._open.clear()
        if self._polls is not None:
            self._polls.hold(self._bus)

    def release(self) -> None:
        assert self._holds > 0
        self._holds -= 1
        if self._polls is not None:
            self._polls.release(self._bus)
        if not self._holds:
            self._open.set()

    async def wait_open(self) -> None:
        """Return when nothing holds the line (at once, nearly always)."""
        while self._holds:
            await self._open.wait()


class _FirstOnReconnect:
    """Holds the line from the moment its link comes back until the lapse's next try ends."""

    def __init__(self, bus: Bus[Any, Any], gate: LineGate) -> None:
        self._bus = bus
        self._gate = gate
        self._held = False
        #: Set when the link came back since the current try began.
        self.back = asyncio.Event()
        self._unregister = bus.on_connected(self._connected)

    def _connected(self) -> None:
        if not self._held:
            self._gate.hold()
            self._held = True
        self.back.set()

    def try_ended(self) -> None:
        """Release the line, unless the link came back during the try (the next one goes first)."""
        if not (self.back.is_set() and self._bus.connected):
            self.release()

    def release(self) -> None:
        if self._held:
            self._held = False
            self._gate.release()

    def close(self) -> None:
        self._unregister()
        self.release()


@dataclass(slots=True)
class _Known:
    """What one lapse has learnt of its drive so far: what a give-up says it knows."""

    #: Loop time the drive last acknowledged the stop (None: it never has).
    taken_at: float | None = None
    #: The drive's state in words at the latest status read after it took the stop.
    state: str = ""
    #: Why the latest try that ended failed ("" when the drive answered it).
    failure: str = ""
    #: What the try under way was doing, said if the gateway's stop cuts it short.
    doing: str = ""


class LapseRunner:
    """Runs one line's lapse actions (see the module docstring)."""

    def __init__(
        self,
        config: LineConfig,
        bus: Bus[Any, Any],
        audit: AuditLog,
        lock: Callable[[GatewayDrive], asyncio.Lock],
        changed: Callable[[GatewayDrive], None],
        gate: LineGate,
    ) -> None:
        self.config = config
        self.bus = bus
        self.audit = audit
        self._lock = lock
        self._changed = changed
        self._gate = gate
        #: Lapse actions started (each counted once, whatever its result).
        self.lapses = 0
        #: Tries of a lapse's stop that failed (each pending lapse's, summed).
        self.failed_tries = 0

    async def run(
        self, holder: str, drive: GatewayDrive, commands: Collection[asyncio.Task[Any]] = ()
    ) -> None:
        """Carry out the line's lapse action for *drive*, whose lease *holder* held.

        *commands* (the holder's, cancelled) end first: the lapse action is
        the last the drive gets from the lapsed controller.
        """
        self.lapses += 1
        action = self.config.on_lapse
        if action == "hold":
            self.audit.write(holder, drive, "lease lapsed: hold (nothing sent)", holder, None, DONE)
            return
        what = f"lease lapsed: {action}"
        drive.lapse_pending, drive.lapse_error, drive.lapse_tries = True, "", 0
        self._changed(drive)
        gate = _FirstOnReconnect(self.bus, self._gate)
        known = _Known(doing="the stop not sent yet: the lapsed holder's command was ending")
        try:
            if commands:
                await asyncio.wait(commands)
            known.doing = ""
            given_up = await self._until_confirmed(holder, drive, action, gate, known)
            if given_up is not None:
                self._give_up(holder, drive, what, given_up, known)
        except asyncio.CancelledError:
            self._give_up(holder, drive, what, "the gateway stopped", known)
            raise
        finally:
            gate.close()
            drive.lapse_pending = False
            self._changed(drive)

    def _give_up(
        self, holder: str, drive: GatewayDrive, what: str, why: str, known: _Known
    ) -> None:
        """Log and audit a lapse given up with what is known (module docstring)."""
        tries = _tries(drive.lapse_tries)
        # The latest news: the try cut short, else the failure of the latest that ended.
        latest = known.doing or known.failure
        if known.doing and known.failure:
            latest += f" (the try before: {known.failure})"
        if known.taken_at is None:
            level = logging.ERROR
            detail = (
                f"given up after {tries} when {why}: the drive never acknowledged the stop: "
                f"{latest or 'the stop was not sent'}"
            )
        else:
            level = logging.WARNING
            if known.state:
                seen = f" and still read {known.state}" if not latest else f", read {known.state}"
            else:
                seen = ""
            detail = (
                f"not confirmed stopped after {tries} when {why}: the drive took the stop"
                f"{seen}{f', then: {latest}' if latest else ''}"
            )
        _log.log(level, "line %s node %d: %s %s", *drive.key, what, detail)
        self.audit.write(
            holder, drive, what, holder, None, WriteResult(Refusal.NOT_CONFIRMED, detail)
        )

    async def _until_confirmed(
        self,
        holder: str,
        drive: GatewayDrive,
        action: str,
        gate: _FirstOnReconnect,
        known: _Known,
    ) -> str | None:
        """Try until confirmed (None), or until the line is closed (why it was given up)."""
        pause = RETRY_FIRST_S
        loop = asyncio.get_running_loop()
        stop_taken_at: float | None = None  # when the drive last acknowledged the stop
        failures = 0
        while True:
            if self.bus.link.closed:
                return "the line was closed"
            drive.lapse_tries += 1
            if gate.back.is_set():
                stop_taken_at = None  # a new connection: the stop goes first, again
            gate.back.clear()
            if not self.bus.connected:
                failures += 1
                known.failure = (f"{self.bus.description} is not connected; the stop goes "
                                 "first when it is back")  # fmt: skip
                self._failed(drive, action, failures, known.failure)
                gate.release()  # nothing held while the link is down (module docstring)
                await self._link_up()
                continue  # the link is back and the line held: the next try at once
            send = stop_taken_at is None or loop.time() - stop_taken_at >= RESEND_S
            try:
                error, taken = await self._try(drive, action if send else None, known)
            except Exception as exc:  # a bug of ours must not end the lapse: logged, retried
                _log.exception("line %s node %d: lapse %s try failed", *drive.key, action)
                error, taken = f"{type(exc).__name__}: {exc}", False
            finally:
                gate.try_ended()
            # Ended (not cut short by the gateway's stop, whose give-up says what it waited for).
            known.doing = ""
            known.failure = "" if error in (None, _STILL_RUNNING) else error
            if taken:
                stop_taken_at = loop.time()
            if error is None:
                detail = f" after {_tries(drive.lapse_tries)}" if drive.lapse_tries > 1 else ""
                if failures:
                    _log.warning("line %s node %d: lapse %s confirmed%s",
                                 *drive.key, action, detail)  # fmt: skip
                self.audit.write(holder, drive, f"lease lapsed: {action}", holder,
                                 f"confirmed stopped{detail}", DONE)  # fmt: skip
                return None
            # A drive that took the stop and still runs is decelerating: not a failure.
            decelerating = error == _STILL_RUNNING and stop_taken_at is not None
            if decelerating:
                _log.debug("line %s node %d: lapse %s: decelerating", *drive.key, action)
            else:
                failures += 1
                self._failed(drive, action, failures, error)
            if gate.back.is_set():
                continue  # the link came back during the try: again at once, the line held
            # The pause ends early when the link comes back in it (the line is held).
            # asyncio.timeout, not wait_for: on 3.11 wait_for can lose a cancellation
            # that lands as the event fires, and the gateway's stop cancels this task.
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(DECELERATING_READ_S if decelerating else pause):
                    await gate.back.wait()
            if not decelerating:
                pause = min(pause * 2, RETRY_MAX_S)

    async def _link_up(self) -> None:
        """Wait for the link (or its close, which the next round of the loop sees)."""
        up = asyncio.ensure_future(self.bus.link.wait_connected())
        try:
            while not up.done() and not self.bus.link.closed:
                await asyncio.wait([up], timeout=RETRY_MAX_S)
        finally:
            up.cancel()

    def _failed(self, drive: GatewayDrive, action: str, failures: int, error: str) -> None:
        """Show a failed try: the drive's lapse error, the count, the log (ERROR the first time)."""
        self.failed_tries += 1
        drive.lapse_error = error
        self._changed(drive)
        level = logging.ERROR if failures == 1 else logging.DEBUG
        _log.log(level, "line %s node %d: lapse %s not confirmed (try %d): %s",
                 *drive.key, action, drive.lapse_tries, error)  # fmt: skip

    async def _try(
        self, drive: GatewayDrive, action: str | None, known: _Known
    ) -> tuple[str | None, bool]:
        """One try: the stop (unless *action* is None) and a status read.

        Returns (None when confirmed, else why not; whether the drive took the stop).
        *known* follows it: what it waits for, and what the drive answered.
        """
        target = self.bus.drive(drive.node)
        loop = asyncio.get_running_loop()
        taken = False
        try:
            known.doing = "the stop not sent yet: a write to the drive was under way"
            async with self._lock(drive):
                if action == "broadcast_stop":
                    known.doing = "the broadcast stop under way"
                    await self.bus.broadcast.stop()  # unacknowledged: the drive's own follows
                if action is not None:
                    known.doing = "the stop under way, no answer yet"
                    await target.stop()
                    taken = True
                    known.taken_at = loop.time()
                known.doing = "its status read under way, no answer yet"
                status = await target.read_status()
        except SJ300Error as exc:
            return str(exc), taken
        drive.readings.set_status(status, loop.time(), drive.profile)
        view = drive.profile.status_view(status)
        if known.taken_at is not None:
            known.state = view.state
        return (_STILL_RUNNING if view.running else None), taken


def _tries(count: int) -> str:
    return f"{count} try" if count == 1 else f"{count} tries"
