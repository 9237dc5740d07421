"""Home Assistant's births, coalesced: a storm of them costs one re-discovery per window.

Any client the broker lets publish on ``<discovery_prefix>/status`` can say
``online`` as fast as the broker takes it. Each birth used to rebuild and
re-queue the whole discovery on the loop: 1,000 of them held it 1.3 s and the
poll fell to 43 % of its rate. Now (:class:`Rediscovery`):

- a birth with no re-discovery in the last ``interval_s``: one at once;
- a birth within that window: exactly one at the window's end, so Home
  Assistant restarting twice quickly still gets its configs (the second
  start may have missed the first copy);
- a birth while one is scheduled adds nothing: counted
  (``BridgeStats.births_coalesced``), said in one log line per window.

The connection's own announce (every connect) is not a re-discovery: it never
delays the answer to Home Assistant's first birth.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from typing import Final

from ._stats import BridgeStats

__all__ = ["MIN_INTERVAL_S", "Rediscovery"]

#: Re-discoveries for Home Assistant's births: at most one per this many seconds.
MIN_INTERVAL_S: Final = 10.0


class Rediscovery:
    """Runs *announce* for Home Assistant's births, coalesced (see the module docstring)."""

    def __init__(
        self,
        announce: Callable[[], None],
        stats: BridgeStats,
        log: logging.Logger,
        *,
        interval_s: float = MIN_INTERVAL_S,
    ) -> None:
        self._announce = announce
        self._stats = stats
        self._log = log
        self.interval_s = interval_s
        #: Loop time of the last re-discovery.
        self._last = -math.inf
        #: The re-discovery scheduled at the window's end, if any.
        self._timer: asyncio.TimerHandle | None = None
        #: This window's coalesced births were said already (one line per window).
        self._said = False

    @property
    def scheduled(self) -> bool:
        return self._timer is not None

    def birth(self) -> None:
        """Home Assistant said ``online``: re-discover now, at the window's end, or not at all."""
        if self._timer is not None:
            # The one scheduled will carry everything this birth asks for.
            self._stats.births_coalesced += 1
            if not self._said:
                self._said = True
                self._log.info(
                    "MQTT: Home Assistant's births come faster than one re-discovery per "
                    "%g s: coalesced (counted in sj300_mqtt_births_coalesced_total)",
                    self.interval_s,
                )
            return
        loop = asyncio.get_running_loop()
        due = self._last + self.interval_s
        if loop.time() >= due:
            self._run()
        else:
            self._timer = loop.call_at(due, self._run)

    def cancel(self) -> None:
        """Stopping: the scheduled re-discovery, if any, is dropped."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _run(self) -> None:
        self._timer = None
        self._said = False
        self._last = asyncio.get_running_loop().time()
        self._stats.rediscoveries += 1
        self._log.info("MQTT: Home Assistant is online: republishing discovery")
        self._announce()
