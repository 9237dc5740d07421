"""The HTTP northbound: ``GET /metrics`` (Prometheus) and ``GET /healthz``.

Configured by ``[metrics] listen = "HOST:PORT"`` or ``--metrics HOST:PORT``.
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

from .. import ConfigTable, Endpoint, Flag, Northbound, SectionContext

__all__ = ["NORTHBOUND", "MetricsConfig"]


@dataclass(frozen=True, slots=True)
class MetricsConfig:
    """``[metrics]``: where /metrics and /healthz are served."""

    listen: Endpoint


class _Spec:
    section = "metrics"
    keys = ("listen",)
    flag = Flag("--metrics", "listen", "HOST:PORT", "serve /metrics and /healthz there")
    requires = ("prometheus_client",)

    def parse(self, table: ConfigTable, context: SectionContext) -> MetricsConfig:
        return MetricsConfig(table.required_endpoint("listen"))

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, MetricsConfig)
        return [("listen", config.listen)]

    def create(self, config: object) -> Northbound:
        from ._northbound import HttpNorthbound

        assert isinstance(config, MetricsConfig)
        return HttpNorthbound(config)


#: The registry's entry (``sj300_async.gateway.http:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
