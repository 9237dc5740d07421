"""The speed patches (gateway/opcua/_speedups.py) against asyncua's own.

share_frozen_values' data-change callback must queue the notifications
asyncua's queues, on the same items and values.

push_frozen writes a value and queues its notifications without asyncua's
coroutines: two variables watched by one subscription, one pushed by it and
one written by asyncua with the same values, must notify the same. Where it
would not be the same (a subscription that publishes as soon as something
is queued, a callback that is not a monitored item's, a Bad value that is
not Null), it does nothing and says so. encode_frozen_values must put the
fast encoder in asyncua's encoders, with the same bytes.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from datetime import UTC, datetime
from typing import Any, cast

import pytest
from asyncua import Node, Server, ua
from asyncua.server.monitored_item_service import MonitoredItemData, MonitoredItemService
from asyncua.ua import ua_binary
from waiting import wait_for

from sj300_async.gateway.opcua import _speedups, _wire

# Nothing to compare where they are off (SJ300_OPCUA_SPEEDUPS=0, an untested asyncua):
# test_opcua_speedups.py checks that nothing of asyncua is replaced then.
pytestmark = pytest.mark.skipif(
    not _speedups.ENABLED, reason=f"speed patches off: {_speedups.OFF_BECAUSE}"
)


class _Handler:
    def __init__(self) -> None:
        self.seen: dict[str, list[tuple[object, int]]] = {}

    def datachange_notification(self, node: Node, value: object, data: Any) -> None:
        dv = data.monitored_item.Value
        self.seen.setdefault(node.nodeid.Identifier, []).append((value, dv.StatusCode.value))


@pytest.fixture
async def space() -> AsyncIterator[tuple[Server, Node, Node]]:
    """A server (not listening: its own subscriptions only), with two Double variables."""
    _speedups.share_frozen_values()
    server = Server()
    await server.init()
    ns = await server.register_namespace("urn:test:fast-paths")
    objects = server.nodes.objects
    ours = await objects.add_variable(ua.NodeId("ours", ns), "ours", 0.0)
    theirs = await objects.add_variable(ua.NodeId("theirs", ns), "theirs", 0.0)
    yield server, ours, theirs
    for subscription in list(server.iserver.subscription_service.subscriptions.values()):
        await subscription.stop()


def _frozen(value: float | None, status: int = 0) -> _speedups.FrozenDataValue:
    now = datetime.now(UTC)
    variant = (
        ua.Variant(None, ua.VariantType.Null)
        if value is None
        else ua.Variant(value, ua.VariantType.Double)
    )
    return _speedups.FrozenDataValue(
        Value=variant, StatusCode=ua.StatusCode(status), SourceTimestamp=now, ServerTimestamp=now
    )


async def test_a_pushed_value_notifies_as_asyncua_s_write_does(
    space: tuple[Server, Node, Node],
) -> None:
    server, ours, theirs = space
    handler = _Handler()
    subscription = await server.create_subscription(20, handler)
    await subscription.subscribe_data_change([ours, theirs])
    await wait_for(lambda: len(handler.seen) == 2, "the initial values")
    values = [
        _frozen(1.0), _frozen(1.0), _frozen(2.5),
        _frozen(2.5, ua.StatusCodes.UncertainLastUsableValue),
        _frozen(None, ua.StatusCodes.BadWaitingForInitialData), _frozen(3.0),
    ]  # fmt: skip
    for value in values:  # both in the same loop turn: one publish carries both
        assert _speedups.push_frozen(server, ours.nodeid, value)
        await server.write_attribute_value(theirs.nodeid, value)
        await wait_for(
            lambda: (
                handler.seen["ours"][-1:] == handler.seen["theirs"][-1:]
                and len(handler.seen["ours"]) == len(handler.seen["theirs"])
            ),
            "the same notifications",
        )
        await asyncio.sleep(0.03)  # a publish interval between values: none coalesced
    assert handler.seen["ours"] == handler.seen["theirs"]
    assert handler.seen["ours"][1:] == [
        (1.0, 0), (2.5, 0), (2.5, ua.StatusCodes.UncertainLastUsableValue),
        (None, ua.StatusCodes.BadWaitingForInitialData), (3.0, 0),
    ]  # fmt: skip


async def test_values_queued_within_one_publish_interval_are_kept_as_asyncua_keeps_them(
    space: tuple[Server, Node, Node],
) -> None:
    """Several values in one loop turn: each item's queue (size 1, 2, unbounded) keeps the
    same ones, dropped oldest first."""
    server, ours, theirs = space
    for size in (1, 2, 0):
        handler = _Handler()
        subscription = await server.create_subscription(20, handler)
        await subscription.subscribe_data_change([ours, theirs], queuesize=size)
        await wait_for(lambda: len(handler.seen) == 2, "the initial values")  # noqa: B023
        for step in range(1, 5):
            value = _frozen(100.0 * size + step)
            assert _speedups.push_frozen(server, ours.nodeid, value)
            await server.write_attribute_value(theirs.nodeid, value)
        last = (100.0 * size + 4, 0)
        await wait_for(
            lambda: handler.seen["ours"][-1:] == handler.seen["theirs"][-1:] == [last],  # noqa: B023
            "the last value",
        )
        assert handler.seen["ours"] == handler.seen["theirs"]
        assert len(handler.seen["ours"]) - 1 == (size or 4)
        await subscription.delete()


async def test_a_failing_item_leaves_the_others_notified_as_asyncua_does(
    space: tuple[Server, Node, Node],
) -> None:
    """asyncua's deadband fails on a value that goes to or from Null; the items on the
    same value in another subscription are notified all the same."""
    server, ours, theirs = space
    deadband, plain = _Handler(), _Handler()
    filtered = await server.create_subscription(20, deadband)
    await filtered.deadband_monitor([ours, theirs], 0.5)
    unfiltered = await server.create_subscription(20, plain)
    await unfiltered.subscribe_data_change([ours, theirs])
    await wait_for(lambda: len(plain.seen) == len(deadband.seen) == 2, "the initial values")
    for value in (
        _frozen(1.0),
        _frozen(None, ua.StatusCodes.BadWaitingForInitialData),
        _frozen(2.0),
    ):
        assert _speedups.push_frozen(server, ours.nodeid, value)
        await server.write_attribute_value(theirs.nodeid, value)
        await asyncio.sleep(0.05)  # a publish interval or two between values
    await wait_for(lambda: len(plain.seen["ours"]) == 4, "every value, unfiltered")
    assert plain.seen["ours"] == plain.seen["theirs"]
    assert deadband.seen["ours"] == deadband.seen["theirs"]


async def test_what_push_frozen_leaves_to_asyncua_is_left_untouched(
    space: tuple[Server, Node, Node],
) -> None:
    server, ours, theirs = space
    before = await ours.read_data_value()
    # A subscription with no publishing interval publishes as an item's first value comes.
    at_once = await server.create_subscription(0, _Handler())
    await at_once.subscribe_data_change(ours)
    assert not _speedups.push_frozen(server, ours.nodeid, _frozen(7.0))
    assert (await ours.read_data_value()).Value == before.Value
    # A data-change callback that is not a monitored item's.
    space_ = server.iserver.aspace
    space_.add_datachange_callback(theirs.nodeid, ua.AttributeIds.Value, lambda *a: None)
    assert not _speedups.push_frozen(server, theirs.nodeid, _frozen(7.0))
    # A Bad value that carries a value (asyncua would store Null), a value of another type
    # (asyncua refuses it), a node that is not there.
    fresh = await server.nodes.objects.add_variable(ua.NodeId("fresh", 9), "fresh", 0.0)
    assert not _speedups.push_frozen(
        server, fresh.nodeid, _frozen(7.0, ua.StatusCodes.BadWaitingForInitialData)
    )
    wrong = _frozen(7.0)
    wrong.Value = ua.Variant(7, ua.VariantType.Int32)
    assert not _speedups.push_frozen(server, fresh.nodeid, wrong)
    assert not _speedups.push_frozen(server, ua.NodeId("absent", 9), _frozen(7.0))
    assert _speedups.push_frozen(server, fresh.nodeid, _frozen(7.0))  # and a plain one is done
    assert (await fresh.read_value()) == 7.0


def test_asyncua_encodes_a_frozen_value_with_the_fast_encoder(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    _speedups.encode_frozen_values()
    assert _speedups._serializers is not None
    generic = _speedups._serializers(ua.DataValue)
    calls: list[object] = []
    fast = _wire.datavalue_binary

    def counted(value: Any) -> bytes | None:
        calls.append(value)
        return fast(value)

    monkeypatch.setattr(_speedups, "datavalue_binary", counted)
    value = _frozen(12.5)
    item = ua.MonitoredItemNotification(ClientHandle=3, Value=value)
    notification = ua.DataChangeNotification(MonitoredItems=[item])
    encoded = ua_binary.struct_to_binary(notification)
    assert calls == [value]
    assert generic(value) in encoded
    assert encoded == ua_binary.struct_to_binary(
        ua.DataChangeNotification(
            MonitoredItems=[ua.MonitoredItemNotification(ClientHandle=3, Value=ua.DataValue(
                Value=value.Value, StatusCode=value.StatusCode,
                SourceTimestamp=value.SourceTimestamp, ServerTimestamp=value.ServerTimestamp,
            ))]
        )
    )  # fmt: skip


class _Queue:
    """What a monitored-item service hands its subscription: each notification queued."""

    def __init__(self) -> None:
        self.data = ua.CreateSubscriptionResult(SubscriptionId=1)
        self.queued: list[tuple[int, int, Any, int]] = []

    async def enqueue_datachange_event(
        self, mid: int, event: ua.MonitoredItemNotification, maxsize: int
    ) -> None:
        self.queued.append((mid, event.ClientHandle, event.Value, maxsize))


def _item(mode: ua.MonitoringMode, item_filter: object) -> tuple[MonitoredItemService, _Queue]:
    queue = _Queue()
    service = MonitoredItemService(cast(Any, queue), cast(Any, None))
    item = MonitoredItemData()
    item.client_handle, item.mode, item.filter, item.queue_size = 7, mode, item_filter, 3
    service._monitored_items[111] = item
    service._monitored_datachange[5] = 111
    return service, queue


def _frozen_double(value: float, status: int = 0) -> _speedups.FrozenDataValue:
    return _speedups.FrozenDataValue(
        Value=ua.Variant(value, ua.VariantType.Double), StatusCode=ua.StatusCode(status)
    )


@pytest.mark.parametrize(
    ("mode", "trigger", "deadband"),
    [
        (ua.MonitoringMode.Reporting, None, None),
        (ua.MonitoringMode.Disabled, None, None),
        (ua.MonitoringMode.Reporting, ua.DataChangeTrigger.StatusValue, 1.0),
        (ua.MonitoringMode.Reporting, ua.DataChangeTrigger.Status, 0.0),
        (ua.MonitoringMode.Sampling, ua.DataChangeTrigger.StatusValueTimestamp, 0.0),
    ],
)
async def test_a_frozen_value_is_notified_as_asyncua_notifies_it(
    mode: ua.MonitoringMode, trigger: ua.DataChangeTrigger | None, deadband: float | None
) -> None:
    """share_frozen_values' data-change callback, for the gateway's values, against
    asyncua's own (kept aside when it was replaced), on the same items and values:
    the same notifications, queued the same way (mode, trigger, deadband honoured)."""
    _speedups.share_frozen_values()
    assert _speedups._notifying is not None
    item_filter = (
        None
        if trigger is None
        else ua.DataChangeFilter(
            Trigger=trigger,
            DeadbandType=ua.DeadbandType.Absolute if deadband else ua.DeadbandType.None_,
            DeadbandValue=deadband or 0.0,
        )
    )
    values = [
        _frozen_double(10.0), _frozen_double(10.0), _frozen_double(10.5), _frozen_double(12.0),
        _frozen_double(12.0, ua.StatusCodes.UncertainLastUsableValue), _frozen_double(13.5),
    ]  # fmt: skip
    ours, ours_queue = _item(mode, item_filter)
    theirs, their_queue = _item(mode, item_filter)
    for value in values:
        await ours.datachange_callback(5, value)
        await _speedups._notifying(theirs, 5, value)
    assert ours_queue.queued == their_queue.queued
    assert all(any(queued[2] is v for v in values) for queued in ours_queue.queued)  # as is
    if mode != ua.MonitoringMode.Disabled:
        assert ours_queue.queued  # something was notified: the comparison compared something
