"""The HTTP northbound: the workbench page, its JSON API and event stream, /metrics, /healthz.

Configured by ``[http] listen = "HOST:PORT"`` or ``--http HOST:PORT``
(``[metrics]`` and ``--metrics``, its older names, still work), with the
listener's limits ``max_connections`` (default 64) and ``idle_timeout_s``
(default 5: the time a connection may stay open without a request in
progress), and ``trend_s``, the window of each drive's trend (default 900).

On one listener: the workbench (``/``, docs/guide/workbench.md), its API
under ``/api/v1/`` (docs/WORKBENCH_API.md), ``/metrics`` with every family
of the gateway, each northbound's included
(:meth:`~sj300_async.gateway.GatewayView.metrics`), built at the scrape,
and ``/healthz``, 200 ``ok`` or 503 with the gateway's problems one per
line. aiohttp and prometheus-client are imported only when the northbound
starts.
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

__all__ = ["DEFAULT_LIMITS", "DEFAULT_TREND_S", "NORTHBOUND", "HttpConfig"]

#: The listener's limits when ``[http]`` sets none. A workbench tab holds one event
#: stream and up to six requests at once; with a few tabs, a scraper and a health
#: probe, 64 leaves room and keeps the gateway far below a small descriptor limit.
#: A connection may stay 5 s without a request in progress.
DEFAULT_LIMITS: Final = ListenerLimits(max_connections=64, idle_timeout_s=5.0)
#: Seconds of each drive's trend the workbench keeps (15 min).
DEFAULT_TREND_S: Final = 900.0
#: The longest trend window accepted (a day): its memory is allocated at start.
MAX_TREND_S: Final = 86_400.0


@dataclass(frozen=True, slots=True)
class HttpConfig:
    """``[http]``: where the workbench, /metrics and /healthz are served, and how."""

    listen: Endpoint
    limits: ListenerLimits = DEFAULT_LIMITS
    trend_s: float = DEFAULT_TREND_S


class _Spec:
    section = "http"
    aliases = ("metrics",)
    keys = ("listen", *LIMIT_KEYS, "trend_s")
    flag = Flag(
        "--http",
        "listen",
        "HOST:PORT",
        "serve the workbench, its API, /metrics and /healthz there",
        aliases=("--metrics",),
    )
    requires = ("aiohttp", "prometheus_client")

    def parse(self, table: ConfigTable, context: SectionContext) -> HttpConfig:
        trend_s = table.number("trend_s", minimum=0, inclusive=False)
        if trend_s is not None and trend_s > MAX_TREND_S:
            raise table.error("trend_s", f"must be <= {MAX_TREND_S:g} (a day), got {trend_s:g}")
        return HttpConfig(
            table.required_endpoint("listen"),
            DEFAULT_LIMITS.parse(table),
            DEFAULT_TREND_S if trend_s is None else trend_s,
        )

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, HttpConfig)
        return [("listen", config.listen)]

    def create(self, config: object) -> Northbound:
        from ._northbound import HttpNorthbound

        assert isinstance(config, HttpConfig)
        return HttpNorthbound(config)


#: The registry's entry (``sj300_async.gateway.http:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
