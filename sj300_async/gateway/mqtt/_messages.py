"""A drive's state as published on MQTT: a drive as served -> :class:`~._topics.StateMessage`.

Sans-IO, and no judgement of its own: what is shown and what is null is
the gateway's served view (:class:`~sj300_async.gateway.ServedDrive`,
decided once per snapshot for every northbound); this module only words
it as the state message's fields. A push (every sample, every write's
read-back) sends the values as served at the sample, the ones every
northbound shares (:meth:`ServedDrive.values()
<sj300_async.gateway.ServedDrive.values>`). So a stale or unavailable value
is null, a polled parameter never read yet is left out, the trip shows
only while the status that says tripped is fresh, and ``lapse_pending`` is
the served drive's. The message's ``time`` is the sample's, in Unix time.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .. import compact_json
from ._topics import StateMessage

if TYPE_CHECKING:
    from .. import ServedDrive

__all__ = ["state_fields", "state_message", "state_payload"]


def state_fields(gateway: str, served: ServedDrive, *, now: float | None = None) -> dict[str, Any]:
    """The state message's fields for *served*, by name (see the module docstring).

    The one mapping from a served drive to the message: :func:`state_message`
    and :func:`state_payload` both read it. *now*: the loop time its values are
    served at; None (a push): at the sample, the values built once for every
    northbound. The mappings are plain dicts, as JSON writes them.
    """
    values = served.values(now)
    snapshot = served.snapshot
    trip = values.trip
    status = values.status_fields
    return {
        "gateway": gateway,
        "line": snapshot.line,
        "node": snapshot.node,
        "protocol": snapshot.protocol,
        "time": snapshot.time,
        "online": values.online,
        "output_frequency_hz": values.output_frequency_hz,
        "output_current_a": values.output_current_a,
        "output_voltage_v": values.output_voltage_v,
        "direction": values.direction,
        "running": values.running,
        "tripped": values.tripped,
        "trip": None if trip is None else trip.code,
        "set_frequency_hz": values.set_frequency_hz,
        "output_torque_percent": values.output_torque_percent,
        "power_kw": values.power_kw,
        "status": None if status is None else dict(status),
        # The served readings carry their read times; the message, their values.
        "parameters": {
            code: None if reading is None else reading.value
            for code, reading in values.parameters.items()
        },
        "state": values.state,
        "trip_meaning": None if trip is None else trip.meaning,
        "lapse_pending": served.lapse_pending,
    }


def state_message(gateway: str, served: ServedDrive, *, now: float | None = None) -> StateMessage:
    """*served* as published by gateway *gateway* (:func:`state_fields`)."""
    return StateMessage(**state_fields(gateway, served, now=now))


def state_payload(gateway: str, served: ServedDrive) -> bytes:
    """``state_message(gateway, served).to_json()``, without building the message.

    The bridge's path, once per drive sample: the frozen message's 22 fields
    cost more to set and read back than the payload costs to write
    (CHANGELOG, issue 42). The same bytes, checked by the tests.
    """
    return compact_json(state_fields(gateway, served), sort_keys=True)
