"""The HTTP northbound, running: the workbench, its API and events, /metrics, /healthz."""

from __future__ import annotations

import asyncio
import dataclasses
import logging
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

from .. import ConnectionLimit, GatewayView, ServedDrive, ServedLine, listener_families
from . import HttpConfig
from ._api import make_app
from ._guards import AddressSlots, PerAddress
from ._server import HttpServer, make_registry, serve_app
from ._workbench import Workbench
from ._write_api import WriteRoutes

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["HttpNorthbound"]


def _fields_of(config: HttpConfig) -> list[str]:
    return [field.name for field in dataclasses.fields(config)]


_log = logging.getLogger("sj300_async.gateway.http")


class HttpNorthbound:
    """Serves the workbench and /metrics (a :class:`~sj300_async.gateway.Northbound`)."""

    def __init__(self, config: HttpConfig) -> None:
        self.config = config
        self.server: HttpServer | None = None
        self.workbench: Workbench | None = None
        #: The routes that write, when there are any (module _write_api).
        self.writes: WriteRoutes | None = None
        self._ticker: asyncio.Task[None] | None = None
        #: Open connections, and those refused at the caps or timed out.
        self.limit = ConnectionLimit(
            "http", config.limits.max_connections, _log, config.limits.per_address
        )
        #: What each client address may hold and spend (module _guards).
        self.per_address = PerAddress(AddressSlots(config.max_streams_per_address))

    async def start(self, gateway: GatewayView) -> None:
        config = self.config
        granted = any(line.grants for line in gateway.config.lines)
        tls = config.ssl_context()
        if granted and config.authentication:
            self.writes = WriteRoutes(
                gateway, config.users, config.tokens, secure_cookie=tls is not None
            )
        elif granted:
            _log.warning(
                "the workbench serves no writes: the configuration grants some, but [http] "
                "names nobody who may make them ([[http.users]] or [[http.tokens]])"
            )
        self.workbench = Workbench(gateway, config.trend_s, writes=self.writes is not None)
        app = make_app(
            self.workbench,
            make_registry(gateway.metrics),
            gateway.problems,
            self.writes,
            self.per_address,
        )
        self.server = await serve_app(
            config.listen,
            app,
            limit=self.limit,
            idle_timeout_s=config.limits.idle_timeout_s,
            tls=tls,
            body_timeout_s=config.body_timeout_s,
        )
        self._ticker = asyncio.create_task(self.workbench.run(), name="sj300-http-lines")

    async def lines_changed(
        self, added: Sequence[ServedLine], removed: Sequence[ServedLine]
    ) -> None:
        """A reload added or removed lines: the workbench's trends and traces follow."""
        if self.workbench is not None:
            self.workbench.lines_changed(added, removed)

    def reconfigure(self, config: object) -> list[str]:
        """A reload changed ``[http]``: users, tokens and limits from the next request
        (the sessions of a user removed or whose password changed end); the keys it
        cannot take live are returned (docs/GATEWAY.md, "Reloading")."""
        assert isinstance(config, HttpConfig)
        old, kept = self.config, []
        live = ("users", "tokens", "limits", "body_timeout_s", "max_streams_per_address")
        for key in _fields_of(config):
            if key in live or getattr(old, key) == getattr(config, key):
                continue
            kept.append(f"http.{key}")
        # The limits from the next connection, request or stream (those open stay).
        self.limit.retune(config.limits)
        self.per_address.streams.per_address = config.max_streams_per_address
        if self.server is not None:
            self.server.idle_timeout_s = config.limits.idle_timeout_s
            self.server.body_timeout_s = config.body_timeout_s
        users, tokens = config.users, config.tokens
        if self.writes is not None:  # nobody named any more: nobody can log in or write
            self.writes.set_credentials(users, tokens)
        elif config.authentication:  # the write routes are made only at a start
            kept.append("http.users and http.tokens (no write routes until a restart)")
            users, tokens = old.users, old.tokens
        self.config = dataclasses.replace(
            old,
            users=users,
            tokens=tokens,
            limits=config.limits,
            body_timeout_s=config.body_timeout_s,
            max_streams_per_address=config.max_streams_per_address,
        )
        return kept

    @property
    def port(self) -> int:
        """The port it listens on (the real one when asked for port 0), 0 when not started."""
        return 0 if self.server is None else self.server.port

    def announce(self) -> str | None:
        host = self.config.listen.host
        shown = f"[{host}]" if ":" in host else host
        scheme = "https" if self.config.tls_cert is not None else "http"
        return f"http on {scheme}://{shown}:{self.port}/ (workbench, /metrics, /healthz)"

    def publish(self, served: ServedDrive) -> None:
        if self.workbench is not None:
            self.workbench.publish(served)

    def flush(self) -> None:
        """The gateway's batch is whole: the event streams send what it left them."""
        if self.workbench is not None:
            self.workbench.hub.flush()

    def metrics(self) -> Iterator[Metric]:
        from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

        yield from listener_families("sj300_http", self.limit)
        yield from self._refusals()
        if self.workbench is None:
            return
        hub = self.workbench.hub
        yield GaugeMetricFamily(
            "sj300_http_event_streams", "Workbench event streams open.", len(hub)
        )
        yield CounterMetricFamily(
            "sj300_http_events_sent", "Events written to workbench event streams.", hub.sent
        )
        yield CounterMetricFamily(
            "sj300_http_events_replaced",
            "Events replaced by a newer state of the same subject before a slow stream took them.",
            hub.replaced,
        )

    def _refusals(self) -> Iterator[Metric]:
        """What the door refused or cut per client (docs/GATEWAY.md, "Hardening")."""
        from prometheus_client.core import CounterMetricFamily

        timed_out = 0 if self.server is None else self.server.timed_out
        yield CounterMetricFamily(
            "sj300_http_requests_timed_out",
            "HTTP requests whose head and body did not come within body_timeout_s "
            "(answered 408 or cut; their connections closed).",
            timed_out,
        )
        refused = CounterMetricFamily(
            "sj300_http_requests_refused",
            "HTTP requests refused by a per-address limit or a busy password check.",
            labels=["reason"],
        )
        refused.add_metric(["streams"], self.per_address.streams.refused)
        refused.add_metric(["check_rate"], self.per_address.checks.refused)
        writes = self.writes
        if writes is not None:
            refused.add_metric(["login_rate"], writes.budget.refused)
            refused.add_metric(["login_failures"], writes.guard.refused)
            refused.add_metric(["login_busy"], writes.checks.busy)
        yield refused
        if writes is not None:
            yield CounterMetricFamily(
                "sj300_http_password_checks",
                "Login passwords checked (scrypt, off the event loop).",
                writes.checks.checked,
            )

    async def close(self) -> None:
        if self._ticker is not None:
            self._ticker.cancel()
            # wait(), not await: the ticker's own cancellation stays its own, and a
            # cancellation of close() itself is not swallowed with it.
            await asyncio.wait([self._ticker])
            self._ticker = None
        if self.workbench is not None:
            self.workbench.close()  # the streams end, so the server's shutdown need not wait
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()
            self.server = None
        if self.writes is not None:
            self.writes.close()
