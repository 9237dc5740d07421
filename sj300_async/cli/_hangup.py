"""``sj300 gateway``'s SIGHUP (``systemctl reload``): read the configuration file again.

The gateway reads and checks the file, and applies what changed
(:meth:`~sj300_async.gateway.Gateway.reload_file`); a file that fails keeps
the running configuration, said in one line. Reloads run one at a time: a
SIGHUP during one asks for one more after it (any number of them, one),
and a SIGHUP during the start waits for the start to end. Under systemd
the service says ``RELOADING=1`` then ``READY=1`` with its new status. A
gateway started from flags has no file: SIGHUP says so and changes nothing.
"""

from __future__ import annotations

import asyncio
import logging
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..gateway import Gateway, ServiceManager

__all__ = ["HangupReloads", "status_line"]

_log = logging.getLogger("sj300_async.gateway")


def status_line(gateway: Gateway) -> str:
    """The gateway in one line: its lines, drives and where each northbound serves."""
    doors = [line for nb in gateway.northbounds.values() if (line := nb.announce()) is not None]
    return f"{len(gateway.lines)} line(s), {len(gateway.drives)} drive(s); " + "; ".join(doors)


class HangupReloads:
    """SIGHUP's reloads of one ``sj300 gateway`` (see the module docstring)."""

    def __init__(self, path: str | None, manager: ServiceManager | None) -> None:
        self._path = path
        self._manager = manager
        self._gateway: Gateway | None = None
        self._wanted = False
        self._task: asyncio.Task[None] | None = None

    def requested(self) -> None:
        """The signal handler: a reload now, or after the one under way (or the start)."""
        self._wanted = True
        if self._gateway is not None and self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="sj300-reload")

    def serving(self, gateway: Gateway) -> None:
        """The gateway is up: a SIGHUP that came during the start is served now."""
        self._gateway = gateway
        if self._wanted:
            self.requested()

    async def close(self) -> None:
        """The gateway stops: a reload under way is cancelled (the stop has the loop)."""
        self._gateway = None
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    async def _run(self) -> None:
        try:
            while self._wanted and self._gateway is not None:
                self._wanted = False
                await self._once(self._gateway)
        finally:
            self._task = None

    async def _once(self, gateway: Gateway) -> None:
        if self._path is None:
            print("SIGHUP: started without --config, there is no file to reload",
                  file=sys.stderr, flush=True)  # fmt: skip
            return
        if self._manager is not None:
            self._manager.reloading()
        try:
            outcome = await gateway.reload_file(self._path)
        except Exception:  # a bug of ours: said with its traceback, the gateway serves on
            _log.exception("reload of %s failed part-way", self._path)
            if self._manager is not None:
                self._manager.ready(status_line(gateway))
            return
        if not outcome.refused:  # a refusal is the gateway's ERROR line already
            assert outcome.plan is not None
            words = outcome.plan.words() or ["nothing changed"]
            said = "".join(f"; {note}" for note in outcome.notes)
            print(f"reloaded {self._path}: {', '.join(words)}{said}", file=sys.stderr, flush=True)
        if self._manager is not None:
            self._manager.ready(status_line(gateway))
