"""The HTTP listener: an aiohttp application behind the gateway's own accept loop.

Decisions:

- aiohttp serves HTTP (parsing, keep-alive, routing, static files,
  streamed responses for server-sent events): the workbench needs all of
  it, and a framework that thousands of services run is a better parser of
  what browsers and scanners send than the two-route server it replaces.
- The sockets are the gateway's :class:`~sj300_async.gateway.Listener`, as
  the Modbus server's: at ``max_connections`` a newcomer is accepted and
  closed at once, and an accept that fails for want of descriptors pauses
  the listener instead of logging a traceback per attempt. Each admitted
  connection gets aiohttp's protocol wrapped in :class:`_Connection`, which
  releases the slot when the connection ends. At ``max_connections`` a
  newcomer from an address holding fewer takes the place of the heaviest
  address's connection idle the longest (no request in progress, the
  longest since its last one ended: :class:`~sj300_async.gateway.Slot`).
- **Idle connections are closed.** A connection may go ``idle_timeout_s``
  without a request in progress (from the moment it opens, and from the
  end of each request): a client that never sends a request, or sends its
  head a byte at a time, is closed and counted
  (``sj300_http_connections_timed_out_total``). A request in progress is
  never timed out by this rule, so an event stream stays open as long as
  its client reads it. aiohttp's own keep-alive timer, at twice the
  value, is a second guard.
- **A request has ``body_timeout_s`` for its head and its body** (default
  :data:`DEFAULT_BODY_TIMEOUT_S`), counted from its first byte (issue 41:
  64 POSTs announcing 100 kB and sending nothing held every slot for
  24-32 s, and /healthz, the workbench's Stop button and its lease
  heartbeats got resets). Past it, a handler waiting for the body gets
  :class:`BodyTimeout` from its read, answered 408 and the connection
  closed; a body nobody reads (a route that answered first, or a stream)
  is cut by closing the connection. Each is counted
  (``sj300_http_requests_timed_out_total``) and logged at DEBUG.
- **aiohttp's lingering is bounded by the same deadline.** A handler that
  answers before reading the body (a 429, a 405) leaves aiohttp reading
  and discarding it for up to its ``lingering_time`` (10 s by default),
  the slot held all the while: the deadline ends that too (the lingering
  read gets :class:`BodyTimeout`, a ``TimeoutError``, which aiohttp takes
  as the end of lingering and closes), and ``lingering_time`` is set to
  ``body_timeout_s`` besides.
- The request head is bounded by aiohttp's limits (:data:`MAX_LINE_BYTES`
  per line and per header field); a body by each route's own limit
  (:mod:`._bodies`).
- The scrape (``/metrics``) runs on the event loop, like everything that
  updates the counters it reads, so one scrape sees one consistent state;
  prometheus_client's own server would read them from a thread.
- **A client that goes away is not an error**: a stream it closed (the
  documented way to stop one), a body it cut. What a handler then raises
  (``ConnectionError``, aiohttp's ``ClientConnectionResetError`` among
  them, or ``ClientPayloadError``) is one DEBUG line with a bounded
  excerpt, never an ERROR with a traceback: a client must not be able to
  write the gateway's log.
- Nothing is dropped silently: an error inside a handler is logged with its
  traceback and answered 500; every refusal (4xx: a malformed request
  aiohttp's parser refused, an unknown path, a wrong method) is logged at
  DEBUG with an escaped, bounded excerpt of the bytes the request came in
  (:class:`_Refusals`, aiohttp's access-log hook, which sees the parser's
  refusals too, where the application's middleware does not).
"""

from __future__ import annotations

import asyncio
import logging
import socket
import ssl
from collections.abc import Awaitable, Callable, Iterable
from typing import TYPE_CHECKING, Final, cast

from aiohttp import ClientPayloadError, web
from aiohttp.abc import AbstractAccessLogger
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest

from .. import ConnectionLimit, Endpoint, Listener, Slot, excerpt
from . import DEFAULT_BODY_TIMEOUT_S
from ._replies import json_error

if TYPE_CHECKING:
    from aiohttp.web_protocol import RequestHandler
    from aiohttp.web_request import BaseRequest
    from prometheus_client.core import Metric

__all__ = [
    "DEFAULT_BODY_TIMEOUT_S",
    "MAX_LINE_BYTES",
    "BodyTimeout",
    "HttpServer",
    "health_response",
    "make_registry",
    "metrics_response",
    "serve_app",
]

_log = logging.getLogger("sj300_async.gateway.http")

#: The longest request line, and the longest header field, accepted (aiohttp's limits).
MAX_LINE_BYTES: Final = 8190
#: What a handler raises when its client went away (module docstring).
_CLIENT_GONE: Final = (ConnectionError, ClientPayloadError)


class BodyTimeout(TimeoutError):
    """The request's body did not come within ``body_timeout_s`` (its read raises this).

    A ``TimeoutError``: aiohttp's lingering read takes it as the end of lingering.
    """


Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


class _Collector:
    """A prometheus_client collector calling *collect* at each scrape."""

    def __init__(self, collect: Callable[[], Iterable[Metric]]) -> None:
        self._collect = collect

    def collect(self) -> Iterable[Metric]:
        return self._collect()


def make_registry(collect: Callable[[], Iterable[Metric]]) -> CollectorRegistry:
    """A new registry whose one collector is *collect* (not the global default registry).

    Two gateways in one process (tests) do not collide, and no process or
    platform collector sneaks in.
    """
    registry = CollectorRegistry()
    registry.register(_Collector(collect))
    return registry


def metrics_response(registry: CollectorRegistry) -> web.Response:
    """``/metrics``: the classic text format, whatever the scraper's ``Accept`` says.

    Prometheus reads it, and nothing exported here needs what OpenMetrics
    adds (exemplars, ``_created``).
    """
    response = web.Response(body=generate_latest(registry))
    response.headers["Content-Type"] = CONTENT_TYPE_LATEST
    return response


def health_response(problems: list[str]) -> web.Response:
    """``/healthz``: 200 ``ok``, or 503 with the gateway's problems one per line."""
    if not problems:
        return web.Response(text="ok\n")
    return web.Response(status=503, text="".join(f"{problem}\n" for problem in problems))


class HttpServer:
    """An aiohttp application served on a :class:`~sj300_async.gateway.Listener`."""

    def __init__(
        self,
        app: web.Application,
        limit: ConnectionLimit,
        idle_timeout_s: float,
        tls: ssl.SSLContext | None = None,
        body_timeout_s: float = DEFAULT_BODY_TIMEOUT_S,
    ):
        self.limit = limit
        self.tls = tls
        self.idle_timeout_s = idle_timeout_s
        self.body_timeout_s = body_timeout_s
        #: Requests whose head and body did not come within body_timeout_s, since the start.
        self.timed_out = 0
        server = self

        class Refusals(_Refusals):
            def connection(self, request: BaseRequest) -> _Connection | None:
                return server._connections.get(request.protocol)

        self._runner = web.AppRunner(
            app,
            handle_signals=False,
            access_log=_log,
            access_log_class=Refusals,
            # The idle rule is ours (_Connection), which counts what it closes;
            # aiohttp's own timer is the second guard, behind it.
            keepalive_timeout=2 * idle_timeout_s,
            max_line_size=MAX_LINE_BYTES,
            max_field_size=MAX_LINE_BYTES,
            # An unread body is read and dropped at most this long after the answer
            # (the body's deadline usually ends it sooner: module docstring).
            lingering_time=body_timeout_s,
            # A stopping gateway waits this long for requests in progress (event
            # streams end on their own when the northbound closes them first).
            shutdown_timeout=2.0,
        )
        self._listener: Listener | None = None
        self._closing: asyncio.Future[None] | None = None
        self._connections: dict[RequestHandler, _Connection] = {}
        app.middlewares.insert(0, self._track)  # outermost: it sees every request

    @property
    def sockets(self) -> list[socket.socket]:
        return [] if self._listener is None else list(self._listener.sockets)

    @property
    def port(self) -> int:
        """The port it listens on (the real one when asked for port 0), 0 when not started."""
        if self._listener is None or not self._listener.sockets:
            return 0
        return int(self._listener.sockets[0].getsockname()[1])

    async def start(self, endpoint: Endpoint) -> None:
        """Listen on *endpoint*.

        Raises:
            OSError: the address cannot be bound (nothing is left running).
        """
        await self._runner.setup()
        server = self._runner.server
        assert server is not None

        def factory(address: str) -> asyncio.BaseProtocol:
            return _Connection(server(), self, address)

        self._listener = Listener(
            factory, self.limit, tls=self.tls, handshake_timeout_s=self.idle_timeout_s
        )
        try:
            await self._listener.start(endpoint.host, endpoint.port)
        except BaseException:
            self._listener = None
            await self._runner.cleanup()
            raise

    def close(self) -> None:
        """Stop listening and start closing every connection (see :meth:`wait_closed`)."""
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        if self._closing is None:
            self._closing = asyncio.ensure_future(self._runner.cleanup())

    async def wait_closed(self) -> None:
        """Wait until every connection is closed (requests in progress get a moment)."""
        if self._closing is not None:
            await self._closing

    @web.middleware
    async def _track(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        connection = self._connections.get(request.protocol)
        if connection is not None:
            connection.begin(request)
        try:
            return await handler(request)
        except web.HTTPException:
            raise
        except BodyTimeout:
            error = json_error(
                408, f"the request did not come whole within {self.body_timeout_s:g} s"
            )
            error.force_close()
            raise error from None
        except _CLIENT_GONE as exc:  # module docstring: a DEBUG line, not an ERROR
            _log.debug(
                "http %s: %s %s: the client went away: %s",
                request.remote,
                request.method,
                excerpt(request.path),
                excerpt(repr(exc)),
            )
            gone = web.Response(status=400, text="the connection was cut\n")
            gone.force_close()  # its write fails quietly, or ends what is left
            return gone
        except Exception:
            _log.exception(
                "http %s: %s %s failed", request.remote, request.method, excerpt(request.path)
            )
            raise web.HTTPInternalServerError(text="internal error\n") from None
        finally:
            if connection is not None:
                connection.end()


#: Bytes of a request's head kept for the log line of its refusal.
_KEPT_BYTES: Final = 256


class _Refusals(AbstractAccessLogger):
    """aiohttp's access log, used to log each refusal (4xx) with what the client sent."""

    def connection(self, request: BaseRequest) -> _Connection | None:
        raise NotImplementedError

    def log(self, request: BaseRequest, response: web.StreamResponse, time: float) -> None:
        connection = self.connection(request)
        received = b""
        if connection is not None:  # the next request's bytes start afresh
            received = bytes(connection.received)
            connection.received.clear()
        if not 400 <= response.status < 500:
            return
        self.logger.debug(
            "http %s: refused %d %s; received: %s",
            request.remote,
            response.status,
            response.reason,
            excerpt(received),
        )


class _Connection(asyncio.Protocol):
    """aiohttp's protocol for one connection: releases its slot, closes it when idle, and
    holds each request to its deadline."""

    def __init__(self, handler: RequestHandler, server: HttpServer, address: str) -> None:
        self._handler = handler
        self._server = server
        #: The client's address as the listener admitted it (the slot's key).
        self.address = address
        self._loop = asyncio.get_running_loop()
        self._transport: asyncio.Transport | None = None
        self._busy = 0
        self._timer: asyncio.TimerHandle | None = None
        #: The request begun last (kept until its body is in: its deadline's subject).
        self._request: BaseRequest | None = None
        #: Loop time of the next request's first byte (None: none of it seen yet).
        self._first_byte_at: float | None = None
        self._deadline: asyncio.TimerHandle | None = None
        #: The first bytes received since the last request ended (for a refusal's log).
        self.received = bytearray()
        #: Its place in the limit, once made (idle between requests: a newcomer's to take).
        self._slot: Slot | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not isinstance(): uvloop's transports implement the interface without
        # deriving from asyncio's classes.
        transport = cast(asyncio.Transport, transport)
        self._transport = transport
        self._server._connections[self._handler] = self
        self._slot = self._server.limit.hold(self.address, self._evict)
        self._handler.connection_made(transport)
        self._arm()

    def data_received(self, data: bytes) -> None:
        if self._first_byte_at is None and (
            self._request is None or self._request.content.is_eof()
        ):  # not the last request's body: the next request's first bytes
            self._first_byte_at = self._loop.time()
        if len(self.received) < _KEPT_BYTES:
            self.received += data[: _KEPT_BYTES - len(self.received)]
        self._handler.data_received(data)

    def eof_received(self) -> None:
        self._handler.eof_received()

    def pause_writing(self) -> None:
        self._handler.pause_writing()

    def resume_writing(self) -> None:
        self._handler.resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        self._cancel_deadline()
        self._request = None
        if self.received and not self._busy:  # bytes of a request that never came whole
            _log.debug(
                "http %s: closed before a whole request came; received: %s",
                None if self._transport is None else self._transport.get_extra_info("peername"),
                excerpt(bytes(self.received)),
            )
        self._server._connections.pop(self._handler, None)
        try:
            self._handler.connection_lost(exc)
        finally:
            if self._slot is None:
                self._server.limit.release(self.address)
            else:  # released already if it was closed for a newcomer
                self._slot.release()

    # -- the idle rule and the body's deadline (module docstring) --------------------------

    def begin(self, request: BaseRequest) -> None:
        self._busy += 1
        self._disarm()
        if self._slot is not None:  # a request in progress is never closed for a newcomer
            self._slot.busy()
        started = self._loop.time() if self._first_byte_at is None else self._first_byte_at
        self._first_byte_at = None
        self._request = request
        self._cancel_deadline()
        if not request.content.is_eof():
            self._deadline = self._loop.call_at(
                started + self._server.body_timeout_s, self._body_late
            )

    def end(self) -> None:
        self._busy -= 1
        if self._busy == 0:
            self._arm()
            if self._slot is not None:  # idle from now: the last of its address to go
                self._slot.active()

    def _arm(self) -> None:
        self._disarm()
        self._timer = self._loop.call_later(self._server.idle_timeout_s, self._expire)

    def _cancel_deadline(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _body_late(self) -> None:
        """The request's deadline: a body not in yet is cut (module docstring)."""
        self._deadline = None
        request, transport = self._request, self._transport
        if request is None or request.content.is_eof() or transport is None:
            return
        if transport.is_closing():
            return
        self._server.timed_out += 1
        _log.debug(
            "http %s: %s %s: not whole within %g s, closed; received: %s",
            self.address,
            request.method,
            excerpt(request.path),
            self._server.body_timeout_s,
            excerpt(bytes(self.received)),
        )
        # A handler reading the body gets the error and answers 408; aiohttp's lingering
        # read takes it as the end. With nobody to answer (the handler is done, or its
        # answer is under way: a stream), the connection is closed now.
        request.content.set_exception(BodyTimeout())
        if not self._busy or request.writer.output_size > 0:
            transport.close()

    def _evict(self) -> None:
        """Closed for a newcomer at max_connections (the limit counted and logged it).

        Aborted, not closed: the slot is already the newcomer's, and a close would
        wait for a client that does not read to take what is buffered."""
        if self._transport is not None:
            self._transport.abort()

    def _disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _expire(self) -> None:
        self._timer = None
        if self._busy or self._transport is None or self._transport.is_closing():
            return
        self._server.limit.timed_out += 1
        _log.debug(
            "http %s: no request for %g s, closed; received: %s",
            self._transport.get_extra_info("peername"),
            self._server.idle_timeout_s,
            excerpt(bytes(self.received)),
        )
        self.received.clear()
        self._transport.close()


async def serve_app(
    endpoint: Endpoint,
    app: web.Application,
    *,
    limit: ConnectionLimit | None = None,
    idle_timeout_s: float = 5.0,
    tls: ssl.SSLContext | None = None,
    body_timeout_s: float = DEFAULT_BODY_TIMEOUT_S,
) -> HttpServer:
    """Serve *app* at *endpoint* (port 0: a free one, :attr:`HttpServer.port`), over TLS
    when *tls* is given.

    Raises:
        OSError: the address cannot be bound.
    """
    connections = ConnectionLimit("http", 1 << 30, _log) if limit is None else limit
    server = HttpServer(app, connections, idle_timeout_s, tls, body_timeout_s)
    await server.start(endpoint)
    return server
