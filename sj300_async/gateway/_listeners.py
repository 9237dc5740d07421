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

- **At the cap, accept and close at once**, in the accept itself
  (:class:`Listener`: the descriptor is free before the next accept).
  Not accepting would leave the newcomers in the kernel's backlog, where
  they look connected to their client and fill the queue that a
  legitimate client needs once a slot frees. asyncio's own server would
  not do: it accepts up to its backlog (100) per loop turn and creates a
  transport for each a turn or two later, so a flood holds a few hundred
  descriptors before any protocol can refuse one.
- **The defaults stay well under a small descriptor limit** (Modbus 64,
  HTTP 16, with the lines, the MQTT session and the interpreter's own: a
  limit of 128 is not reached), and an accept that fails all the same
  (EMFILE, ENFILE, ENOBUFS) pauses that listener for
  :data:`ACCEPT_RETRY_S` with one log line, where asyncio's loop logs a
  traceback per attempt.
- **Refusals are logged once per interval** (:class:`RateLimitedLog`: one
  WARNING per :data:`LOG_INTERVAL_S`, the others at DEBUG) and counted: a
  flood of connections must not become a flood of log lines.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import ssl
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from ._toml import ConfigTable

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = [
    "ACCEPT_RETRY_S",
    "LIMIT_KEYS",
    "LOG_INTERVAL_S",
    "ConnectionLimit",
    "Listener",
    "ListenerLimits",
    "RateLimitedLog",
    "listener_families",
]

_log = logging.getLogger("sj300_async.gateway")

#: The keys of a listening northbound's section that :meth:`ListenerLimits.parse` reads.
LIMIT_KEYS: Final = ("max_connections", "idle_timeout_s")
#: Seconds between two WARNING lines of one :class:`RateLimitedLog`.
LOG_INTERVAL_S: Final = 10.0
#: Seconds a listener stops accepting after an accept failed for want of resources.
ACCEPT_RETRY_S: Final = 0.5
#: Connections accepted per readiness of the listening socket (then other work runs).
ACCEPT_BURST: Final = 16
#: The kernel's queue of connections not yet accepted.
BACKLOG: Final = 64


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
        self.log = RateLimitedLog(log)

    def admit(self, peer: object) -> bool:
        """Count a new connection from *peer* in; at the cap, count and log a refusal."""
        if self.open < self.max_connections:
            self.open += 1
            return True
        self.refused += 1
        self.log.log(
            "%s: %d connections open (max_connections): refused %s",
            self.listener,
            self.open,
            peer,
        )
        return False

    def release(self) -> None:
        """An admitted connection closed (its protocol's ``connection_lost`` says so)."""
        self.open -= 1


class Listener:
    """Listening sockets with an accept loop that applies a :class:`ConnectionLimit`.

    Each admitted connection gets a protocol from *factory* (through
    ``loop.connect_accepted_socket``), whose ``connection_lost`` must call
    ``limit.release()``; a refused one is closed in the accept. The
    sockets, ``close()`` and ``wait_closed()`` are those of an
    :class:`asyncio.Server`.
    """

    def __init__(
        self,
        factory: Callable[[], asyncio.BaseProtocol],
        limit: ConnectionLimit,
        *,
        tls: ssl.SSLContext | None = None,
        handshake_timeout_s: float = 10.0,
    ):
        self._factory = factory
        self.limit = limit
        #: TLS on every connection (the handshake must end within *handshake_timeout_s*).
        self._tls = tls
        self._handshake_timeout_s = handshake_timeout_s
        self.sockets: list[socket.socket] = []
        self._loop = asyncio.get_running_loop()
        self._closed = False

    async def start(self, host: str, port: int) -> None:
        """Bind every address of *host* on *port* and start accepting.

        Raises:
            OSError: an address cannot be bound (in use, not on this host).
        """
        infos = await self._loop.getaddrinfo(
            host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )
        try:
            for family, kind, proto, _, address in dict.fromkeys(infos):
                sock = socket.socket(family, kind, proto)
                self.sockets.append(sock)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                if family == socket.AF_INET6:  # the IPv4 address is bound on its own
                    sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
                try:
                    sock.bind(address)
                except OSError as exc:
                    raise OSError(
                        exc.errno, f"cannot listen on {address!r}: {exc.strerror}"
                    ) from None
                sock.listen(BACKLOG)
                sock.setblocking(False)
        except BaseException:
            self.close()
            raise
        for sock in self.sockets:
            self._loop.add_reader(sock.fileno(), self._accept, sock)

    def _accept(self, sock: socket.socket) -> None:
        for _ in range(ACCEPT_BURST):
            try:
                connection, peer = sock.accept()
            except (BlockingIOError, InterruptedError, ConnectionAbortedError):
                return
            except OSError as exc:  # EMFILE, ENFILE, ENOBUFS, ENOMEM: out of resources
                self.limit.log.log(
                    "%s: cannot accept (%s): paused for %g s",
                    self.limit.listener,
                    exc.strerror,
                    ACCEPT_RETRY_S,
                )
                self._loop.remove_reader(sock.fileno())
                self._loop.call_later(ACCEPT_RETRY_S, self._resume, sock)
                return
            if not self.limit.admit(peer):
                connection.close()  # now: the descriptor is free for the next accept
                continue
            connection.setblocking(False)
            self._loop.create_task(self._connect(connection))

    async def _connect(self, connection: socket.socket) -> None:
        try:
            if self._tls is None:
                await self._loop.connect_accepted_socket(self._factory, connection)
            else:
                await self._loop.connect_accepted_socket(
                    self._factory,
                    connection,
                    ssl=self._tls,
                    ssl_handshake_timeout=self._handshake_timeout_s,
                )
        except (OSError, TimeoutError) as exc:
            # Reset before its transport was made, or a failed TLS handshake (plain
            # HTTP to an HTTPS port, an old client): nothing to serve.
            _log.debug("%s: connection not set up: %r", self.limit.listener, exc)
            connection.close()
            self.limit.release()

    def _resume(self, sock: socket.socket) -> None:
        if not self._closed:
            self._loop.add_reader(sock.fileno(), self._accept, sock)

    def close(self) -> None:
        """Stop listening (the connections already made are their protocols' to close)."""
        self._closed = True
        for sock in self.sockets:
            self._loop.remove_reader(sock.fileno())
            sock.close()

    async def wait_closed(self) -> None:
        """Nothing to wait for once :meth:`close` returned (for asyncio.Server's callers)."""


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
