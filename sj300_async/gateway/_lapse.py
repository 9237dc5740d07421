"""A lapsed lease's action, carried out until the drive is confirmed stopped.

When a control lease lapses (:mod:`._control`), the line's ``on_lapse``
action runs here: ``stop`` (the drive's stop, which jumps the line's
queue), ``broadcast_stop`` (every drive of the line, then the lapsed
drive's status is checked), or ``hold`` (nothing is sent; audited).

A stop is *confirmed* when a status read after it shows the drive not
running (stopped, or tripped). Until then the lapse is *pending*: the drive
shows it (:attr:`~._drive.GatewayDrive.lapse_pending`, hence a metric,
/healthz and the MQTT state), and the stop is tried again with a growing
pause (:data:`RETRY_FIRST_S` doubling up to :data:`RETRY_MAX_S`), whatever
went wrong: a NAK, a time-out, the link down. A drive that acknowledged the
stop and still reports running is decelerating: it is read again until it
stops, and sent the stop again only every :data:`RESEND_S` (one stop on the
wire per lapse when all goes well).

While the link is down the line's polls are held (:class:`PollHold`), and
the try waits for the link: when it comes back, the stop is the first
request on the line, before any poll. Polls are released after that try,
confirmed or not, so a drive that never confirms (powered off) does not
stop the line's polling.

Decisions: the log says the first failure at ERROR and later ones at
DEBUG (a line down for an hour must not write a line per try); the audit
log gets one record when the lapse ends (confirmed after N tries, or given
up when the gateway stops). The runner never gives up on its own: a drive
left running with nobody in control is the failure this exists to prevent.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any, Final, Protocol

from ..bus import Bus
from ..wire import SJ300Error
from ._audit import AuditLog
from ._drive import GatewayDrive
from ._model import LineConfig
from ._writes import DONE, Refusal, WriteResult

__all__ = ["RETRY_FIRST_S", "RETRY_MAX_S", "LapseRunner", "PollHold"]

_log = logging.getLogger("sj300_async.gateway")

#: The pause after a lapse's first failed try; it doubles after each failure...
RETRY_FIRST_S: Final = 0.1
#: ...up to this.
RETRY_MAX_S: Final = 2.0
#: A drive that took the stop and still reports running (decelerating) is only
#: read until it stops; the stop is sent again when it has not within this.
RESEND_S: Final = 10.0
_STILL_RUNNING: Final = "the drive still reports running"


class PollHold(Protocol):
    """What holds a line's polls (the :class:`~sj300_async.Poller`)."""

    def hold(self, bus: Bus[Any, Any]) -> None: ...

    def release(self, bus: Bus[Any, Any]) -> None: ...


class LapseRunner:
    """Runs one line's lapse actions (see the module docstring)."""

    def __init__(
        self,
        config: LineConfig,
        bus: Bus[Any, Any],
        audit: AuditLog,
        lock: Callable[[GatewayDrive], asyncio.Lock],
        changed: Callable[[GatewayDrive], None],
        polls: PollHold | None = None,
    ) -> None:
        self.config = config
        self.bus = bus
        self.audit = audit
        self._lock = lock
        self._changed = changed
        self._polls = polls
        #: Lapse actions started (each counted once, whatever its result).
        self.lapses = 0
        #: Tries of a lapse's stop that failed (each pending lapse's, summed).
        self.failed_tries = 0

    async def run(self, holder: str, drive: GatewayDrive) -> None:
        """Carry out the line's lapse action for *drive*, whose lease *holder* held."""
        self.lapses += 1
        action = self.config.on_lapse
        if action == "hold":
            self.audit.write(holder, drive, "lease lapsed: hold (nothing sent)", holder, None, DONE)
            return
        drive.lapse_pending, drive.lapse_error, drive.lapse_tries = True, "", 0
        self._changed(drive)
        try:
            await self._until_confirmed(holder, drive, action)
        except asyncio.CancelledError:
            self.audit.write(
                holder, drive, f"lease lapsed: {action}", holder, None,
                WriteResult(Refusal.NOT_CONFIRMED, f"given up after {drive.lapse_tries} tries "
                            f"when the gateway stopped: {drive.lapse_error or 'no answer'}"),
            )  # fmt: skip
            raise
        finally:
            drive.lapse_pending = False
            self._changed(drive)

    async def _until_confirmed(self, holder: str, drive: GatewayDrive, action: str) -> None:
        pause = RETRY_FIRST_S
        loop = asyncio.get_running_loop()
        stop_taken_at: float | None = None  # when the drive last acknowledged the stop
        failures = 0
        while True:
            drive.lapse_tries += 1
            if not self.bus.connected:  # _try waits for the link: show why meanwhile
                failures += 1
                self._failed(drive, action, failures, f"{self.bus.description} is not "
                             "connected; the stop goes first when it is back")  # fmt: skip
            send = stop_taken_at is None or loop.time() - stop_taken_at >= RESEND_S
            error, taken = await self._try(drive, action if send else None)
            if taken:
                stop_taken_at = loop.time()
            if error is None:
                detail = f" after {drive.lapse_tries} tries" if drive.lapse_tries > 1 else ""
                if failures:
                    _log.warning("line %s node %d: lapse %s confirmed%s",
                                 *drive.key, action, detail)  # fmt: skip
                self.audit.write(holder, drive, f"lease lapsed: {action}", holder,
                                 f"confirmed stopped{detail}", DONE)  # fmt: skip
                return
            # A drive that took the stop and still runs is decelerating: not a failure.
            if error == _STILL_RUNNING and stop_taken_at is not None:
                _log.debug("line %s node %d: lapse %s: decelerating", *drive.key, action)
            else:
                failures += 1
                self._failed(drive, action, failures, error)
            await asyncio.sleep(pause)
            pause = min(pause * 2, RETRY_MAX_S)

    def _failed(self, drive: GatewayDrive, action: str, failures: int, error: str) -> None:
        """Show a failed try: the drive's lapse error, the count, the log (ERROR the first time)."""
        self.failed_tries += 1
        drive.lapse_error = error
        self._changed(drive)
        level = logging.ERROR if failures == 1 else logging.DEBUG
        _log.log(level, "line %s node %d: lapse %s not confirmed (try %d): %s",
                 *drive.key, action, drive.lapse_tries, error)  # fmt: skip

    async def _try(self, drive: GatewayDrive, action: str | None) -> tuple[str | None, bool]:
        """One try: the stop (unless *action* is None) and a status read.

        Returns (None when confirmed, else why not; whether the drive took the stop).
        """
        held = False
        taken = False
        try:
            if not self.bus.connected and self._polls is not None:
                # Hold the polls before the link is back, so the stop is the first request.
                self._polls.hold(self.bus)
                held = True
                await self.bus.link.wait_connected()
            target = self.bus.drive(drive.node)
            async with self._lock(drive):
                if action == "broadcast_stop":
                    await self.bus.broadcast.stop()
                elif action is not None:
                    await target.stop()
                taken = action is not None
                status = await target.read_status()
        except SJ300Error as exc:
            return str(exc), taken
        finally:
            if held:
                assert self._polls is not None
                self._polls.release(self.bus)
        drive.readings.set_status(status, asyncio.get_running_loop().time(), drive.profile)
        view = drive.readings.status_view
        if view is not None and not view.running:
            return None, taken
        return (_STILL_RUNNING if view is not None else "no status in the answer"), taken
