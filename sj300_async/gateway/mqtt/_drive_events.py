"""What happened to a drive, as events on ``…/<line>/<node>/event``: refused, tripped, lapsed.

Sans-IO. Home Assistant shows each drive's events in an ``event`` entity
(:mod:`._discovery`): a refused command, a trip, a lapse, each in its
logbook and each able to trigger an automation (issue 43: before, a
refusal was visible only to whoever read ``…/error``). The payload is one
JSON object with ``event_type`` (what HA's MQTT event entity keys on) and
what else there is to say, which HA keeps as the event's attributes.

- **refused**: every refusal answered on ``…/error``, with the same words
  (``reason``, the neutral refusal; ``error``, the sentence; ``command``
  and ``payload``, what was sent, as an escaped excerpt). It is under the
  same reply budget: a flood of junk makes no flood of events.
- **tripped**: the served drive's ``tripped`` turned true, with the trip's
  code and meaning when the history named it already (else null: the trip
  sensor shows the code once it is read).
- **lapsed**: a lapsed lease's stop began (``lapse_pending`` turned true;
  a line with ``on_lapse = "hold"`` lapses without one, and says nothing).

A trip record kept (the gateway's recorder, :mod:`sj300_async.gateway.recorder`)
is a message of its own on ``…/<line>/<node>/trip`` (:func:`trip_record_event`,
``event_type`` ``trip``): the code, the meaning and the record's id, which
``GET /api/v1/trips/ID`` serves. It comes ``after_s`` after the trip, once the
record is written: the ``tripped`` event above is the trip's moment.

A drive's first sample is no transition: a drive tripped when the gateway
starts shows it on its trip sensor, not as an event. Events are not
retained: one that happened while Home Assistant was away is not news
when it comes back.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    from .. import ServedDrive
    from ..recorder import RecordSummary

__all__ = ["EVENT_TYPES", "TRIP_EVENT_TYPES", "DriveEvents", "refused_event", "trip_record_event"]

#: Every ``event_type`` published (the event entity's ``event_types``).
EVENT_TYPES: Final = ("refused", "tripped", "lapsed")


#: The ``event_type`` of ``…/trip`` (the trips' event entity's ``event_types``).
TRIP_EVENT_TYPES: Final = ("trip",)


def trip_record_event(summary: RecordSummary) -> dict[str, Any]:
    """A trip record kept, as the message on ``…/trip``."""
    return {
        "event_type": "trip",
        "code": summary.code,
        "meaning": summary.meaning,
        "record": summary.id,
        "seen_by": summary.seen_by,
        "time": summary.time,
    }


def refused_event(command: str, payload: str, error: str, reason: str | None) -> dict[str, Any]:
    """A refusal as an event (the words of its ``…/error`` reply)."""
    return {
        "event_type": "refused",
        "command": command,
        "payload": payload,
        "reason": reason,
        "error": error,
        "time": time.time(),
    }


class DriveEvents:
    """The tripped and lapsed transitions of each drive as served (module docstring)."""

    def __init__(self) -> None:
        #: Per drive: (tripped, lapse pending) as last served.
        self._last: dict[tuple[str, int], tuple[bool, bool]] = {}

    def on_served(self, served: ServedDrive) -> list[dict[str, Any]]:
        """The events *served* makes, against the drive's last one (none the first time)."""
        snapshot, values = served.snapshot, served.values()
        key = (snapshot.line, snapshot.node)
        # A stale status (None) is no news either way: the last known holds.
        before = self._last.get(key)
        tripped = bool(values.tripped) if values.tripped is not None else bool(before and before[0])
        now = (tripped, served.lapse_pending)
        self._last[key] = now
        if before is None:
            return []
        events: list[dict[str, Any]] = []
        if now[0] and not before[0]:
            trip = values.trip
            events.append(
                {
                    "event_type": "tripped",
                    "trip": None if trip is None else trip.code,
                    "meaning": None if trip is None else trip.meaning,
                    "time": snapshot.time,
                }
            )
        if now[1] and not before[1]:
            events.append({"event_type": "lapsed", "time": snapshot.time})
        return events
