"""Who may hold one of the OPC UA server's slots: a connection, a session not yet activated.

asyncua takes every connection up to ``max_connections`` and every
CreateSession up to its session limit, and keeps a session that is never
activated as long as its connection stays (issue 41: 100 CreateSession on
one unsecured connection refused the operator's login with
BadTooManySessions for 30 s, and the attacker could repeat it). Creating a
session costs an attacker one request; so the slots are rationed by what
the attacker cannot choose freely, the connection and the client's address,
and a slot that never becomes a working session is taken back soon:

- **Connections per address** (``max_connections_per_address``): one
  address cannot hold every connection the server takes.
- **Sessions per connection** (:data:`SESSIONS_PER_CONNECTION`, activated
  or not) **and per address** (``max_connections_per_address``, the
  connections' share), and **unactivated sessions per address**
  (``max_unactivated_per_address``): past any, CreateSession is refused
  (``BadTooManySessions``), counted. A client creates one session on its
  connection and activates it at once (asyncua serves one session per
  connection: the last created); two leave room for a client that retries
  before its first attempt timed out. Anonymous sessions activate without
  a password, so without the caps on all sessions an attacker would only
  need to activate them to fill the server.
- **Closed when not activated in time** (``activate_within_s``, 5 s):
  activation follows creation within a round trip; 5 s is a slow link's
  many round trips, not a 30 s hold.
- **The oldest unactivated session makes room.** When every session slot
  is taken and some of them are unactivated, a newcomer's CreateSession
  closes the oldest unactivated one (counted ``evicted``) instead of being
  refused: an attacker's unactivated sessions are a queue the legitimate
  client goes past, never a wall. Only activated sessions can fill the
  server.
- **No session on a discovery-only channel.** An unsecured channel that no
  endpoint offers (or that carries no certificate under
  ``trusted_clients``) serves GetEndpoints and FindServers only
  (:mod:`._hooks`); a session there could serve no request, so creating
  one is refused (``BadSecurityPolicyRejected``) before it takes a slot.

The sessions here are asyncua's objects, opaque: :mod:`._hooks` tells the
admission what happens to them and closes those it names. Times are the
event loop's.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter, OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Final

from asyncua import ua

__all__ = ["SESSIONS_PER_CONNECTION", "Admission", "Peer", "SessionLimits"]

_log = logging.getLogger("sj300_async.gateway.opcua")

#: Sessions one connection may hold, activated or not (see the module docstring).
SESSIONS_PER_CONNECTION: Final = 2

#: A connection's peer as asyncua names it: (host, port), (host, port, flow, scope).
Peer = tuple[object, ...]


@dataclass(frozen=True, slots=True)
class SessionLimits:
    """The admission's limits (``[opcua]``; docs/OPCUA.md, "Hardening")."""

    #: Sessions at most, activated or not (``max_connections``).
    sessions: int
    #: Connections one client address may hold at once, and sessions.
    max_connections_per_address: int
    #: Sessions one client address may hold not yet activated.
    max_unactivated_per_address: int
    #: Seconds a session may wait for its activation before it is closed.
    activate_within_s: float
    sessions_per_connection: int = SESSIONS_PER_CONNECTION


@dataclass(slots=True)
class _Pending:
    peer: Peer
    address: Hashable
    timer: asyncio.TimerHandle


class Admission:
    """Connections and unactivated sessions rationed (see the module docstring).

    Args:
        limits: the limits.
        close: closes a session (asyncua's; called for the expired and the evicted).
    """

    def __init__(self, limits: SessionLimits, close: Callable[[object], None]) -> None:
        self.limits = limits
        self._close = close
        #: Connections open, by client address.
        self._connections: Counter[Hashable] = Counter()
        #: Every session open (those the gateway let in): its connection's peer and its
        #: address; and the unactivated ones, oldest first.
        self._open: dict[object, tuple[Peer, Hashable]] = {}
        self._pending: OrderedDict[object, _Pending] = OrderedDict()
        #: Sessions refused or closed unactivated, by reason (the metric's label).
        self.sessions_refused: Counter[str] = Counter()
        #: Connections refused, by reason.
        self.connections_refused: Counter[str] = Counter()

    # -- connections -------------------------------------------------------------------

    def connection_opened(self, peer: Peer) -> bool:
        """Count a new connection of *peer*; False (counted): its address holds its share."""
        address = _address(peer)
        if self._connections[address] >= self.limits.max_connections_per_address:
            self.connections_refused["per_address"] += 1
            _log.debug("opcua: refused a connection from %s: its address holds its share", peer)
            return False
        self._connections[address] += 1
        return True

    def connection_closed(self, peer: Peer) -> None:
        """*peer*'s connection is gone: its unactivated sessions go with it."""
        address = _address(peer)
        if self._connections[address] > 0:
            self._connections[address] -= 1
            if not self._connections[address]:
                del self._connections[address]
        for session, pending in list(self._pending.items()):
            if pending.peer == peer:
                self._drop(session)
                self._close(session)

    @property
    def connections(self) -> int:
        return sum(self._connections.values())

    # -- sessions ----------------------------------------------------------------------

    def admit(self, peer: Peer, *, discovery: bool = False) -> int | None:
        """May *peer* create a session now? None, or the status code refusing it (counted).

        Makes room by closing the oldest unactivated session when every slot is taken.
        """
        reason, status = None, ua.StatusCodes.BadTooManySessions
        address = _address(peer)
        limits = self.limits
        if discovery:
            reason, status = "discovery", ua.StatusCodes.BadSecurityPolicyRejected
        elif self._held(0, peer) >= limits.sessions_per_connection:
            reason = "per_connection"
        elif self._held(1, address) >= limits.max_connections_per_address:
            reason = "per_address"
        elif self._count(lambda p: p.address == address) >= limits.max_unactivated_per_address:
            reason = "unactivated_per_address"
        elif len(self._open) >= limits.sessions:
            if not self._pending:
                reason = "full"  # every slot holds an activated session
            else:
                oldest = next(iter(self._pending))
                self._drop(oldest)
                self.sessions_refused["evicted"] += 1
                _log.debug("opcua: closed the oldest unactivated session for a newcomer")
                self._close(oldest)
        if reason is not None:
            self.sessions_refused[reason] += 1
            _log.debug("opcua: refused a session of %s (%s)", peer, reason)
            return int(status)
        return None

    def created(self, session: object, peer: Peer, *, admitted: bool) -> int | None:
        """asyncua made *session* for *peer*: it waits for its activation from now.

        None, or the status code refusing it: a session not *admitted* before asyncua
        made it (:mod:`._hooks` could not reach asyncua's request processing) is judged
        here.
        """
        if not admitted:
            status = self.admit(peer)
            if status is not None:
                return status
        loop = asyncio.get_running_loop()
        timer = loop.call_later(self.limits.activate_within_s, self._expire, session)
        self._open[session] = (peer, _address(peer))
        self._pending[session] = _Pending(peer, _address(peer), timer)
        return None

    def activated(self, session: object) -> None:
        pending = self._pending.pop(session, None)
        if pending is not None:
            pending.timer.cancel()

    def closed(self, session: object) -> None:
        self._drop(session)

    def close(self) -> None:
        """The server stopped: no session is left to expire."""
        for pending in self._pending.values():
            pending.timer.cancel()
        self._pending.clear()
        self._open.clear()

    @property
    def sessions(self) -> int:
        return len(self._open)

    @property
    def unactivated(self) -> int:
        return len(self._pending)

    def _expire(self, session: object) -> None:
        if session not in self._pending:
            return
        self._drop(session)
        self.sessions_refused["expired"] += 1
        _log.debug("opcua: closed a session not activated in %g s", self.limits.activate_within_s)
        self._close(session)

    def _drop(self, session: object) -> None:
        self._open.pop(session, None)
        pending = self._pending.pop(session, None)
        if pending is not None:
            pending.timer.cancel()

    def _count(self, match: Callable[[_Pending], bool]) -> int:
        # The unactivated are few (each connection and address holds a handful): a scan.
        return sum(1 for pending in self._pending.values() if match(pending))

    def _held(self, field: int, key: Hashable) -> int:
        """Sessions open whose peer (*field* 0) or address (1) is *key* (at most
        max_connections: a scan, once per CreateSession)."""
        return sum(1 for held in self._open.values() if held[field] == key)


def _address(peer: Peer) -> Hashable:
    """The client's address (the host of its peer name; the whole name when it has none)."""
    return peer[0] if peer else peer
