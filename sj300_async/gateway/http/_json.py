"""The workbench's JSON: a drive, a trip and a line as the API and the event stream carry them.

Sans-IO. Everything here is plain ``dict`` / ``list`` / ``float`` / ``str``
/ ``None``, ready for ``json.dumps``; docs/WORKBENCH_API.md is the user's
description of each field.

Decisions:

- What is served of a drive is the gateway's judgement, not this
  module's: the values come masked (:class:`~sj300_async.gateway.ServedValues`,
  a stale, unavailable or unread value None, the direction in words), and
  this module only writes them as JSON. So a value is null here exactly
  when MQTT publishes null and Modbus refuses the read.
- Times are Unix seconds: the sample's (``time``) and the monitor read's
  (``monitor_time``, the trend's clock), so that a page can place a live
  event on the trend it loaded.
- A drive carries its trip history's time (``trips_time``), not the
  history itself: the history is fetched when that changes, which keeps
  every live event of every drive small.
"""

from __future__ import annotations

from typing import Any

from ...profiles import NEVER, DriveSnapshot, Trip, TripLog
from .. import ServedValues
from ..recorder import trip_fields

__all__ = ["drive_json", "monitor_time", "trip_json", "trip_log_json", "unix_time"]

Json = dict[str, Any]


def unix_time(snapshot: DriveSnapshot, at: float) -> float | None:
    """Loop time *at* of a value of *snapshot* as Unix time (None: never read)."""
    if at == NEVER:
        return None
    return snapshot.time - (snapshot.taken_at - at)


def monitor_time(snapshot: DriveSnapshot) -> float | None:
    """When *snapshot*'s monitor values were read, in Unix time (None: never)."""
    return unix_time(snapshot, snapshot.monitor_at)


def trip_json(trip: Trip) -> Json:
    """One trip with its meaning and the drive's values at the trip (as a trip record
    keeps it)."""
    fields = trip_fields(trip)
    assert fields is not None
    return fields


def trip_log_json(log: TripLog | None, time: float | None) -> Json:
    """A drive's trip history, newest first; ``records`` empty when never read."""
    return {
        "time": time,
        "total_count": None if log is None else log.total_count,
        "records": [] if log is None else [trip_json(trip) for trip in log.records],
    }


def drive_json(snapshot: DriveSnapshot, values: ServedValues) -> Json:
    """*snapshot* as served: *values* are the gateway's, as of the sample or of a reader's now.

    The snapshot gives what is not judged (the drive's name, its times); every
    value comes from *values* (see the module docstring).
    """
    trip = values.trip
    status = values.status_fields
    parameters: dict[str, Json | None] = {
        code: None
        if reading is None
        else {"value": reading.value, "raw": reading.raw, "unit": reading.unit}
        for code, reading in values.parameters.items()
    }
    return {
        "line": snapshot.line,
        "node": snapshot.node,
        "protocol": snapshot.protocol,
        "unit": snapshot.unit,
        "time": snapshot.time,
        "online": values.online,
        "sample_age_s": values.sample_age_s,
        "state": values.state,
        "running": values.running,
        "tripped": values.tripped,
        "status": None if status is None else dict(status),
        "direction": values.direction,
        "monitor_time": monitor_time(snapshot),
        "output_frequency_hz": values.output_frequency_hz,
        "output_current_a": values.output_current_a,
        "output_voltage_v": values.output_voltage_v,
        "output_torque_percent": values.output_torque_percent,
        "power_kw": values.power_kw,
        "set_frequency_hz": values.set_frequency_hz,
        "trip": None if trip is None else trip_json(trip),
        "trips_time": unix_time(snapshot, snapshot.trips_at),
        "parameters": parameters,
    }
