"""What one session's subscriptions may cost the loop: a hook beside :mod:`._hooks`.

asyncua's SubscriptionService takes any publishing interval (10 ms, even
0), revises every monitored item's sampling interval to it, and takes any
number of monitored items and subscriptions per session. The probe after
issue 41 (tests/adversarial/test_probe_findings.py): 16 anonymous
sessions from one address, each a 10 ms subscription of 500 items, took
the loop's p99 lag to 72-268 ms. The costly parts were the CreateMonitoredItems
requests (asyncua creates all 500 items, each read and notified, in one
turn of the loop) and the publishing at 10 ms. So, on the one server:

- **Publishing interval at least** :data:`MIN_PUBLISHING_INTERVAL_MS`.
  A smaller one (or 0, NaN) is revised up, as OPC UA Part 4 (5.13.2)
  lets a server do; asyncua revises each item's sampling interval to its
  subscription's, so sampling follows (a ModifyMonitoredItems asking for
  less is revised up too). The values change at most once per poll
  (0.1 s and more): a faster publishing sends nothing new.
- **Subscriptions per session** (:data:`SUBSCRIPTIONS_PER_SESSION`):
  past it, CreateSubscription ``BadTooManySubscriptions``.
- **Monitored items per session and per client address** (its sessions
  together): ``[opcua] max_monitored_items_per_session`` (1,000) and
  ``max_monitored_items_per_address`` (2,000). The items past either are
  answered ``BadTooManyMonitoredItems``, the others created.
- **A request's items a slice at a time** (:data:`ITEMS_PER_TURN`): the
  loop serves the poll and the leases between slices.
- **Event filters of a bounded size** (:data:`MAX_WHERE_ELEMENTS`,
  :data:`MAX_SELECT_CLAUSES`): asyncua evaluates every event item's where
  clause for each event, on the loop, recursively. An anonymous session's
  60 items of 900 nested elements held the loop 0.37 s for four trips'
  events (issue 45's probe; 2,000 elements raise RecursionError in asyncua
  at each event). A larger filter is answered ``BadEventFilterInvalid``
  (created or modified), the item not made; an alarm list's filter is a
  handful of elements. And **event items per session**
  (:data:`EVENT_ITEMS_PER_SESSION`): 1,000 of 16 elements each held the
  loop 0.24 s for four trips' events; an alarm list uses one or two.

The rest are constants, not ``[opcua]`` keys: no client needs them
moved. This is private
asyncua access (``iserver.subscription_service``, its ``subscriptions``,
a session's ``name`` and ``session_id``), checked against the installed
asyncua by ``tests/opcua/test_opcua_subscriptions.py``.
"""

from __future__ import annotations

import asyncio
import math
import weakref
from collections import Counter
from collections.abc import Hashable
from typing import Any, Final

from asyncua import Server, ua
from asyncua.common.utils import ServiceError

__all__ = [
    "EVENT_ITEMS_PER_SESSION",
    "ITEMS_PER_TURN",
    "MAX_SELECT_CLAUSES",
    "MAX_WHERE_ELEMENTS",
    "MIN_PUBLISHING_INTERVAL_MS",
    "SUBSCRIPTIONS_PER_SESSION",
    "bound_subscriptions",
]

#: The least publishing (so sampling) interval, ms: the fastest poll's interval.
MIN_PUBLISHING_INTERVAL_MS: Final = 100.0
#: Subscriptions one session may hold (a client uses one or two).
SUBSCRIPTIONS_PER_SESSION: Final = 10
#: An event filter's where-clause elements and select clauses, at most.
MAX_WHERE_ELEMENTS: Final = 16
MAX_SELECT_CLAUSES: Final = 64
#: Event monitored items one session may hold (its subscriptions together).
EVENT_ITEMS_PER_SESSION: Final = 10
# The monitored items' caps are [opcua] keys (_config.py). 16 anonymous sessions of 500
# items on one variable from one address (8,000: a change of it is 8,000 notifications in
# one turn of the loop) held the loop p99 48-59 ms, max 52-367 ms on the loaded 2-core
# machine, over issue 41's bounds; the address cap of 2,000 brought it to 21 ms alone.
#: Monitored items created per turn of the loop (500 in one turn: 30-70 ms).
ITEMS_PER_TURN: Final = 50


def _host(session: Any) -> Hashable:
    """The client address of one of asyncua's sessions (its name is the peer)."""
    name: Hashable = session.name
    return name[0] if isinstance(name, tuple) and name else name


def _interval(requested: float) -> float:
    """*requested* revised up to the least publishing interval (NaN too)."""
    if math.isnan(requested) or requested < MIN_PUBLISHING_INTERVAL_MS:
        return MIN_PUBLISHING_INTERVAL_MS
    return requested


class _Bounds:
    """The bounds on one server's subscription service (module docstring)."""

    def __init__(self, service: Any, per_session: int, per_address: int) -> None:
        self.service = service
        self.per_session, self.per_address = per_session, per_address
        #: Each external session by its id, while it lives.
        self.sessions: weakref.WeakValueDictionary[Any, Any] = weakref.WeakValueDictionary()
        #: Items granted, not yet created (a request's slices yield the loop).
        self.pending_session: Counter[Any] = Counter()
        self.pending_host: Counter[Hashable] = Counter()

    def items(self, session_id: Any, host: Hashable) -> tuple[int, int]:
        """Monitored items of the session *session_id*, of the address *host*."""
        by_session, by_host = 0, 0
        for subscription in self.service.subscriptions.values():
            owner = self.sessions.get(subscription.session_id)
            if owner is None or _host(owner) != host:
                continue
            count = len(subscription.monitored_item_srv._monitored_items)
            by_host += count
            if subscription.session_id == session_id:
                by_session += count
        return (
            by_session + self.pending_session[session_id],
            by_host + self.pending_host[host],
        )


def _oversized(filter_: object) -> bool:
    """An event filter past :data:`MAX_WHERE_ELEMENTS` or :data:`MAX_SELECT_CLAUSES`."""
    if not isinstance(filter_, ua.EventFilter):
        return False
    where = filter_.WhereClause
    elements = 0 if where is None else len(where.Elements or ())
    return elements > MAX_WHERE_ELEMENTS or len(filter_.SelectClauses or ()) > MAX_SELECT_CLAUSES


def _is_event(item: ua.MonitoredItemCreateRequest) -> bool:
    return bool(item.ItemToMonitor.AttributeId == ua.AttributeIds.EventNotifier)


def _event_items(service: Any, session_id: Any) -> int:
    """The event monitored items *session_id*'s subscriptions hold (asyncua's tables)."""
    return sum(
        len(mids)
        for subscription in service.subscriptions.values()
        if subscription.session_id == session_id
        for mids in subscription.monitored_item_srv._monitored_events.values()
    )


def bound_subscriptions(server: Server, *, items_per_session: int, items_per_address: int) -> None:
    """Bound the subscriptions of *server*'s sessions (module docstring). Runs after
    :func:`._hooks.guard_sessions`, whose session creation it wraps."""
    iserver = server.iserver
    service = iserver.subscription_service
    bounds = _Bounds(service, items_per_session, items_per_address)
    create_session = iserver.create_session
    create_subscription = service.create_subscription
    create_items = service.create_monitored_items
    modify_items = service.modify_monitored_items

    def session_created(name: Any, user: Any = None, external: bool = False) -> Any:
        if user is None:
            session = create_session(name, external=external)
        else:
            session = create_session(name, user, external)
        if external:
            bounds.sessions[session.session_id] = session
        return session

    async def subscription_created(
        params: ua.CreateSubscriptionParameters, callback: Any, session_id: Any, **kwargs: Any
    ) -> Any:
        if session_id in bounds.sessions:
            held = sum(1 for s in service.subscriptions.values() if s.session_id == session_id)
            if held >= SUBSCRIPTIONS_PER_SESSION:
                raise ServiceError(ua.StatusCodes.BadTooManySubscriptions)
        params.RequestedPublishingInterval = _interval(params.RequestedPublishingInterval)
        return await create_subscription(params, callback, session_id, **kwargs)

    async def items_created(
        params: ua.CreateMonitoredItemsParameters,
    ) -> list[ua.MonitoredItemCreateResult]:
        oversized = {
            i: ua.StatusCodes.BadEventFilterInvalid
            for i, item in enumerate(params.ItemsToCreate)
            if _oversized(item.RequestedParameters.Filter)
        }
        if oversized:  # the others created, bounded as any
            return await _all_but(params, oversized)
        subscription = service.subscriptions.get(params.SubscriptionId)
        if subscription is not None and subscription.session_id in bounds.sessions:
            room = EVENT_ITEMS_PER_SESSION - _event_items(service, subscription.session_id)
            events = [i for i, item in enumerate(params.ItemsToCreate) if _is_event(item)]
            if len(events) > room:
                too_many = ua.StatusCodes.BadTooManyMonitoredItems
                return await _all_but(params, dict.fromkeys(events[max(room, 0) :], too_many))
        session = None if subscription is None else bounds.sessions.get(subscription.session_id)
        if session is None:  # no such subscription (asyncua answers), or the server's own
            result: list[ua.MonitoredItemCreateResult] = await create_items(params)
            return result
        session_id, host = session.session_id, _host(session)
        by_session, by_host = bounds.items(session_id, host)
        wanted = params.ItemsToCreate
        granted = max(
            0, min(len(wanted), bounds.per_session - by_session, bounds.per_address - by_host)
        )
        bounds.pending_session[session_id] += granted
        bounds.pending_host[host] += granted
        results: list[ua.MonitoredItemCreateResult] = []
        try:
            for start in range(0, granted, ITEMS_PER_TURN):
                if start:
                    await asyncio.sleep(0)  # the poll and the leases between slices
                part = ua.CreateMonitoredItemsParameters(
                    SubscriptionId=params.SubscriptionId,
                    TimestampsToReturn=params.TimestampsToReturn,
                    ItemsToCreate=wanted[start : min(granted, start + ITEMS_PER_TURN)],
                )
                results.extend(await create_items(part))
        finally:
            bounds.pending_session[session_id] -= granted
            bounds.pending_host[host] -= granted
            if not bounds.pending_session[session_id]:
                del bounds.pending_session[session_id]
            if not bounds.pending_host[host]:
                del bounds.pending_host[host]
        for _ in wanted[granted:]:
            results.append(
                ua.MonitoredItemCreateResult(
                    StatusCode=ua.StatusCode(ua.StatusCodes.BadTooManyMonitoredItems)
                )
            )
        return results

    async def _all_but(
        params: ua.CreateMonitoredItemsParameters, refused: dict[int, int]
    ) -> list[ua.MonitoredItemCreateResult]:
        """The items created but the *refused* ones (index: the status they are answered)."""
        items = params.ItemsToCreate
        kept = [item for i, item in enumerate(items) if i not in refused]
        made = iter(
            await items_created(
                ua.CreateMonitoredItemsParameters(
                    SubscriptionId=params.SubscriptionId,
                    TimestampsToReturn=params.TimestampsToReturn,
                    ItemsToCreate=kept,
                )
            )
            if kept
            else []
        )
        return [
            ua.MonitoredItemCreateResult(StatusCode=ua.StatusCode(refused[i]))
            if i in refused
            else next(made)
            for i in range(len(items))
        ]

    def items_modified(
        params: ua.ModifyMonitoredItemsParameters,
    ) -> list[ua.MonitoredItemModifyResult]:
        if any(_oversized(item.RequestedParameters.Filter) for item in params.ItemsToModify):
            return [
                ua.MonitoredItemModifyResult(
                    StatusCode=ua.StatusCode(ua.StatusCodes.BadEventFilterInvalid)
                )
                for _ in params.ItemsToModify
            ]  # the whole request refused: nothing changed, nothing half-applied
        results: list[ua.MonitoredItemModifyResult] = modify_items(params)
        for result in results:  # asyncua grants the requested interval as it is
            result.RevisedSamplingInterval = _interval(result.RevisedSamplingInterval)
        return results

    iserver.create_session = session_created
    service.create_subscription = subscription_created
    service.create_monitored_items = items_created
    service.modify_monitored_items = items_modified
