"""The link: one connection to the line, kept up by reconnecting with capped backoff.

A connector opens a transport (TCP, serial, in-memory); the link owns the
resulting :class:`LineProtocol`. When the connection drops, the supervisor
(run in the bus's task group) reconnects: the first attempt after
``initial_s``, then exponentially longer up to ``max_s``, each delay
multiplied by a random factor in ``[1 - jitter, 1]`` so that many clients
of one device server do not reconnect in lock-step. While the link is down,
:meth:`Link.require` raises :class:`TransportError` at once: a request fails
promptly instead of hanging, and the next one after the server is back
succeeds.
"""

from __future__ import annotations

import asyncio
import logging
import random
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from ..wire import BusClosedError, LocalProtocolError, TransportError
from ._protocol import LineProtocol
from ._stats import BusStats

__all__ = ["Connector", "Link", "ReconnectPolicy"]

_log = logging.getLogger("sj300_async.link")

#: Opens a transport for the protocol the factory makes; raises OSError (or
#: TransportError) on failure.
Connector = Callable[[Callable[[], LineProtocol[Any]]], Awaitable[asyncio.BaseTransport]]


@dataclass(frozen=True, slots=True)
class ReconnectPolicy:
    """When and how often a dropped link is reconnected."""

    #: Reconnect at all? (False: a dropped link stays down until the bus is reopened.)
    enabled: bool = True
    #: Delay before the first attempt.
    initial_s: float = 0.1
    #: Cap of the delay between attempts.
    max_s: float = 5.0
    #: Growth of the delay per failed attempt.
    factor: float = 2.0
    #: Each delay is multiplied by a random factor in [1 - jitter, 1].
    jitter: float = 0.5
    #: Time allowed for one connection attempt.
    connect_timeout_s: float = 3.0

    def __post_init__(self) -> None:
        if not (0 < self.initial_s <= self.max_s and self.factor >= 1 and 0 <= self.jitter <= 1):
            raise LocalProtocolError(f"invalid reconnect policy: {self!r}")
        if not self.connect_timeout_s > 0:
            raise LocalProtocolError("connect_timeout_s must be > 0")

    def delay(self, failures: int, rng: random.Random) -> float:
        """Delay before the next attempt after *failures* failed ones."""
        base = min(self.max_s, self.initial_s * self.factor**failures)
        return base * (1 - self.jitter * rng.random())


class Link:
    """One connection to the line and the policy that keeps it up."""

    def __init__(
        self,
        connector: Connector,
        make_protocol: Callable[[], LineProtocol[Any]],
        stats: BusStats,
        *,
        description: str,
        policy: ReconnectPolicy | None = None,
        rng: random.Random | None = None,
    ) -> None:
        self._connector = connector
        self._make_protocol = make_protocol
        self._stats = stats
        self.description = description
        self.policy = policy or ReconnectPolicy()
        self._rng = rng or random.Random()
        self._protocol: LineProtocol[Any] | None = None
        self._closed = False
        self._last_error: BaseException | None = None
        self._next_attempt: float | None = None
        self._up = asyncio.Event()
        self._on_connected: list[Callable[[], None]] = []

    @property
    def connected(self) -> bool:
        """True while a connection is up."""
        return self._protocol is not None and self._protocol.connected

    @property
    def closed(self) -> bool:
        """True once the link was closed (by the bus's owner): it takes no more requests."""
        return self._closed

    @property
    def last_error(self) -> BaseException | None:
        """Why the link is down: the last failed attempt or the lost connection's error.

        None while connected, and before the first attempt.
        """
        return None if self.connected else self._last_error

    @property
    def protocol(self) -> LineProtocol[Any] | None:
        """The current protocol adapter, if connected."""
        return self._protocol if self.connected else None

    def require(self) -> LineProtocol[Any]:
        """Return the connected protocol, or raise at once.

        Raises:
            BusClosedError: the bus was closed.
            TransportError: the link is down (a reconnect may be under way).
        """
        if self._closed:
            raise BusClosedError(f"bus {self.description} is closed")
        protocol = self._protocol
        if protocol is not None and protocol.connected:
            return protocol
        detail = f": {self._last_error}" if self._last_error else ""
        if self._next_attempt is not None:
            wait = max(0.0, self._next_attempt - asyncio.get_running_loop().time())
            detail += f" (reconnecting, next attempt in {wait:.2f} s)"
        raise TransportError(f"{self.description} is not connected{detail}")

    async def wait_connected(self) -> None:
        """Return once the link is up (for callers that prefer to wait)."""
        await self._up.wait()

    def on_connected(self, callback: Callable[[], None]) -> Callable[[], None]:
        """Call *callback* each time the link comes up; returns what unregisters it.

        It runs inside the connection's set-up, before any waiting task can
        send: a caller whose request must be the first on a new connection
        (the gateway's pending stop) holds the others back from here. A
        callback that raises is logged; the connection stands.
        """
        self._on_connected.append(callback)
        return lambda: self._on_connected.remove(callback)

    async def connect(self) -> None:
        """Open the connection once.

        Raises:
            TransportError: the connection could not be opened in time.
        """
        made: list[LineProtocol[Any]] = []

        def factory() -> LineProtocol[Any]:
            made.append(self._make_protocol())
            return made[-1]

        try:
            async with asyncio.timeout(self.policy.connect_timeout_s):
                transport = await self._connector(factory)
                await made[-1].made
        except TimeoutError:
            self._last_error = TimeoutError("connection attempt timed out")
            raise TransportError(
                f"could not connect to {self.description}: timed out after "
                f"{self.policy.connect_timeout_s:g} s"
            ) from None
        except TransportError as exc:
            self._last_error = exc
            raise
        except OSError as exc:
            self._last_error = exc
            raise TransportError(f"could not connect to {self.description}: {exc}") from exc
        protocol = made[-1]
        if self._closed:
            transport.close()
            raise BusClosedError(f"bus {self.description} closed while connecting")
        self._protocol = protocol
        self._last_error = None
        self._next_attempt = None
        self._stats.connects += 1
        for callback in list(self._on_connected):
            try:
                callback()
            except Exception:  # a caller's bug must not undo the connection
                _log.exception("an on_connected callback of %s failed", self.description)
        self._up.set()
        _log.info("connected to %s", self.description)

    async def supervise(self) -> None:
        """Reconnect whenever the connection drops, until the link is closed. Runs forever."""
        failures = 0
        while not self._closed:
            protocol = self._protocol
            if protocol is not None:
                exc = await asyncio.shield(protocol.lost)
                if self._closed:
                    return
                self._up.clear()
                self._stats.disconnects += 1
                self._last_error = exc or ConnectionResetError("connection closed by peer")
                _log.warning("lost %s: %s", self.description, self._last_error)
                self._protocol = None
                if not self.policy.enabled:
                    return
            delay = self.policy.delay(failures, self._rng)
            loop = asyncio.get_running_loop()
            self._next_attempt = loop.time() + delay
            await asyncio.sleep(delay)
            try:
                await self.connect()
            except BusClosedError:
                return
            except TransportError as exc:
                failures += 1
                _log.debug("reconnect to %s failed (%d): %s", self.description, failures, exc)
            else:
                failures = 0

    def drop(self) -> None:
        """Abort the current connection (tests; a caller that knows the line is broken)."""
        if self._protocol is not None:
            self._protocol.abort()

    def close(self) -> None:
        """Close the connection and stop reconnecting (idempotent)."""
        self._closed = True
        if self._protocol is not None:
            self._protocol.close()
