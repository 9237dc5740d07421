"""What every listening northbound limits: how many connections, and how long one may idle.

The Modbus and HTTP northbounds each listen on a socket anyone on the
network can open. Without limits, idle sockets take every file descriptor
of the process, and then nothing works: not the listeners, not the lines'
reconnects (the issue's outage: 345 idle sockets against a limit of 256).
Each listener therefore has :class:`ListenerLimits`, configured in its own
section (``max_connections``, ``idle_timeout_s``, parsed by
:meth:`ListenerLimits.parse`), and a :class:`ConnectionLimit` that admits
or refuses each new connection.

Decisions:

- **At the cap, accept and close at once.** Not accepting would leave the
  newcomers in the kernel's backlog, where they look connected to their
  client and fill the queue that a legitimate client needs once a slot
  frees. Accepting costs a descriptor for one loop turn.
- **The defaults stay well under a small descriptor limit** (Modbus 64,
  HTTP 16, with the lines, the MQTT session and the interpreter's own: a
  limit of 128 is not reached), so the process never meets EMFILE, where
  asyncio's own accept loop logs a traceback per attempt.
- **Refusals are logged once per interval** (:class:`RateLimitedLog`: one
  WARNING per :data:`LOG_INTERVAL_S`, the others at DEBUG) and counted: a
  flood of connections must not become a flood of log lines.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from ._toml import ConfigTable

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = [
    "LIMIT_KEYS",
    "LOG_INTERVAL_S",
    "ConnectionLimit",
    "ListenerLimits",
    "RateLimitedLog",
    "listener_families",
]

#: The keys of a listening northbound's section that :meth:`ListenerLimits.parse` reads.
LIMIT_KEYS: Final = ("max_connections", "idle_timeout_s")
#: Seconds between two WARNING lines of one :class:`RateLimitedLog`.
LOG_INTERVAL_S: Final = 10.0


@dataclass(frozen=True, slots=True)
class ListenerLimits:
    """A listener's limits: open connections at most, and seconds a connection may idle."""

    max_connections: int
    idle_timeout_s: float

    def parse(self, table: ConfigTable) -> ListenerLimits:
        """The limits *table* sets (:data:`LIMIT_KEYS`), these where it sets none.

        Raises:
            GatewayConfigError: not an integer >= 1, or not a number > 0.
        """
        cap = table.integer("max_connections")
        if cap is not None and cap < 1:
            raise table.error("max_connections", f"must be >= 1, got {cap}")
        idle = table.number("idle_timeout_s", minimum=0, inclusive=False)
        return ListenerLimits(
            self.max_connections if cap is None else cap,
            self.idle_timeout_s if idle is None else idle,
        )


class RateLimitedLog:
    """One WARNING per *interval_s* on *logger*; in between, the same lines at DEBUG.

    The WARNING says how many were moved to DEBUG since the last one.
    """

    def __init__(
        self,
        logger: logging.Logger,
        interval_s: float = LOG_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._logger = logger
        self._interval_s = interval_s
        self._clock = clock
        self._next_at = -float("inf")
        self._quiet = 0

    def log(self, message: str, *args: object) -> None:
        now = self._clock()
        if now < self._next_at:
            self._quiet += 1
            self._logger.debug(message, *args)
            return
        self._next_at = now + self._interval_s
        if self._quiet:
            message += " (%d more since the last warning, at DEBUG)"
            args = (*args, self._quiet)
            self._quiet = 0
        self._logger.warning(message, *args)


class ConnectionLimit:
    """One listener's open connections: admitted up to the cap, refused past it.

    Args:
        listener: its name in log lines and metrics (``"modbus"``, ``"http"``).
        max_connections: the cap.
        log: where refusals are logged (rate-limited).
    """

    def __init__(self, listener: str, max_connections: int, log: logging.Logger) -> None:
        self.listener = listener
        self.max_connections = max_connections
        #: Connections open now.
        self.open = 0
        #: Connections refused at the cap, and closed for idling, since the start.
        self.refused = 0
        self.timed_out = 0
        self._log = RateLimitedLog(log)

    def admit(self, transport: asyncio.BaseTransport) -> bool:
        """Count a new connection in; at the cap, close it now and return False."""
        if self.open < self.max_connections:
            self.open += 1
            return True
        self.refused += 1
        self._log.log(
            "%s: %d connections open (max_connections): refused %s",
            self.listener,
            self.open,
            transport.get_extra_info("peername"),
        )
        transport.close()
        return False

    def release(self) -> None:
        """An admitted connection closed."""
        self.open -= 1


def listener_families(prefix: str, limit: ConnectionLimit) -> Iterator[Metric]:
    """``<prefix>_connections`` and its ``_refused_total`` / ``_timed_out_total``, built now."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    name = limit.listener
    yield GaugeMetricFamily(f"{prefix}_connections", f"{name} connections open.", limit.open)
    yield CounterMetricFamily(
        f"{prefix}_connections_refused",
        f"{name} connections refused at max_connections (accepted and closed at once).",
        limit.refused,
    )
    yield CounterMetricFamily(
        f"{prefix}_connections_timed_out",
        f"{name} connections closed by the server for idling past idle_timeout_s.",
        limit.timed_out,
    )
