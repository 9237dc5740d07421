"""``GET /metrics`` and ``GET /healthz`` over a small asyncio HTTP/1.1 server.

Decisions:

- asyncio's own streams, no web framework and no thread: two read-only
  resources do not justify a dependency, and prometheus_client's own
  server runs in a thread, where it would read the buses' live counters
  while the event loop updates them. Here the scrape runs on the loop
  (:func:`prometheus_client.generate_latest` is synchronous and cheap: the
  families are built from counters the gateway keeps anyway), so it sees
  one consistent state.
- ``/metrics`` is always the classic text format (``CONTENT_TYPE_LATEST``),
  whatever the scraper's ``Accept`` says: Prometheus reads it, and nothing
  exported here needs what OpenMetrics adds (exemplars, ``_created``).
- One request per connection: every response says ``Connection: close``
  and the connection is closed after it. Scrapers and health probes make
  one request per interval; keep-alive would only add state.
- The request's header section is read and thrown away (nothing here
  depends on a header), within limits: more than :data:`MAX_HEAD_BYTES`
  or slower than the listener's ``idle_timeout_s`` (:data:`HEAD_TIMEOUT_S`
  unless configured) and the connection is closed without an answer, so a
  slow or endless client cannot hold a handler. Writing the response has
  the same time limit. At most ``max_connections`` are open at once: past
  it a newcomer is accepted and closed at once
  (:class:`~sj300_async.gateway.ConnectionLimit`, the Modbus listener's
  too).
- A malformed request line gets 400, a path other than the two 404, a
  method other than GET and HEAD on them 405 (with ``Allow``). HEAD
  answers the GET's status and headers, without the body.
- Nothing is dropped silently (project rule): a refused or abandoned
  request is logged at DEBUG with the bytes received, in hex; a failure
  while building a response is logged with its traceback and answered
  with 500.
"""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from typing import Final

from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest
from prometheus_client.core import Metric

from .. import ConnectionLimit, Endpoint, Listener

__all__ = ["HEAD_TIMEOUT_S", "MAX_HEAD_BYTES", "make_registry", "serve_http"]

_log = logging.getLogger("sj300_async.gateway.http")

#: The largest request line plus header section accepted, in bytes.
MAX_HEAD_BYTES: Final = 8 * 1024
#: Seconds a client has to send its request line and headers (and to take the response).
HEAD_TIMEOUT_S: Final = 5.0

_TEXT: Final = "text/plain; charset=utf-8"
_REASONS: Final = {
    200: "OK",
    400: "Bad Request",
    404: "Not Found",
    405: "Method Not Allowed",
    500: "Internal Server Error",
    503: "Service Unavailable",
}
#: ``METHOD SP request-target SP HTTP-version`` (RFC 9112, section 3): origin-form
#: targets only, printable ASCII (so that decoding them cannot fail).
_REQUEST_LINE: Final = re.compile(rb"([!#$%&'*+.^_`|~0-9A-Za-z-]+) (/[!-~]*) HTTP/\d\.\d")
_ALLOWED: Final = "GET, HEAD"


@dataclass(frozen=True, slots=True)
class _Response:
    status: int
    body: bytes
    content_type: str = _TEXT
    #: Extra header lines, without their CRLF.
    headers: tuple[str, ...] = ()

    def encode(self, *, head_only: bool) -> bytes:
        """The whole response; with *head_only*, its head (Content-Length still the body's)."""
        lines = [
            f"HTTP/1.1 {self.status} {_REASONS[self.status]}",
            f"Content-Type: {self.content_type}",
            f"Content-Length: {len(self.body)}",
            "Connection: close",
            *self.headers,
        ]
        head = ("\r\n".join(lines) + "\r\n\r\n").encode("ascii")
        return head if head_only else head + self.body


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


class _BadRequest(Exception):
    """The request head was too large, too slow, cut off or malformed."""

    def __init__(self, reason: str, received: bytes, *, timed_out: bool = False) -> None:
        super().__init__(reason)
        self.received = received
        #: The client was too slow (counted as a time-out), rather than wrong.
        self.timed_out = timed_out


async def serve_http(
    endpoint: Endpoint,
    registry: CollectorRegistry,
    health: Callable[[], list[str]],
    *,
    limit: ConnectionLimit | None = None,
    timeout_s: float | None = None,
) -> Listener:
    """Serve ``/metrics`` from *registry* and ``/healthz`` from *health* at *endpoint*.

    Args:
        endpoint: where to listen; port 0 picks a free port (read it from
            ``server.sockets[0].getsockname()``).
        health: returns the gateway's problems now, one line each; none
            means healthy (200 ``ok``), any means 503 with them as the body.
        limit: admits each connection (None: no cap to speak of); counts the
            timed-out ones.
        timeout_s: seconds a client has to send its request head, and to take
            the response (None: :data:`HEAD_TIMEOUT_S`).

    Returns:
        The listening server; close it with ``close()`` and ``wait_closed()``.
    """
    routes: dict[str, Callable[[], _Response]] = {
        "/metrics": lambda: _Response(200, generate_latest(registry), CONTENT_TYPE_LATEST),
        "/healthz": lambda: _health_response(health()),
    }
    timeout = HEAD_TIMEOUT_S if timeout_s is None else timeout_s
    connections = ConnectionLimit("http", 1 << 30, _log) if limit is None else limit

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if not await _handle(reader, writer, routes, timeout):
            connections.timed_out += 1

    def protocol() -> asyncio.StreamReaderProtocol:
        # limit: a single line longer than the whole head allowance fails readline() at once.
        reader = asyncio.StreamReader(limit=MAX_HEAD_BYTES)
        return _Counted(reader, handle, connections)

    server = Listener(protocol, connections)
    await server.start(endpoint.host, endpoint.port)
    return server


class _Counted(asyncio.StreamReaderProtocol):
    """asyncio's stream protocol (what ``start_server`` makes), releasing its slot at the end."""

    def __init__(
        self,
        reader: asyncio.StreamReader,
        handle: Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]],
        limit: ConnectionLimit,
    ) -> None:
        super().__init__(reader, handle)
        self._limit = limit

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        self._limit.release()


def _health_response(problems: list[str]) -> _Response:
    if not problems:
        return _Response(200, b"ok\n")
    return _Response(503, "".join(f"{problem}\n" for problem in problems).encode())


async def _handle(
    reader: asyncio.StreamReader,
    writer: asyncio.StreamWriter,
    routes: dict[str, Callable[[], _Response]],
    timeout_s: float,
) -> bool:
    """Serve one request; False when the client was too slow (closed for it)."""
    peer = writer.get_extra_info("peername")
    try:
        try:
            request_line = await _read_head(reader, timeout_s)
        except _BadRequest as bad:
            _log.debug("http %s: %s, closed; received: %s", peer, bad, bad.received.hex(" "))
            return not bad.timed_out
        response, head_only = _respond(request_line, routes, peer)
        async with asyncio.timeout(timeout_s):
            writer.write(response.encode(head_only=head_only))
            await writer.drain()
    except TimeoutError:
        _log.debug("http %s: the response not taken within %g s", peer, timeout_s)
        return False
    except ConnectionError as exc:
        # The client went away: nothing left to answer.
        _log.debug("http %s: connection ended before the response was sent: %r", peer, exc)
    finally:
        writer.close()
        try:
            await writer.wait_closed()
        except ConnectionError:
            pass  # reset by the peer while closing: it is closed either way
    return True


async def _read_head(reader: asyncio.StreamReader, timeout_s: float) -> bytes:
    """Read the request line and the header section; return the request line.

    Raises:
        _BadRequest: the head is too large, cut off, or does not come in time.
    """
    received = bytearray()  # kept out here so that a refusal can log it
    try:
        async with asyncio.timeout(timeout_s):
            return await _read_lines(reader, received)
    except TimeoutError:
        raise _BadRequest(
            f"request head not complete within {timeout_s:g} s", bytes(received), timed_out=True
        ) from None
    except ValueError:
        # readline() found a line longer than the stream's limit, and dropped it.
        raise _BadRequest(
            f"request head over {MAX_HEAD_BYTES} bytes (a line over the limit, not shown)",
            bytes(received),
        ) from None


async def _read_lines(reader: asyncio.StreamReader, received: bytearray) -> bytes:
    """Read lines into *received* up to the empty line ending the head; return the first."""
    request_line: bytes | None = None
    while True:
        line = await reader.readline()
        received += line
        if len(received) > MAX_HEAD_BYTES:
            raise _BadRequest(f"request head over {MAX_HEAD_BYTES} bytes", bytes(received))
        if not line.endswith(b"\n"):
            raise _BadRequest("connection closed before the end of the head", bytes(received))
        if request_line is None:
            # RFC 9112 section 2.2: empty lines before the request line are ignored.
            if line.strip(b"\r\n"):
                request_line = line.rstrip(b"\r\n")
        elif line in (b"\r\n", b"\n"):
            return request_line


def _respond(
    request_line: bytes, routes: dict[str, Callable[[], _Response]], peer: object
) -> tuple[_Response, bool]:
    """The response to *request_line*, and whether to send its head only (HEAD)."""
    match = _REQUEST_LINE.fullmatch(request_line)
    if match is None:
        _log.debug("http %s: malformed request line: %s", peer, request_line.hex(" "))
        return _Response(400, b"malformed request line\n"), False
    method, target = match[1].decode("ascii"), match[2].decode("ascii")
    path = target.partition("?")[0]  # a query string changes nothing here
    route = routes.get(path)
    if route is None:
        _log.debug("http %s: no such path: %s", peer, request_line.hex(" "))
        return _Response(404, b"not found\n"), method == "HEAD"
    if method not in ("GET", "HEAD"):
        _log.debug("http %s: method not allowed: %s", peer, request_line.hex(" "))
        return _Response(405, b"method not allowed\n", headers=(f"Allow: {_ALLOWED}",)), False
    try:
        return route(), method == "HEAD"
    except Exception:
        _log.exception("http %s: %s failed", peer, path)
        return _Response(500, b"internal error\n"), method == "HEAD"
