"""The HTTP northbound: ``GET /metrics`` (Prometheus) and ``GET /healthz``.

Configured by ``[metrics] listen = "HOST:PORT"`` or ``--metrics HOST:PORT``,
and the listener's limits ``max_connections`` (default 16) and
``idle_timeout_s`` (default 5: the time a client has to send its request,
and again to take the answer).
``/metrics`` serves every family of the gateway, each northbound's
included (:meth:`~sj300_async.gateway.GatewayView.metrics`), built at the
scrape; ``/healthz`` is 200 ``ok``, or 503 with the gateway's problems one
per line. The server itself is :mod:`._server`; prometheus-client is
imported only when the northbound starts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from .. import (
    LIMIT_KEYS,
    ConfigTable,
    Endpoint,
    Flag,
    ListenerLimits,
    Northbound,
    SectionContext,
)

__all__ = ["DEFAULT_LIMITS", "NORTHBOUND", "MetricsConfig"]

#: The listener's limits when ``[metrics]`` sets none: a scraper and a health probe or
#: two, each one request per connection; 16 leaves room for several of each and keeps
#: the gateway far below a small descriptor limit. A request must come, and its answer
#: be taken, within 5 s.
DEFAULT_LIMITS: Final = ListenerLimits(max_connections=16, idle_timeout_s=5.0)


@dataclass(frozen=True, slots=True)
class MetricsConfig:
    """``[metrics]``: where /metrics and /healthz are served, and the listener's limits."""

    listen: Endpoint
    limits: ListenerLimits = DEFAULT_LIMITS


class _Spec:
    section = "metrics"
    keys = ("listen", *LIMIT_KEYS)
    flag = Flag("--metrics", "listen", "HOST:PORT", "serve /metrics and /healthz there")
    requires = ("prometheus_client",)

    def parse(self, table: ConfigTable, context: SectionContext) -> MetricsConfig:
        return MetricsConfig(table.required_endpoint("listen"), DEFAULT_LIMITS.parse(table))

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, MetricsConfig)
        return [("listen", config.listen)]

    def create(self, config: object) -> Northbound:
        from ._northbound import HttpNorthbound

        assert isinstance(config, MetricsConfig)
        return HttpNorthbound(config)


#: The registry's entry (``sj300_async.gateway.http:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
