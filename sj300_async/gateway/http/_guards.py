"""What one client address may hold or spend at the HTTP door: streams, logins, backup checks.

The listener caps each address's connections (``max_connections_per_address``,
gateway/_listeners.py) and the server each request's time
(``body_timeout_s``, :mod:`._server`); this module holds what the routes
themselves limit per client address (``request.remote``), each refusal a
429 with ``Retry-After`` and counted
(``sj300_http_requests_refused_total{reason}``).

Decisions:

- **Event streams**: at most ``max_streams_per_address`` (default
  :data:`DEFAULT_STREAMS_PER_ADDRESS`) open at once per address, the
  workbench's event stream and the parameter-read stream together
  (:class:`AddressSlots`). A stream is a request that never ends, so the
  connection's time limits do not bound it; a page holds one, and a few
  tabs from one desk fit (a browser opens at most 6 connections to one
  host anyway).
- **Logins**: a token bucket per address (:data:`LOGIN_BURST`, one more
  every 1 / :data:`LOGIN_PER_S` s), spent once the request's head is in,
  before its body is read: a refused login costs a dictionary lookup, not
  a read and a 65 ms scrypt check, so 60 logins sent at once from one
  address give at most :data:`LOGIN_BURST` checks (issue 41: there were
  60, on the loop, 2.6-3.75 s of stall). A login that succeeds gives its
  token back: an operator who logs in often is never refused. The
  failed-login lock (``LoginGuard``, 10 failures in 5 minutes) stays, for
  the slow guesser the bucket lets through.
- **Backup checks** (``POST /api/v1/parameters/check``, open to anyone,
  up to 1 MiB parsed on the loop each, tens of ms for the worst): a
  bucket per address too (:data:`CHECK_BURST`, one more every
  1 / :data:`CHECK_PER_S` s); the page sends one per file the operator
  picks.
- ``Retry-After`` is the bucket's own answer in whole seconds, rounded up;
  a stream's is :data:`STREAM_RETRY_S` (a slot frees when a stream ends,
  which no clock predicts).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final

from aiohttp import web

from .. import KeyedBudget
from . import DEFAULT_STREAMS_PER_ADDRESS
from ._replies import json_error

__all__ = [
    "CHECK_BURST",
    "CHECK_PER_S",
    "LOGIN_BURST",
    "LOGIN_PER_S",
    "STREAM_RETRY_S",
    "AddressSlots",
    "PerAddress",
    "client_address",
    "spend",
    "too_many",
]

#: The ``Retry-After`` of a refused stream.
STREAM_RETRY_S: Final = 5
#: Password checks one address may have at once, and how fast it may have more.
LOGIN_BURST: Final = 5
LOGIN_PER_S: Final = 1 / 12
#: Backup checks one address may have at once, and how fast it may have more.
CHECK_BURST: Final = 8
CHECK_PER_S: Final = 1 / 2


def client_address(request: web.BaseRequest) -> str:
    """The client's address, the key of every per-address limit (``?``: none known)."""
    return request.remote or "?"


def too_many(message: str, retry_after_s: float) -> web.HTTPException:
    """A 429 saying *message*, with ``Retry-After`` (whole seconds, at least 1)."""
    error = json_error(429, message)
    error.headers["Retry-After"] = str(max(1, math.ceil(retry_after_s)))
    return error


def spend(budget: KeyedBudget, address: str, what: str) -> None:
    """Spend one of *address*'s tokens of *budget*, or refuse (429) saying *what* it was.

    Raises:
        HTTPException: 429, the budget spent (counted by the budget).
    """
    if not budget.spend(address):
        wait_s = budget.retry_after_s(address)
        raise too_many(f"too many {what} from this address: try again in {wait_s:.0f} s", wait_s)


class AddressSlots:
    """Streams open per client address, at most *per_address* each (module docstring)."""

    def __init__(self, per_address: int = DEFAULT_STREAMS_PER_ADDRESS) -> None:
        self.per_address = per_address
        self._held: dict[str, int] = {}
        #: Streams refused for their address's cap, since the start.
        self.refused = 0

    def held(self, address: str) -> int:
        return self._held.get(address, 0)

    def acquire(self, address: str) -> None:
        """Count a stream of *address* in.

        Raises:
            HTTPException: 429, *address* holds its cap (counted).
        """
        held = self._held.get(address, 0)
        if held >= self.per_address:
            self.refused += 1
            raise too_many(
                f"{held} event streams open from this address (max_streams_per_address): "
                "close one first",
                STREAM_RETRY_S,
            )
        self._held[address] = held + 1

    def release(self, address: str) -> None:
        held = self._held.get(address, 0) - 1
        if held > 0:
            self._held[address] = held
        else:
            self._held.pop(address, None)


def _check_budget() -> KeyedBudget:
    return KeyedBudget(CHECK_BURST, CHECK_PER_S)


@dataclass(slots=True)
class PerAddress:
    """The per-address limits the routes of one HTTP northbound share."""

    #: Open event streams (the events route and the parameter-read route).
    streams: AddressSlots = field(default_factory=AddressSlots)
    #: Backup checks.
    checks: KeyedBudget = field(default_factory=_check_budget)
