"""A drive's state as published on MQTT: a snapshot -> :class:`~._topics.StateMessage`.

Sans-IO but for :func:`drive_state`, which reads the loop's clock. A value
is published only when younger than ``stale_after_s`` at the moment of
publishing (the rule of the Modbus reads), else it is null; the message's
``time`` is the sample's, in Unix time. A polled parameter that is stale, or
that the drive refused to read (unavailable), is null; one never read yet is
left out (the gateway polls it before it knows). The trip is the snapshot's
present trip (known only from a trip history read after the trip was seen),
shown only while the drive's status is fresh.
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Final

from ...profiles import DriveSnapshot, is_fresh
from ...wire import Direction
from ._topics import StateMessage

if TYPE_CHECKING:
    from .. import GatewayView

__all__ = ["drive_state", "state_message"]

_DIRECTIONS: Final = {
    Direction.STOP: "stop",
    Direction.FORWARD: "forward",
    Direction.REVERSE: "reverse",
}


def state_message(
    gateway: str,
    snapshot: DriveSnapshot,
    *,
    now: float,
    stale_after_s: float,
    lapse_pending: bool = False,
) -> StateMessage:
    """*snapshot* as published at loop time *now* (see the module docstring).

    *lapse_pending*: the gateway's word that a lapsed lease's stop is not
    confirmed yet (not part of the snapshot: it is the gateway's, not the drive's).
    """
    status = is_fresh(snapshot.status_at, now, stale_after_s)
    monitor = is_fresh(snapshot.monitor_at, now, stale_after_s)
    direction = snapshot.direction
    trip = snapshot.trip if status and snapshot.tripped else None
    parameters: dict[str, float | None] = {
        code: reading.value if is_fresh(reading.at, now, stale_after_s) else None
        for code, reading in snapshot.parameters.items()
    }
    for code in snapshot.unavailable_parameters:
        parameters[code] = None
    set_hz = snapshot.set_frequency_hz
    return StateMessage(
        gateway=gateway,
        line=snapshot.line,
        node=snapshot.node,
        protocol=snapshot.protocol,
        time=snapshot.time,
        online=snapshot.available,
        output_frequency_hz=snapshot.output_frequency_hz if monitor else None,
        output_current_a=snapshot.output_current_a if monitor else None,
        output_voltage_v=snapshot.output_voltage_v if monitor else None,
        direction=(
            _DIRECTIONS.get(direction)
            if direction is not None and is_fresh(snapshot.direction_at, now, stale_after_s)
            else None
        ),
        running=snapshot.running if status else None,
        tripped=snapshot.tripped if status else None,
        trip=None if trip is None else trip.code,
        set_frequency_hz=set_hz
        if is_fresh(snapshot.set_frequency_at, now, stale_after_s)
        else None,
        output_torque_percent=snapshot.output_torque_percent if monitor else None,
        power_kw=snapshot.power_kw if monitor else None,
        status=None if not status or snapshot.status_fields is None else snapshot.status_fields,
        parameters=parameters,
        state=snapshot.state if status else None,
        trip_meaning=None if trip is None else trip.meaning,
        lapse_pending=lapse_pending,
    )


def drive_state(
    gateway: GatewayView | None, gateway_id: str, snapshot: DriveSnapshot, stale_after_s: float
) -> StateMessage:
    """*snapshot*'s state message now, with the gateway's word on its lapse (in the loop)."""
    drive = None if gateway is None else gateway.drive(snapshot.line, snapshot.node)
    return state_message(
        gateway_id,
        snapshot,
        now=asyncio.get_running_loop().time(),
        stale_after_s=stale_after_s,
        lapse_pending=drive is not None and drive.lapse_pending,
    )
