"""The HTTP northbound: the workbench page, its JSON API and event stream, /metrics, /healthz.

Configured by ``[http] listen = "HOST:PORT"`` or ``--http HOST:PORT``
(``[metrics]`` and ``--metrics``, its older names, still work), with the
listener's limits ``max_connections`` (default 64),
``max_connections_per_address`` (default half of it) and
``idle_timeout_s`` (default 5: the time a connection may stay open
without a request in progress), ``body_timeout_s`` (default 5: the time a
request's head and body may take), ``max_streams_per_address`` (default
4: event streams open at once from one address), and ``trend_s``, the
window of each drive's trend (default 900). What each limit is for:
docs/GATEWAY.md, "Hardening".

On one listener: the workbench (``/``, docs/guide/workbench.md), its API
under ``/api/v1/`` (docs/WORKBENCH_API.md), ``/metrics`` with every family
of the gateway, each northbound's included
(:meth:`~sj300_async.gateway.GatewayView.metrics`), built at the scrape,
and ``/healthz``, 200 ``ok`` or 503 with the gateway's problems one per
line. aiohttp and prometheus-client are imported only when the northbound
starts.
"""

from __future__ import annotations

import re
import ssl
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from .. import (
    LIMIT_KEYS,
    ConfigTable,
    Endpoint,
    Flag,
    ListenerLimits,
    Northbound,
    SectionContext,
    Trend,
    User,
    hash_password,
    named_entries,
    parse_users,
    trend_capacity,
)
from .. import TREND_BLOCK as BLOCK
from .. import TREND_SAMPLE_BYTES as SAMPLE_BYTES
from ._auth import ApiToken, hash_token, new_token

#: Seconds a request's head and body may take, from its first byte (``_server``): a
#: 1 MiB backup needs 1.7 Mbit/s, a login or a write a few hundred bytes.
DEFAULT_BODY_TIMEOUT_S: Final = 5.0
#: Event streams one client address may hold at once (``_guards``): a control room's PC
#: with a workbench tab on each of its screens, each tab one stream and, while it reads
#: parameters, a second. Far below the address's connections (half of 64).
DEFAULT_STREAMS_PER_ADDRESS: Final = 16

__all__ = [
    "BLOCK",
    "DEFAULT_LIMITS",
    "DEFAULT_TREND_S",
    "NORTHBOUND",
    "SAMPLE_BYTES",
    "ApiToken",
    "HttpConfig",
    "Trend",
    "User",
    "hash_password",
    "hash_token",
    "new_token",
    "trend_capacity",
]

#: The listener's limits when ``[http]`` sets none. A workbench tab holds one event
#: stream and up to six requests at once; with a few tabs, a scraper and a health
#: probe, 64 leaves room and keeps the gateway far below a small descriptor limit.
#: A connection may stay 5 s without a request in progress.
DEFAULT_LIMITS: Final = ListenerLimits(max_connections=64, idle_timeout_s=5.0)
#: Seconds of each drive's trend the workbench keeps (15 min).
DEFAULT_TREND_S: Final = 900.0
#: The longest trend window accepted (a day): its memory is allocated at start.
MAX_TREND_S: Final = 86_400.0


_TOKEN_HASH: Final = re.compile(r"sha256\$[0-9a-f]{64}\Z")


@dataclass(frozen=True, slots=True)
class HttpConfig:
    """``[http]``: where the workbench, /metrics and /healthz are served, and how."""

    listen: Endpoint
    limits: ListenerLimits = DEFAULT_LIMITS
    trend_s: float = DEFAULT_TREND_S
    #: Who may write (module _auth): people with passwords, scripts with tokens.
    users: tuple[User, ...] = ()
    tokens: tuple[ApiToken, ...] = ()
    #: HTTPS: the certificate chain and its key (PEM files), both or neither.
    tls_cert: Path | None = None
    tls_key: Path | None = None
    #: Seconds a request's head and body may take, from its first byte (then 408).
    body_timeout_s: float = DEFAULT_BODY_TIMEOUT_S
    #: Event streams one client address may hold at once (then 429).
    max_streams_per_address: int = DEFAULT_STREAMS_PER_ADDRESS

    @property
    def authentication(self) -> bool:
        """Someone is named who may write (without, the workbench serves no write)."""
        return bool(self.users or self.tokens)

    def ssl_context(self) -> ssl.SSLContext | None:
        """The server's TLS context, None without TLS.

        Raises:
            ssl.SSLError, OSError: the files cannot be loaded.
        """
        if self.tls_cert is None or self.tls_key is None:
            return None
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        context.load_cert_chain(self.tls_cert, self.tls_key)
        return context


def _token_problem(stored: str) -> str | None:
    if _TOKEN_HASH.match(stored):
        return None
    return "expected sha256$ and 64 hex digits (sj300 gateway --new-token)"


def _tokens(table: ConfigTable) -> tuple[ApiToken, ...]:
    found = named_entries(table, "tokens", "token", "token_hash", _token_problem)
    return tuple(ApiToken(name, stored) for name, stored in found.items())


def _tls(table: ConfigTable, base_dir: Path) -> tuple[Path | None, Path | None]:
    cert, key = table.string("tls_cert"), table.string("tls_key")
    if (cert is None) != (key is None):
        missing = "tls_key" if key is None else "tls_cert"
        raise table.error(missing, "HTTPS needs both tls_cert and tls_key")
    if cert is None or key is None:
        return None, None
    paths = []
    for name, text in (("tls_cert", cert), ("tls_key", key)):
        path = base_dir / text
        if not text.strip() or not path.is_file():
            raise table.error(name, f"no such file: {str(path)!r}")
        paths.append(path)
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:  # a bad pair starts nothing: it is refused here, with the file's line
        context.load_cert_chain(paths[0], paths[1])
    except (ssl.SSLError, OSError) as exc:
        raise table.error("tls_cert", f"cannot load the certificate and key: {exc}") from None
    return paths[0], paths[1]


class _Spec:
    section = "http"
    aliases = ("metrics",)
    keys = (
        "listen",
        *LIMIT_KEYS,
        "body_timeout_s",
        "max_streams_per_address",
        "trend_s",
        "users",
        "tokens",
        "tls_cert",
        "tls_key",
    )
    flag = Flag(
        "--http",
        "listen",
        "HOST:PORT",
        "serve the workbench, its API, /metrics and /healthz there",
        aliases=("--metrics",),
    )
    requires = ("aiohttp", "orjson", "prometheus_client")

    def parse(self, table: ConfigTable, context: SectionContext) -> HttpConfig:
        trend_s = table.number("trend_s", minimum=0, inclusive=False)
        if trend_s is not None and trend_s > MAX_TREND_S:
            raise table.error("trend_s", f"must be <= {MAX_TREND_S:g} (a day), got {trend_s:g}")
        tls_cert, tls_key = _tls(table, context.base_dir)
        body_timeout_s = table.number("body_timeout_s", minimum=0, inclusive=False)
        streams = table.integer("max_streams_per_address")
        if streams is not None and streams < 1:
            raise table.error("max_streams_per_address", f"must be >= 1, got {streams}")
        return HttpConfig(
            table.required_endpoint("listen"),
            DEFAULT_LIMITS.parse(table),
            DEFAULT_TREND_S if trend_s is None else trend_s,
            users=parse_users(table),
            tokens=_tokens(table),
            tls_cert=tls_cert,
            tls_key=tls_key,
            body_timeout_s=DEFAULT_BODY_TIMEOUT_S if body_timeout_s is None else body_timeout_s,
            max_streams_per_address=DEFAULT_STREAMS_PER_ADDRESS if streams is None else streams,
        )

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, HttpConfig)
        return [("listen", config.listen)]

    def check(self, config: object) -> Sequence[str]:
        """``--check-config``'s words for it (its files were loaded by the parser)."""
        assert isinstance(config, HttpConfig)
        scheme = "HTTPS" if config.tls_cert is not None else "HTTP"
        writes = (
            f"writes by {len(config.users)} user(s) and {len(config.tokens)} token(s)"
            if config.authentication
            else "read-only (no user or token)"
        )
        return (f"{scheme}, {writes}",)

    def create(self, config: object) -> Northbound:
        from ._northbound import HttpNorthbound

        assert isinstance(config, HttpConfig)
        return HttpNorthbound(config)


#: The registry's entry (``sj300_async.gateway.http:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
