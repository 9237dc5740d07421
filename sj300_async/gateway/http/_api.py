"""The HTTP northbound's routes: the workbench page, its JSON API and event stream, /metrics.

docs/WORKBENCH_API.md describes each route for scripts; the page is one
of its clients. Every route here reads
(the routes that write are :mod:`._write_api`'s, added only when the
gateway grants writes and names who may make them).

Decisions:

- Paths are versioned (``/api/v1/...``) so that a script written today
  keeps working when the API grows.
- An error is JSON ``{"error": "..."}`` with its 4xx status, for scripts
  and the page alike; a path that names no drive is 404, a malformed
  query 400.
- The page and its assets ship inside the package (``static/``): plants
  are air-gapped, so nothing is fetched from elsewhere at run time, and
  the Content-Security-Policy says so to the browser (``'self'`` only).
- Every response says ``nosniff``, refuses framing and sends no referrer.
- An event stream counts against its client address's streams
  (``max_streams_per_address``, :mod:`._guards`): past them, 429.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
import logging
import math
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Final

from aiohttp import web
from prometheus_client import CollectorRegistry

from .. import ConnectionLimit, Endpoint, GatewayDrive
from ._events import KEEPALIVE
from ._guards import PerAddress, client_address
from ._json import trip_log_json, unix_time
from ._linetrace import KEEP_S, LineTrace
from ._parameters import ParameterRoutes
from ._replies import find_drive, json_error, json_reply
from ._server import (
    DEFAULT_BODY_TIMEOUT_S,
    HttpServer,
    health_response,
    metrics_response,
    serve_app,
)
from ._trip_api import TripRoutes
from ._workbench import Workbench
from ._write_api import WriteRoutes

__all__ = ["STATIC_DIR", "make_app", "operations_app", "serve_http"]

_log = logging.getLogger("sj300_async.gateway.http")

#: The page and its assets (the vendored libraries under ``vendor/``).
STATIC_DIR: Final = Path(__file__).parent / "static"
#: Seconds between two keep-alive comments on an idle event stream.
KEEPALIVE_S: Final = 15.0
#: Seconds a client may take to accept one write of its event stream before it is closed.
STREAM_WRITE_TIMEOUT_S: Final = 30.0

_HEADERS: Final = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Content-Security-Policy": (
        "default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; "
        "frame-ancestors 'none'; base-uri 'none'; form-action 'self'"
    ),
}
_WORKBENCH: Final = web.AppKey("workbench", Workbench)
_PER_ADDRESS: Final = web.AppKey("per_address", PerAddress)


def operations_app(registry: CollectorRegistry, health: Callable[[], list[str]]) -> web.Application:
    """An application with /metrics (from *registry*) and /healthz (from *health*) alone."""
    app = web.Application(client_max_size=64 * 1024)

    async def metrics(request: web.Request) -> web.Response:
        return metrics_response(registry)

    async def healthz(request: web.Request) -> web.Response:
        return health_response(health())

    app.router.add_get("/metrics", metrics)
    app.router.add_get("/healthz", healthz)
    app.on_response_prepare.append(_security_headers)
    return app


def make_app(
    workbench: Workbench,
    registry: CollectorRegistry,
    health: Callable[[], list[str]],
    writes: WriteRoutes | None = None,
    per_address: PerAddress | None = None,
) -> web.Application:
    """The whole application: page, API, events, /metrics and /healthz; with *writes*,
    the routes that write (module _write_api). *per_address*: what each client address
    may hold and spend (module _guards; the defaults when None)."""
    app = operations_app(registry, health)
    app[_WORKBENCH] = workbench
    app[_PER_ADDRESS] = per_address = PerAddress() if per_address is None else per_address
    ParameterRoutes(workbench.gateway, per_address).add_to(app)
    TripRoutes(workbench.gateway).add_to(app)
    if writes is not None:
        writes.add_to(app)
    app.router.add_get("/", _index)
    app.router.add_static("/static/", STATIC_DIR, follow_symlinks=False)
    app.router.add_get("/api/v1/gateway", _gateway)
    app.router.add_get("/api/v1/lines", _lines)
    app.router.add_get("/api/v1/drives", _drives)
    app.router.add_get("/api/v1/drives/{line}/{node}", _drive)
    app.router.add_get("/api/v1/drives/{line}/{node}/trend", _trend)
    app.router.add_get("/api/v1/drives/{line}/{node}/trend.csv", _trend_csv)
    app.router.add_get("/api/v1/drives/{line}/{node}/trips", _trips)
    app.router.add_get("/api/v1/lines/{line}/frames", _frames)
    app.router.add_get("/api/v1/lines/{line}/capture.pcapng", _capture)
    app.router.add_get("/api/v1/audit", _audit)
    app.router.add_get("/api/v1/events", _events)
    return app


async def _security_headers(request: web.Request, response: web.StreamResponse) -> None:
    response.headers["Server"] = "sj300-gateway"  # not the framework's name and version
    for name, value in _HEADERS.items():
        response.headers.setdefault(name, value)
    if request.path.startswith(("/static/", "/api/")) or request.path == "/":
        response.headers.setdefault("Cache-Control", "no-cache")


def _bench(request: web.Request) -> Workbench:
    return request.app[_WORKBENCH]


def _find(request: web.Request) -> GatewayDrive:
    return find_drive(_bench(request).gateway, request)


def _trace(request: web.Request) -> LineTrace:
    name = request.match_info["line"]
    trace = _bench(request).traces.get(name)
    if trace is None:
        raise json_error(404, f"no line {name[:64]!r}")
    return trace


def _seconds(request: web.Request, default: float) -> float:
    text = request.query.get("seconds")
    if text is None:
        return default
    try:
        seconds = float(text)
    except ValueError:
        seconds = math.nan
    if not 0 < seconds <= KEEP_S:
        raise json_error(400, f"seconds: expected 0 < seconds <= {KEEP_S:g}, got {text[:32]!r}")
    return seconds


def _node(request: web.Request) -> int | None:
    text = request.query.get("node")
    if text is None or text == "":
        return None
    if not (text.isascii() and text.isdigit() and len(text) <= 3):
        raise json_error(400, f"node: expected a node number, got {text[:32]!r}")
    return int(text)


async def _frames(request: web.Request) -> web.Response:
    trace = _trace(request)
    seconds = _seconds(request, 10.0)
    frames = trace.frames(seconds, node=_node(request))
    return json_reply({"line": trace.name, "seconds": seconds, "frames": frames})


async def _capture(request: web.Request) -> web.Response:
    trace = _trace(request)
    seconds = _seconds(request, 60.0)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    return web.Response(
        body=trace.pcapng(seconds),
        content_type="application/x-pcapng",
        headers={"Content-Disposition": f'attachment; filename="{trace.name}-{stamp}.pcapng"'},
    )


async def _audit(request: web.Request) -> web.Response:
    """The latest writes, newest first, as the audit log records them."""
    text = request.query.get("limit", "200")
    if not (text.isascii() and text.isdigit() and 1 <= int(text[:5]) <= 1000):
        raise json_error(400, f"limit: expected 1..1000, got {text[:32]!r}")
    recent = _bench(request).gateway.audit.recent
    limit = int(text)
    records = [recent[-i] for i in range(1, min(limit, len(recent)) + 1)]
    return json_reply({"records": records, "kept": recent.maxlen})


async def _index(request: web.Request) -> web.FileResponse:
    return web.FileResponse(STATIC_DIR / "index.html")


async def _gateway(request: web.Request) -> web.Response:
    return json_reply(_bench(request).gateway_json())


async def _lines(request: web.Request) -> web.Response:
    bench = _bench(request)
    return json_reply([bench.line_json(line) for line in bench.gateway.lines])


async def _drives(request: web.Request) -> web.Response:
    bench = _bench(request)
    return json_reply([bench.drive_json(drive.served) for drive in bench.gateway.drives])


async def _drive(request: web.Request) -> web.Response:
    return json_reply(_bench(request).drive_json(_find(request).served))


def _since(request: web.Request) -> float | None:
    text = request.query.get("since")
    if text is None:
        return None
    try:
        since = float(text)
    except ValueError:
        since = math.nan
    if not math.isfinite(since):
        raise json_error(400, f"since: expected Unix seconds, got {text[:32]!r}")
    return since


async def _trend(request: web.Request) -> web.Response:
    capacity, columns = _bench(request).trend(_find(request), _since(request))
    return json_reply({"capacity": capacity, **columns})


async def _trend_csv(request: web.Request) -> web.Response:
    drive = _find(request)
    _, columns = _bench(request).trend(drive, _since(request))
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\r\n")
    names = ["output_frequency_hz", "output_current_a", "output_voltage_v"]
    writer.writerow(["time_utc", "time_unix", *names])
    for row, time in enumerate(columns["time"]):
        assert time is not None
        at = round(time, 3)  # once, for both columns (isoformat cuts, an f-string rounds)
        stamp = datetime.fromtimestamp(at, UTC).isoformat(timespec="milliseconds")
        values = ["" if columns[name][row] is None else columns[name][row] for name in names]
        writer.writerow([stamp, f"{at:.3f}", *values])
    line, node = drive.key
    return web.Response(
        text=out.getvalue(),
        content_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="{line}-{node}-trend.csv"'},
    )


async def _trips(request: web.Request) -> web.Response:
    snapshot = _find(request).snapshot
    return json_reply(trip_log_json(snapshot.trips, unix_time(snapshot, snapshot.trips_at)))


async def _events(request: web.Request) -> web.StreamResponse:
    """Server-sent events: everything as of now, then each change (module _events)."""
    streams, address = request.app[_PER_ADDRESS].streams, client_address(request)
    streams.acquire(address)
    try:
        return await _stream_events(request)
    finally:
        streams.release(address)


async def _stream_events(request: web.Request) -> web.StreamResponse:
    bench = _bench(request)
    response = web.StreamResponse(
        headers={
            "Content-Type": "text/event-stream",
            "Cache-Control": "no-cache",
            "X-Accel-Buffering": "no",  # a reverse proxy must not hold events back
        }
    )
    stream = bench.hub.open()
    try:
        for subject, frame in bench.everything():
            stream.put(subject, frame)
        await response.prepare(request)
        await response.write(b"retry: 2000\n\n")
        while True:
            chunk = await stream.take(KEEPALIVE_S)
            if chunk is None:
                break
            transport = request.transport
            if transport is not None and transport.get_write_buffer_size() == 0:
                # The client has taken everything so far: the write goes to the socket
                # without waiting, and needs no timer (one per write per stream costs).
                await response.write(chunk or KEEPALIVE)
                continue
            async with asyncio.timeout(STREAM_WRITE_TIMEOUT_S):
                await response.write(chunk or KEEPALIVE)
    except (ConnectionError, TimeoutError) as exc:
        _log.debug("http %s: event stream ended: %r", request.remote, exc)
    finally:
        bench.hub.discard(stream)
    with contextlib.suppress(ConnectionError):
        await response.write_eof()
    return response


async def serve_http(
    endpoint: Endpoint,
    registry: CollectorRegistry,
    health: Callable[[], list[str]],
    *,
    limit: ConnectionLimit | None = None,
    idle_timeout_s: float = 5.0,
    body_timeout_s: float = DEFAULT_BODY_TIMEOUT_S,
) -> HttpServer:
    """Serve /metrics and /healthz alone at *endpoint* (what a test or a tool needs)."""
    return await serve_app(
        endpoint,
        operations_app(registry, health),
        limit=limit,
        idle_timeout_s=idle_timeout_s,
        body_timeout_s=body_timeout_s,
    )
