"""What every listening northbound limits: how many connections, and how long one may idle.

The Modbus and HTTP northbounds each listen on a socket anyone on the
network can open. Without limits, idle sockets take every file descriptor
of the process, and then nothing works: not the listeners, not the lines'
reconnects (the issue's outage: 345 idle sockets against a limit of 256).
Each listener therefore has :class:`ListenerLimits`, configured in its own
section (``max_connections``, ``max_connections_per_address``,
``idle_timeout_s``, parsed by :meth:`ListenerLimits.parse`), and a
:class:`ConnectionLimit` that admits or refuses each new connection.

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
- **One address cannot hold every slot** (issue 41: 64 POSTs whose bodies
  never came, from one address, held all of HTTP's slots, and /healthz,
  the workbench's Stop button and its lease heartbeats got resets). Each
  client address (the accept's peer address, not a port) may hold at most
  ``max_connections_per_address``, by default half the listener's cap, so
  a second address always finds a slot while one misbehaves. The count is
  kept from the accept's own address, handed to the connection's protocol
  (the factory's argument), which gives it back on release: a transport's
  ``peername`` can be missing for a connection reset before it was set
  up, and a count released under another key would lock that address out
  for good. One address is one host; a NAT or a reverse proxy puts many
  clients behind one, and then the per-address cap needs raising.
- **At the cap, a newcomer takes a slot from the heaviest holder**
  (fair share; the probe after issue 41: two addresses with 32 keep-alive
  connections each, a request every 3 s, held all 64 of HTTP's slots, and
  /healthz, the Stop button and a reconnecting SCADA were closed at once
  for as long as they stayed). The per-address cap stops one address, not
  two. So when the listener is full, a newcomer whose address would, once
  in, still hold fewer connections than the address holding the most is
  admitted by closing one connection of that address: the one idle the
  longest (for HTTP, one with no request in progress, the longest since
  its last request ended; for Modbus, the one whose last request is
  oldest), at once (``abort``: a client that does not read must not keep
  the descriptor of a connection no longer counted), counted (``evicted``)
  and logged (rate-limited). A newcomer from the top address itself, or
  from one a connection short of it (admitting it would only swap the two
  and close a connection for nothing, over and over), or when every
  address holds the same share, is refused as before. Why this rule: a
  newcomer from a fresh address always gets in (its address holds none,
  and a full listener's top address holds at least two unless each of
  ``max_connections`` addresses holds one); an attacker needs as many
  addresses as it wants slots, and even then only pushes out the heaviest
  holder, which is itself unless a legitimate client holds more than it
  does. Ranking addresses by what they hold, rather than connections by
  age, means the operator's one connection is never what a flood closes.
  Connections still being set up (a TLS handshake) and, for HTTP, those
  with a request in progress (an event stream being read) are never
  closed this way: at most no slot is found and the newcomer is refused.
  Each connection's protocol registers with the limit once it is made
  (:meth:`ConnectionLimit.hold`: a :class:`Slot` with its close callback)
  and says when it is busy and when it was last active; the limit keeps,
  per address, its idle connections in order of last activity (a dict
  used as an ordered set) and the addresses by the count they hold, so an
  accept costs O(1) (a scan of the addresses tied at the top, at most).
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
    "Slot",
    "default_per_address",
    "listener_families",
    "peer_address",
]

_log = logging.getLogger("sj300_async.gateway")

#: The keys of a listening northbound's section that :meth:`ListenerLimits.parse` reads.
LIMIT_KEYS: Final = ("max_connections", "max_connections_per_address", "idle_timeout_s")
#: Seconds between two WARNING lines of one :class:`RateLimitedLog`.
LOG_INTERVAL_S: Final = 10.0
#: Seconds a listener stops accepting after an accept failed for want of resources.
ACCEPT_RETRY_S: Final = 0.5
#: Connections accepted per readiness of the listening socket (then other work runs).
ACCEPT_BURST: Final = 16
#: The kernel's queue of connections not yet accepted.
BACKLOG: Final = 64


def default_per_address(max_connections: int) -> int:
    """The per-address cap where none is configured: half the listener's (at least 1)."""
    return max(1, max_connections // 2)


@dataclass(frozen=True, slots=True)
class ListenerLimits:
    """A listener's limits: open connections at most, in all and from one address, and
    seconds a connection may idle."""

    max_connections: int
    idle_timeout_s: float
    #: None: :func:`default_per_address` of ``max_connections``.
    max_connections_per_address: int | None = None

    @property
    def per_address(self) -> int:
        """The per-address cap in force."""
        if self.max_connections_per_address is None:
            return default_per_address(self.max_connections)
        return self.max_connections_per_address

    def parse(self, table: ConfigTable) -> ListenerLimits:
        """The limits *table* sets (:data:`LIMIT_KEYS`), these where it sets none.

        Raises:
            GatewayConfigError: not an integer >= 1, not a number > 0, or a per-address
                cap above the listener's.
        """
        cap = table.integer("max_connections")
        if cap is not None and cap < 1:
            raise table.error("max_connections", f"must be >= 1, got {cap}")
        cap = self.max_connections if cap is None else cap
        per_address = table.integer("max_connections_per_address")
        if per_address is not None and not 1 <= per_address <= cap:
            raise table.error(
                "max_connections_per_address",
                f"must be 1..max_connections ({cap}), got {per_address}",
            )
        idle = table.number("idle_timeout_s", minimum=0, inclusive=False)
        return ListenerLimits(
            cap,
            self.idle_timeout_s if idle is None else idle,
            self.max_connections_per_address if per_address is None else per_address,
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


def peer_address(peer: object) -> str:
    """The client address of an accept's *peer* (``(host, port, ...)``): what is counted."""
    if isinstance(peer, tuple) and peer:
        return str(peer[0])
    return str(peer)


class Slot:
    """One admitted connection's place in its :class:`ConnectionLimit`.

    Its protocol gets it from :meth:`ConnectionLimit.hold` once the connection
    is made, calls :meth:`busy` when a request starts (not closed for a
    newcomer while busy), :meth:`active` when one ended or came (the most
    recently active are closed last), and :meth:`release` when the
    connection is lost (a slot already released, by an eviction, is not
    released twice).
    """

    __slots__ = ("_close", "_limit", "address", "released")

    def __init__(self, limit: ConnectionLimit, address: str, close: Callable[[], None]) -> None:
        self._limit = limit
        self._close = close
        #: The client's address as admitted (the count's key).
        self.address = address
        #: True once its place is given back (lost, or evicted for a newcomer).
        self.released = False

    def busy(self) -> None:
        """A request is in progress: not to be closed for a newcomer until :meth:`active`."""
        if not self.released:
            self._limit._forget(self)

    def active(self) -> None:
        """Activity now, and nothing in progress: the last to close for a newcomer."""
        if not self.released:
            idle = self._limit._idle_of(self.address)
            idle.pop(self, None)
            idle[self] = None  # to the end: the order is last activity's

    def release(self) -> None:
        """The connection closed: its place is free (once)."""
        if not self.released:
            self.released = True
            self._limit._forget(self)
            self._limit.release(self.address)


class ConnectionLimit:
    """One listener's open connections: admitted up to the caps, refused past them, and at
    the cap a newcomer from a lighter address admitted in place of a connection of the
    heaviest (module docstring).

    Args:
        listener: its name in log lines and metrics (``"modbus"``, ``"http"``).
        max_connections: the cap.
        log: where refusals are logged (rate-limited).
        max_per_address: the cap of one client address (None: half of *max_connections*).
    """

    def __init__(
        self,
        listener: str,
        max_connections: int,
        log: logging.Logger,
        max_per_address: int | None = None,
    ) -> None:
        self.listener = listener
        self.max_connections = max_connections
        self.max_per_address = (
            default_per_address(max_connections) if max_per_address is None else max_per_address
        )
        #: Connections open now, in all and per client address (an address with none
        #: is not kept: the table holds at most the open connections' addresses).
        self.open = 0
        self._by_address: dict[str, int] = {}
        #: The addresses holding each count (none empty), and the largest count: the
        #: heaviest holder in O(1).
        self._holding: dict[int, set[str]] = {}
        self._top = 0
        #: Per address, its registered connections with nothing in progress, least
        #: recently active first (dicts as ordered sets; an address with none not kept).
        self._idle: dict[str, dict[Slot, None]] = {}
        #: Connections refused at the cap, refused at the per-address cap, closed for
        #: idling, and closed for a newcomer (fair share), since the start.
        self.refused = 0
        self.refused_per_address = 0
        self.timed_out = 0
        self.evicted = 0
        self.log = RateLimitedLog(log)

    def retune(self, limits: ListenerLimits) -> None:
        """The caps of *limits* from the next connection on (a reload): the connections
        open now stay, even over a lower cap."""
        self.max_connections = limits.max_connections
        self.max_per_address = limits.per_address

    def open_from(self, address: str) -> int:
        """Connections open now from *address*."""
        return self._by_address.get(address, 0)

    def admit(self, address: str) -> bool:
        """Count a new connection from *address* in; past a cap, count and log a refusal.

        At ``max_connections``, a connection of the heaviest address is closed for it
        when its address is light enough (module docstring).
        """
        if self.open >= self.max_connections and not self._evict_for(address):
            self.refused += 1
            self.log.log(
                "%s: %d connections open (max_connections): refused %s",
                self.listener,
                self.open,
                address,
            )
            return False
        held = self._by_address.get(address, 0)
        if held >= self.max_per_address:
            self.refused_per_address += 1
            self.log.log(
                "%s: %d connections open from %s (max_connections_per_address): refused",
                self.listener,
                held,
                address,
            )
            return False
        self.open += 1
        self._count(address, held, held + 1)
        return True

    def hold(self, address: str, close: Callable[[], None]) -> Slot:
        """Register the connection admitted from *address* once it is made: *close* closes
        it at once (called at most once, for a newcomer). It is active now."""
        slot = Slot(self, address, close)
        slot.active()
        return slot

    def release(self, address: str) -> None:
        """A connection admitted from *address* closed (its protocol's ``connection_lost``,
        through its :class:`Slot` when it has one)."""
        self.open -= 1
        held = self._by_address.get(address, 0)
        self._count(address, held, held - 1)

    def _count(self, address: str, was: int, now: int) -> None:
        """*address* goes from holding *was* to *now* (one more or one less)."""
        if was > 0:
            peers = self._holding[was]
            peers.discard(address)
            if not peers:
                del self._holding[was]
                if self._top == was and now < was:
                    self._top = now  # the one that held the most now holds one less
        if now > 0:
            self._by_address[address] = now
            self._holding.setdefault(now, set()).add(address)
            self._top = max(self._top, now)
        else:
            self._by_address.pop(address, None)

    def _idle_of(self, address: str) -> dict[Slot, None]:
        idle = self._idle.get(address)
        if idle is None:
            idle = self._idle[address] = {}
        return idle

    def _forget(self, slot: Slot) -> None:
        idle = self._idle.get(slot.address)
        if idle is not None:
            idle.pop(slot, None)
            if not idle:
                del self._idle[slot.address]

    def _evict_for(self, address: str) -> bool:
        """Close the idlest connection of the heaviest address for a newcomer from
        *address*, if that address, once in, still holds fewer; True if one was closed."""
        if self._by_address.get(address, 0) + 1 >= self._top:
            return False  # it is the top, or would become it: refused as before
        for heaviest in self._holding[self._top]:
            idle = self._idle.get(heaviest)
            if idle:
                victim = next(iter(idle))
                break
        else:
            return False  # every connection of theirs busy, or still being set up
        self.evicted += 1
        self.log.log(
            "%s: %d connections open (max_connections): closed the idlest of %s's %d for %s",
            self.listener,
            self.open,
            heaviest,
            self._top,
            address,
        )
        # Its place is free now, before its connection_lost (a loop turn later): the
        # newcomer is counted in its place in this same accept.
        victim.release()
        victim._close()
        return True


class Listener:
    """Listening sockets with an accept loop that applies a :class:`ConnectionLimit`.

    Each admitted connection gets a protocol from *factory*, called with the
    client's address as admitted (through ``loop.connect_accepted_socket``),
    whose ``connection_made`` registers with ``limit.hold(address, close)``
    (a :class:`Slot`, which tells the limit when the connection is busy and
    when active, and whose ``release()`` its ``connection_lost`` must call);
    a refused one is closed in the accept. The sockets, ``close()`` and
    ``wait_closed()`` are those of an :class:`asyncio.Server`.
    """

    def __init__(
        self,
        factory: Callable[[str], asyncio.BaseProtocol],
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
            address = peer_address(peer)
            if not self.limit.admit(address):
                connection.close()  # now: the descriptor is free for the next accept
                continue
            connection.setblocking(False)
            self._loop.create_task(self._connect(connection, address))

    async def _connect(self, connection: socket.socket, address: str) -> None:
        def factory() -> asyncio.BaseProtocol:
            return self._factory(address)

        try:
            if self._tls is None:
                await self._loop.connect_accepted_socket(factory, connection)
            else:
                await self._loop.connect_accepted_socket(
                    factory,
                    connection,
                    ssl=self._tls,
                    ssl_handshake_timeout=self._handshake_timeout_s,
                )
        except (OSError, TimeoutError) as exc:
            # Reset before its transport was made, or a failed TLS handshake (plain
            # HTTP to an HTTPS port, an old client): nothing to serve.
            _log.debug("%s: connection not set up: %r", self.limit.listener, exc)
            connection.close()
            self.limit.release(address)

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
    """``<prefix>_connections`` and its ``_refused_total``, ``_refused_per_address_total``,
    ``_timed_out_total`` and ``_evicted_total``, built now."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    name = limit.listener
    yield GaugeMetricFamily(f"{prefix}_connections", f"{name} connections open.", limit.open)
    yield CounterMetricFamily(
        f"{prefix}_connections_refused",
        f"{name} connections refused at max_connections (accepted and closed at once).",
        limit.refused,
    )
    yield CounterMetricFamily(
        f"{prefix}_connections_refused_per_address",
        f"{name} connections refused at max_connections_per_address (one client address's cap).",
        limit.refused_per_address,
    )
    yield CounterMetricFamily(
        f"{prefix}_connections_timed_out",
        f"{name} connections closed by the server for idling past idle_timeout_s.",
        limit.timed_out,
    )
    yield CounterMetricFamily(
        f"{prefix}_connections_evicted",
        f"{name} connections closed at max_connections for a newcomer from an address "
        "holding fewer (the idlest of the address holding the most).",
        limit.evicted,
    )
