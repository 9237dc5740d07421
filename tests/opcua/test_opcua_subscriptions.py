"""What a session's subscriptions may cost (``_subscriptions.py``), against a real gateway:
the publishing and sampling intervals revised up, the caps on subscriptions and monitored
items per session and per client address. Checks the private asyncua access too."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
from asyncua import Client, ua
from asyncua.ua.uaerrors import UaStatusCodeError

from sj300_async.gateway.opcua import _subscriptions
from sj300_async.gateway.opcua._operations import MAX_OPERATIONS
from sj300_async.gateway.opcua._subscriptions import MIN_PUBLISHING_INTERVAL_MS

from .conftest import NAMESPACE, connected, opcua_gateway, opcua_toml

VARIABLE = "hall/Drive1/Monitoring/ConverterOutputFrequency"


async def _subscribe(client: Client, interval_ms: float = 10.0) -> ua.CreateSubscriptionResult:
    params = ua.CreateSubscriptionParameters(
        RequestedPublishingInterval=interval_ms,
        RequestedLifetimeCount=300,
        RequestedMaxKeepAliveCount=10,
        PublishingEnabled=True,
    )
    result: ua.CreateSubscriptionResult = await client.uaclient.create_subscription(
        params, lambda *_: None
    )
    return result


async def _items(
    client: Client, subscription: int, count: int, sampling_ms: float = 0.0
) -> list[ua.MonitoredItemCreateResult]:
    namespace = await client.get_namespace_index(NAMESPACE)
    requests = [
        ua.MonitoredItemCreateRequest(
            ItemToMonitor=ua.ReadValueId(
                NodeId=ua.NodeId(VARIABLE, namespace), AttributeId=ua.AttributeIds.Value
            ),
            MonitoringMode=ua.MonitoringMode.Reporting,
            RequestedParameters=ua.MonitoringParameters(
                ClientHandle=n, SamplingInterval=sampling_ms, QueueSize=1, DiscardOldest=True
            ),
        )
        for n in range(count)
    ]
    results: list[ua.MonitoredItemCreateResult] = []
    for start in range(0, count, MAX_OPERATIONS):  # the server's most per request
        params = ua.CreateMonitoredItemsParameters(
            SubscriptionId=subscription,
            TimestampsToReturn=ua.TimestampsToReturn.Both,
            ItemsToCreate=requests[start : start + MAX_OPERATIONS],
        )
        results += await client.uaclient.create_monitored_items(params)
    return results


def _codes(results: list[Any]) -> list[str]:
    return [ua.StatusCode(r.StatusCode.value).name for r in results]


@asynccontextmanager
async def _sessions(url: str, count: int) -> AsyncIterator[list[Client]]:
    """*count* anonymous sessions from 127.0.0.1, one address."""
    async with AsyncExitStack() as stack:
        yield [await stack.enter_async_context(connected(url)) for _ in range(count)]


async def test_a_publishing_interval_below_the_least_is_revised_up(tmp_path: Path) -> None:
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server), connected(server.url) as c:
        for asked in (10.0, 0.0, float("nan")):
            subscription = await _subscribe(c, asked)
            assert subscription.RevisedPublishingInterval == MIN_PUBLISHING_INTERVAL_MS
        slow = await _subscribe(c, 1000.0)
        assert slow.RevisedPublishingInterval == 1000.0
        (item,) = await _items(c, subscription.SubscriptionId, 1, sampling_ms=0.0)
        assert item.StatusCode.is_good()
        assert item.RevisedSamplingInterval == MIN_PUBLISHING_INTERVAL_MS
        modified = await c.uaclient.modify_monitored_items(
            ua.ModifyMonitoredItemsParameters(
                SubscriptionId=subscription.SubscriptionId,
                TimestampsToReturn=ua.TimestampsToReturn.Both,
                ItemsToModify=[
                    ua.MonitoredItemModifyRequest(
                        MonitoredItemId=item.MonitoredItemId,
                        RequestedParameters=ua.MonitoringParameters(SamplingInterval=1.0),
                    )
                ],
            )
        )
        assert [m.RevisedSamplingInterval for m in modified] == [MIN_PUBLISHING_INTERVAL_MS]


async def test_items_past_the_session_cap_are_refused(tmp_path: Path) -> None:
    cap = 1000  # the default of [opcua] max_monitored_items_per_session
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server), connected(server.url) as c:
        first = (await _subscribe(c)).SubscriptionId
        results = await _items(c, first, cap + 5)  # in slices of ITEMS_PER_TURN
        assert _codes(results) == ["Good"] * cap + ["BadTooManyMonitoredItems"] * 5
        assert len({r.MonitoredItemId for r in results[:cap]}) == cap
        # The cap is the session's, over its subscriptions.
        second = (await _subscribe(c)).SubscriptionId
        assert _codes(await _items(c, second, 1)) == ["BadTooManyMonitoredItems"]


async def test_items_past_the_address_cap_are_refused_and_freed_with_their_session(
    tmp_path: Path,
) -> None:
    caps = "max_monitored_items_per_session = 3\nmax_monitored_items_per_address = 5"
    async with (
        opcua_gateway(opcua_toml(tmp_path, opcua_extra=caps)) as (_, server),
        _sessions(server.url, 2) as (one, two),
        connected(server.url) as three,
    ):
        one_sub = (await _subscribe(one)).SubscriptionId
        assert _codes(await _items(one, one_sub, 4)) == ["Good"] * 3 + ["BadTooManyMonitoredItems"]
        two_sub = (await _subscribe(two)).SubscriptionId
        assert _codes(await _items(two, two_sub, 3)) == ["Good"] * 2 + ["BadTooManyMonitoredItems"]
        three_sub = (await _subscribe(three)).SubscriptionId
        assert _codes(await _items(three, three_sub, 1)) == ["BadTooManyMonitoredItems"]
        await one.disconnect()  # its session closes, its subscription with it
        assert _codes(await _items(three, three_sub, 4)) == ["Good"] * 3 + [
            "BadTooManyMonitoredItems"
        ]


async def test_subscriptions_past_the_session_cap_are_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(_subscriptions, "SUBSCRIPTIONS_PER_SESSION", 2)
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server), connected(server.url) as c:
        await _subscribe(c)
        await _subscribe(c)
        with pytest.raises(UaStatusCodeError) as refused:
            await _subscribe(c)
        assert refused.value.code == ua.StatusCodes.BadTooManySubscriptions
        async with connected(server.url) as other:  # another session's are its own
            await _subscribe(other)
