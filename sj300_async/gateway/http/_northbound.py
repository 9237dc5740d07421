"""The HTTP northbound, running: /metrics and /healthz on one listener."""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import TYPE_CHECKING

from ...profiles import DriveSnapshot
from .. import ConnectionLimit, GatewayView, Listener, listener_families
from . import MetricsConfig
from ._server import make_registry, serve_http

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["HttpNorthbound"]

_log = logging.getLogger("sj300_async.gateway.http")


class HttpNorthbound:
    """Serves /metrics and /healthz (a :class:`~sj300_async.gateway.Northbound`)."""

    def __init__(self, config: MetricsConfig) -> None:
        self.config = config
        self.server: Listener | None = None
        limits = config.limits
        #: Open connections, and those refused at the cap or timed out.
        self.limit = ConnectionLimit("http", limits.max_connections, _log)

    async def start(self, gateway: GatewayView) -> None:
        self.server = await serve_http(
            self.config.listen,
            make_registry(gateway.metrics),
            gateway.problems,
            limit=self.limit,
            timeout_s=self.config.limits.idle_timeout_s,
        )

    @property
    def port(self) -> int:
        """The port it listens on (the real one when asked for port 0), 0 when not started."""
        return 0 if self.server is None else int(self.server.sockets[0].getsockname()[1])

    def announce(self) -> str | None:
        return f"metrics on http://{self.config.listen.host}:{self.port}/metrics"

    def publish(self, snapshot: DriveSnapshot) -> None:
        """Nothing to do: a scrape reads the latest snapshots."""

    def metrics(self) -> Iterable[Metric]:
        return listener_families("sj300_http", self.limit)

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()
            self.server = None
