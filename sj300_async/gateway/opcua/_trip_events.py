"""Each trip record as an OPC UA event: what a SCADA alarm list shows of a trip.

When the gateway keeps a trip record, the server emits one event of
``DriveTripEventType`` (a subtype of ``BaseEventType`` in the gateway's
namespace, with ``TripCode`` and ``RecordId``) from the ``Server`` object,
where SCADA clients subscribe to events: ``SourceNode`` is the drive's
object, ``SourceName`` its ``line/node``, ``Message`` the trip's meaning
(with its code), ``Severity`` :data:`SEVERITY`, ``Time`` the trip's own.

Decisions (docs/OPCUA.md):

- **An event, not an AlarmConditionType.** asyncua 2.1 carries conditions'
  fields and ConditionRefresh but implements none of their methods
  (Acknowledge, Confirm, Enable): an alarm a client cannot acknowledge
  would leave every trip active in the SCADA's list for ever. The drive's
  ``Tripped`` variable is the state; this event is the news, with the record
  to fetch (``GET /api/v1/trips/ID``).
- **From the Server object.** asyncua delivers an event to the monitored
  items of the node that emits it; alarm lists subscribe to ``Server``
  (i=2253), so that is where every trip is emitted from.
- **Bounded, in order.** Events wait in a queue of :data:`QUEUE` for one
  task that triggers them one at a time; past it a record's event is
  dropped and counted (``sj300_opcua_trip_events_total{result="dropped"}``).
"""

from __future__ import annotations

import asyncio
import collections
import logging
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any, Final

from asyncua import ua

if TYPE_CHECKING:
    from asyncua import Server
    from asyncua.server.event_generator import EventGenerator

    from ..recorder import RecordSummary

__all__ = ["EVENT_TYPE", "QUEUE", "SEVERITY", "TripEvents"]

_log = logging.getLogger("sj300_async.gateway.opcua")

#: The event type's browse name (in the gateway's namespace).
EVENT_TYPE: Final = "DriveTripEventType"
#: A trip's severity (1..1000): high, where alarm lists show a motor that stopped.
SEVERITY: Final = 800
#: Events waiting to be emitted, at most.
QUEUE: Final = 256
#: The event type's own properties.
_PROPERTIES: Final = (("TripCode", ua.VariantType.String), ("RecordId", ua.VariantType.String))


class TripEvents:
    """The trip events of one OPC UA server (see the module docstring)."""

    #: The nodes the event type adds to the gateway's namespace: itself, its properties.
    type_nodes: Final[int] = 1 + len(_PROPERTIES)

    def __init__(self, generator: EventGenerator) -> None:
        self._generator = generator
        self._queue: collections.deque[tuple[RecordSummary, ua.NodeId]] = collections.deque()
        self._wake = asyncio.Event()
        #: Events emitted, dropped (the queue full), failed (asyncua raised: logged).
        self.counts: dict[str, int] = {"emitted": 0, "dropped": 0, "failed": 0}

    @classmethod
    async def install(cls, server: Server, namespace: int) -> TripEvents:
        """The event type in *server*'s address space, and its generator."""
        event_type = await server.create_custom_event_type(
            namespace,
            EVENT_TYPE,
            ua.ObjectIds.BaseEventType,
            list(_PROPERTIES),
        )
        generator = await server.get_event_generator(event_type, ua.ObjectIds.Server)
        return cls(generator)

    def announce(self, summary: RecordSummary, source: ua.NodeId) -> None:
        """Emit *summary*'s event (soon: queued), from the drive object *source*."""
        if len(self._queue) >= QUEUE:
            self.counts["dropped"] += 1
            _log.debug("opcua: trip record %s not announced: %d events wait", summary.id, QUEUE)
            return
        self._queue.append((summary, source))
        self._wake.set()

    async def run(self) -> None:
        """Emit the queued events, one at a time, until cancelled."""
        while True:
            await self._wake.wait()
            self._wake.clear()
            while self._queue:
                summary, source = self._queue.popleft()
                try:
                    await self._emit(summary, source)
                except Exception:  # asyncua's: this event is lost, the next goes
                    self.counts["failed"] += 1
                    _log.exception("opcua: the event of trip record %s failed", summary.id)
                else:
                    self.counts["emitted"] += 1

    async def _emit(self, summary: RecordSummary, source: ua.NodeId) -> None:
        event: Any = self._generator.event
        event.SourceNode = source
        event.SourceName = f"{summary.line}/{summary.node}"
        event.Severity = SEVERITY
        event.TripCode = summary.code or ""
        event.RecordId = summary.id
        what = summary.meaning or "a trip"
        code = f" ({summary.code})" if summary.code else ""
        message = f"{summary.line}/{summary.node} tripped: {what}{code}"
        at = datetime.fromtimestamp(summary.time, UTC)
        await self._generator.trigger(time_attr=at, message=message)
