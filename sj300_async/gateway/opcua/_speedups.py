"""The OPC UA northbound's speed patches to asyncua, only on the releases they were tested with.

The hardening (:mod:`._hooks`) is always on: the gateway is unsafe without
it. What is here only makes the gateway faster at plant scale, so it is
applied only where it was checked against asyncua's own behaviour: on an
asyncua release named in :data:`TESTED_ASYNCUA` (the ``opcua`` extra pins
the minor version), unless switched off. Otherwise the gateway keeps
asyncua's public path: its values are plain ``ua.DataValue``, which
asyncua deep-copies and encodes as it always does; a push is asyncua's
``write_attribute_value``; no asyncua class or function is replaced; and
one line at start says that the speed patches are off and why (WARNING
for an untested release, INFO for the switch).

The switch: the environment variable ``SJ300_OPCUA_SPEEDUPS`` (read once,
when this module is imported): ``0``, ``false``, ``no`` or ``off`` turns
the patches off even on a tested release (``make test-opcua-public`` runs
the OPC UA suite so, to show the public path serves the same).

- **Values not copied** (:func:`share_frozen_values`): asyncua deep-copies
  every value written, once per monitored item on it, in case its writer
  changes it afterwards (more than half the northbound's CPU, measured).
  The gateway's values are :class:`FrozenDataValue`, made new for each
  change and never changed after: asyncua keeps them as they are, and its
  monitored items' notifications carry them as they are (asyncua made
  each one empty first). Values of every other kind are copied and
  notified as before.
- **Values pushed without coroutines** (:func:`push_frozen`): asyncua's
  write, where it would do the same, without its six coroutines a value;
  False otherwise, and the caller awaits asyncua's own.
- **Values encoded faster** (:func:`encode_frozen_values`): asyncua's
  encoder of a DataValue is generic, field by field; a
  :class:`FrozenDataValue` of a shape the gateway serves is packed by
  :mod:`._wire` in one ``struct`` call, the same bytes.

- **Drive nodes made when asked for** (:mod:`._lazy`, applied by the
  server where :data:`ENABLED`): the address space's memory.

Each is checked against asyncua's own by ``tests/opcua/test_opcua_fast_paths.py``
and ``tests/opcua/test_opcua_wire.py``; ``tests/opcua/test_opcua_speedups.py``
checks that, switched off, none of asyncua is replaced.
"""

from __future__ import annotations

import functools
import importlib.metadata
import logging
import os
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Final

from asyncua import Server, ua
from asyncua.server.monitored_item_service import MonitoredItemService, MonitoredItemValues
from asyncua.ua import ua_binary

from ._wire import datavalue_binary

__all__ = [
    "ENABLED",
    "OFF_BECAUSE",
    "SWITCH",
    "TESTED_ASYNCUA",
    "FrozenDataValue",
    "ServedDataValue",
    "encode_frozen_values",
    "install",
    "push_frozen",
    "share_frozen_values",
]

_log = logging.getLogger("sj300_async.gateway.opcua")

#: The asyncua releases the speed patches were tested with (each reads asyncua's private
#: monitored-item and encoder internals); another release gets asyncua's public path.
TESTED_ASYNCUA: Final = ("2.1.0",)
#: The environment variable that turns the speed patches off (module docstring).
SWITCH: Final = "SJ300_OPCUA_SPEEDUPS"


def _off_because() -> str | None:
    """Why the speed patches are off in this process (None: they are on)."""
    switch = os.environ.get(SWITCH, "").strip().lower()
    if switch in ("0", "false", "no", "off"):
        return f"{SWITCH}={os.environ[SWITCH]}"
    version = importlib.metadata.version("asyncua")
    if version not in TESTED_ASYNCUA:
        tested = ", ".join(TESTED_ASYNCUA)
        return f"asyncua {version} is not a release they were tested with ({tested})"
    return None


#: Why the speed patches are off (None: on), decided once, at import.
OFF_BECAUSE: Final = _off_because()
#: Whether the speed patches are applied in this process.
ENABLED: Final = OFF_BECAUSE is None


@dataclass
class FrozenDataValue(ua.DataValue):  # type: ignore[misc]
    """A value the gateway never changes once made (see :func:`share_frozen_values`)."""


#: The class the northbound makes its values of: FrozenDataValue with the speed patches,
#: asyncua's own DataValue (which asyncua copies as it copies any) without them.
ServedDataValue: Final[Any] = FrozenDataValue if ENABLED else ua.DataValue

_told = False


def install() -> bool:
    """Apply the speed patches (once per process) where they are on; False, and the reason
    logged once, where they are off (module docstring)."""
    global _told
    if ENABLED:
        share_frozen_values()
        encode_frozen_values()
        return True
    if not _told:
        _told = True
        level = logging.INFO if OFF_BECAUSE and OFF_BECAUSE.startswith(SWITCH) else logging.WARNING
        _log.log(
            level,
            "opcua: speed patches off (%s): asyncua's public path, values deep-copied and "
            "encoded by asyncua",
            OFF_BECAUSE,
        )
    return False


_copying: Callable[[Any, Any], None] | None = None
#: asyncua's own data-change callback, as it was before share_frozen_values (the tests
#: compare the two).
_notifying: Callable[..., Awaitable[None]] | None = None
#: share_frozen_values' data-change callback (push_frozen knows its monitored items by it).
_sharing: Callable[..., Awaitable[None]] | None = None


def share_frozen_values() -> None:
    """Let asyncua keep a :class:`FrozenDataValue` as it is (once per process; nothing
    where the speed patches are off).

    And notify its monitored items with it as it is: asyncua's data-change
    callback makes each notification empty first, a DataValue holding a
    Variant whose type it guesses (about 5 µs, once per value per monitored
    item), then puts the value in. For a FrozenDataValue the notification is
    made with it; the rest (the item's mode, its filter and deadband, the
    queue) is asyncua's own, called as asyncua calls it.
    """
    global _copying, _notifying, _sharing
    if _copying is not None or not ENABLED:
        return
    copying = _copying = MonitoredItemValues.set_current_datavalue
    notifying = _notifying = MonitoredItemService.datachange_callback

    def set_current_datavalue(self: Any, value: Any) -> None:
        if type(value) is FrozenDataValue:
            self.old_dvalue = self.current_dvalue
            self.current_dvalue = value
        else:
            copying(self, value)

    async def datachange_callback(
        self: Any, handle: int, value: Any, error: ua.StatusCode | None = None
    ) -> None:
        if error or type(value) is not FrozenDataValue:
            await notifying(self, handle, value, error)
            return
        notified = _notification(self, handle, value)
        if notified is not None:
            await self.isub.enqueue_datachange_event(*notified)

    MonitoredItemValues.set_current_datavalue = set_current_datavalue
    MonitoredItemService.datachange_callback = datachange_callback
    _sharing = datachange_callback


def _notification(
    service: Any, handle: int, value: FrozenDataValue
) -> tuple[int, ua.MonitoredItemNotification, int] | None:
    """What asyncua's data-change callback queues for *value* on the item of *handle*:
    (item id, notification, queue size), or None when the item reports nothing."""
    mid = service._monitored_datachange[handle]
    item = service._monitored_items[mid]
    if item.mode == ua.MonitoringMode.Disabled:
        return None
    item.mvalue.set_current_datavalue(value)
    if item.filter:
        changed = service._is_data_changed(
            item.mvalue, item.filter.Trigger
        ) and service._is_deadband_exceeded(item.mvalue, item.filter)
    else:
        changed = service._is_data_changed(item.mvalue, ua.DataChangeTrigger.StatusValue)
    if not changed:
        return None
    return (
        mid,
        ua.MonitoredItemNotification(ClientHandle=item.client_handle, Value=value),
        (item.queue_size),
    )


def push_frozen(server: Server, node: ua.NodeId, value: FrozenDataValue) -> bool:
    """Write *value* to *node*'s Value and queue it for its monitored items, as asyncua's
    ``write_attribute_value`` does, without its coroutines; False (nothing done) where
    that would not be the same, and the caller awaits asyncua's own.

    asyncua's write is a coroutine calling each monitored item's callback, a
    coroutine calling its subscription's queue, a coroutine: at plant scale six
    coroutines a value, most of the push's time. Only one thing in it can
    wait: a subscription with no publishing interval publishes as soon as an
    item's first notification is queued. So: the node and its Value exist,
    every callback on it is :func:`share_frozen_values`' (a
    monitored item of a subscription that publishes on its own time), and the
    value is one asyncua would store as it is (a Bad status carries a Null
    value, any other has the node's type). A monitored item whose
    notification fails is logged and the others are notified, as asyncua
    does (its deadband filter fails on a value that goes to or from Null).
    """
    if _sharing is None:  # the speed patches are off: asyncua's own write
        return False
    space = server.iserver.aspace
    record = space._nodes.get(node)
    attribute = None if record is None else record.attributes.get(ua.AttributeIds.Value)
    if attribute is None:
        return False
    if value.StatusCode.is_bad():
        if value.Value.VariantType != ua.VariantType.Null:
            return False
    elif not space._is_expected_variant_type(value, attribute, record):
        return False  # asyncua answers BadTypeMismatch and stores nothing
    callbacks = attribute.datachange_callbacks
    for callback in callbacks.values():
        if getattr(callback, "__func__", None) is not _sharing:
            return False
        subscription = callback.__self__.isub
        if not subscription._task and subscription.data.RevisedPublishingInterval <= 0.0:
            return False
    if attribute.value_setter is not None:  # the gateway's: its binding holds the value
        attribute.value_setter(record, ua.AttributeIds.Value, value)
    else:
        attribute.value = value
        attribute.value_callback = None
    for handle, callback in callbacks.items():
        try:
            _enqueue(callback.__self__, handle, value)
        except Exception:
            _log.exception("opcua: notifying monitored item %s of %s failed", handle, node)
    return True


def _enqueue(service: Any, handle: int, value: FrozenDataValue) -> None:
    """Queue *value* for the item of *handle* as its subscription's queue does."""
    notified = _notification(service, handle, value)
    if notified is None:
        return
    mid, notification, size = notified
    queue = service.isub._triggered_datachanges
    queued = queue.get(mid)
    if queued is None:
        queue[mid] = [notification]
        return
    if size != 0 and len(queued) >= size:
        queued.pop(0)
    queued.append(notification)


#: asyncua's own dataclass-serializer factory, as it was before encode_frozen_values.
_serializers: Callable[[type], Callable[[Any], bytes]] | None = None


def encode_frozen_values() -> None:
    """asyncua encodes a :class:`FrozenDataValue` with :func:`._wire.datavalue_binary`
    (once per process, nothing where the speed patches are off; a shape that leaves to
    asyncua is encoded by asyncua).

    asyncua builds an encoder per structure type once, from its factory, and
    keeps it (``functools.cache``); a structure's encoder holds its fields'
    encoders. The factory is wrapped so that DataValue's is ours, and the
    caches are emptied, so that every encoder built before (a publish
    response's, holding a monitored item's, holding a DataValue's) is built
    again around it.
    """
    global _serializers
    if _serializers is not None or not ENABLED:
        return
    original = _serializers = ua_binary.create_dataclass_serializer
    generic = original(ua.DataValue)

    def datavalue(value: Any) -> bytes:
        if type(value) is FrozenDataValue:
            wire = datavalue_binary(value)
            if wire is not None:
                return wire
        encoded: bytes = generic(value)
        return encoded

    @functools.cache
    def create_dataclass_serializer(dataclazz: type) -> Callable[[Any], bytes]:
        # A DataValue field's encoder is its type's; a value in a variant (a read's, a
        # notification's) is encoded by its own class's.
        if dataclazz is ua.DataValue or dataclazz is FrozenDataValue:
            return datavalue
        serializer: Callable[[Any], bytes] = original(dataclazz)
        return serializer

    ua_binary.create_dataclass_serializer = create_dataclass_serializer
    for cached in (
        original,
        ua_binary.create_type_serializer,
        ua_binary.create_list_serializer,
        ua_binary.create_uatype_serializer,
        ua_binary.create_uatype_array_serializer,
    ):
        cached.cache_clear()
