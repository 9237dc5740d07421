"""Requests and exception replies per Modbus client, counted for the exporter.

A client is labelled by its IP address only (the port changes on every
connection). Past :data:`MAX_CLIENTS` distinct addresses the rest are
counted as ``client="other"``: a scan of the port must not turn into an
unbounded number of series. The counters are plain dicts: a dict increment
on the server's hot path, no prometheus_client object and no lock; the
families are built at scrape time (:func:`client_families`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = [
    "MAX_CLIENTS",
    "OTHER_CLIENT",
    "ClientCounters",
    "bad_frames_family",
    "client_families",
]

_log = logging.getLogger("sj300_async.gateway.metrics")

#: Distinct client addresses labelled one by one; the rest share :data:`OTHER_CLIENT`.
MAX_CLIENTS: Final = 64
OTHER_CLIENT: Final = "other"


class ClientCounters:
    """Requests and exception replies per Modbus client (see the module docstring).

    Args:
        max_clients: distinct addresses counted under their own label; the
            next ones are counted as :data:`OTHER_CLIENT`.
    """

    __slots__ = ("_known", "_max_clients", "exceptions", "requests")

    def __init__(self, max_clients: int = MAX_CLIENTS) -> None:
        self._max_clients = max_clients
        #: The addresses labelled one by one so far.
        self._known: set[str] = set()
        #: Requests by client address.
        self.requests: dict[str, int] = {}
        #: Exception replies by (client address, Modbus exception code).
        self.exceptions: dict[tuple[str, int], int] = {}

    def request(self, client: str) -> None:
        """Count one request of *client* (its IP address, without the port)."""
        client = self._label(client)
        self.requests[client] = self.requests.get(client, 0) + 1

    def exception(self, client: str, code: int) -> None:
        """Count one exception reply with *code* sent to *client*."""
        key = (self._label(client), code)
        self.exceptions[key] = self.exceptions.get(key, 0) + 1

    def _label(self, client: str) -> str:
        if client in self._known:
            return client
        if len(self._known) < self._max_clients:
            self._known.add(client)
            return client
        if OTHER_CLIENT not in self._known:
            # Once, when the cap is first reached: later newcomers are not news.
            self._known.add(OTHER_CLIENT)
            _log.warning(
                "more than %d Modbus client addresses: %s and later ones are counted as %r",
                self._max_clients,
                client,
                OTHER_CLIENT,
            )
        return OTHER_CLIENT


def client_families(clients: ClientCounters) -> Iterator[Metric]:
    """``sj300_modbus_requests_total`` and ``sj300_modbus_exceptions_total``, built now."""
    from prometheus_client.core import CounterMetricFamily

    requests = CounterMetricFamily(
        "sj300_modbus_requests",
        "Modbus TCP requests received, by client IP address.",
        labels=["client"],
    )
    for client, count in sorted(clients.requests.items()):
        requests.add_metric([client], count)
    yield requests
    exceptions = CounterMetricFamily(
        "sj300_modbus_exceptions",
        "Modbus exception replies sent, by client IP address and exception code (decimal).",
        labels=["client", "code"],
    )
    for (client, code), count in sorted(clients.exceptions.items()):
        exceptions.add_metric([client, str(code)], count)
    yield exceptions


def bad_frames_family(count: int) -> Metric:
    """``sj300_modbus_bad_frames_total``: frames that could not be framed (each closed its
    connection)."""
    from prometheus_client.core import CounterMetricFamily

    return CounterMetricFamily(
        "sj300_modbus_bad_frames",
        "Modbus TCP frames with a protocol id other than 0 or an impossible length "
        "(each closed its connection).",
        count,
    )
