"""The workbench's JSON: a drive, a trip and a line as the API and the event stream carry them.

Sans-IO. Everything here is plain ``dict`` / ``list`` / ``float`` / ``str``
/ ``None``, ready for ``json.dumps``; docs/WORKBENCH_API.md is the user's
description of each field.

Decisions:

- The staleness rule is the other northbounds': a value older than the
  gateway's ``stale_after_s`` at the moment it is encoded is null (MQTT
  publishes null, Modbus refuses the read), never served as if current.
- Times are Unix seconds: the sample's (``time``) and the monitor read's
  (``monitor_time``, the trend's clock), so that a page can place a live
  event on the trend it loaded.
- A drive carries its trip history's time (``trips_time``), not the
  history itself: the history is fetched when that changes, which keeps
  every live event of every drive small.
"""

from __future__ import annotations

from typing import Any, Final

from ...profiles import NEVER, DriveSnapshot, Trip, TripLog
from ...wire import Direction

__all__ = ["drive_json", "monitor_time", "trip_json", "trip_log_json", "unix_time"]

Json = dict[str, Any]

_DIRECTIONS: Final = {
    Direction.STOP: "stop",
    Direction.FORWARD: "forward",
    Direction.REVERSE: "reverse",
}


def unix_time(snapshot: DriveSnapshot, at: float) -> float | None:
    """Loop time *at* of a value of *snapshot* as Unix time (None: never read)."""
    if at == NEVER:
        return None
    return snapshot.time - (snapshot.taken_at - at)


def monitor_time(snapshot: DriveSnapshot) -> float | None:
    """When *snapshot*'s monitor values were read, in Unix time (None: never)."""
    return unix_time(snapshot, snapshot.monitor_at)


def trip_json(trip: Trip) -> Json:
    """One trip with its meaning and the drive's values at the trip."""
    return {
        "code": trip.code,
        "number": trip.number,
        "name": trip.name,
        "meaning": trip.meaning,
        "output_frequency_hz": trip.output_frequency_hz,
        "output_current_a": trip.output_current_a,
        "output_voltage_v": trip.output_voltage_v,
        "run_time_h": trip.run_time_h,
        "power_on_time_h": trip.power_on_time_h,
        "details": [{"name": name, "value": value} for name, value in trip.details],
    }


def trip_log_json(log: TripLog | None, time: float | None) -> Json:
    """A drive's trip history, newest first; ``records`` empty when never read."""
    return {
        "time": time,
        "total_count": None if log is None else log.total_count,
        "records": [] if log is None else [trip_json(trip) for trip in log.records],
    }


def drive_json(snapshot: DriveSnapshot, *, now: float, stale_after_s: float) -> Json:
    """*snapshot* at loop time *now* (see the module docstring)."""
    # Every sample of every drive comes here while an event stream is open: each
    # freshness test is is_fresh's, inline (no closure made per call).
    status = now - snapshot.status_at <= stale_after_s
    monitor = now - snapshot.monitor_at <= stale_after_s
    direction = snapshot.direction
    trip = snapshot.trip if status and snapshot.tripped else None
    parameters: dict[str, Json | None] = {
        code: {"value": reading.value, "raw": reading.raw, "unit": reading.unit}
        if now - reading.at <= stale_after_s
        else None
        for code, reading in snapshot.parameters.items()
    }
    for code in snapshot.unavailable_parameters:
        parameters[code] = None
    return {
        "line": snapshot.line,
        "node": snapshot.node,
        "protocol": snapshot.protocol,
        "unit": snapshot.unit,
        "time": snapshot.time,
        "online": snapshot.available,
        "sample_age_s": snapshot.sample_age_s(now),
        "state": snapshot.state if status else None,
        "running": snapshot.running if status else None,
        "tripped": snapshot.tripped if status else None,
        "status": dict(snapshot.status_fields)
        if status and snapshot.status_fields is not None
        else None,
        "direction": _DIRECTIONS.get(direction)
        if direction is not None and now - snapshot.direction_at <= stale_after_s
        else None,
        "monitor_time": monitor_time(snapshot),
        "output_frequency_hz": snapshot.output_frequency_hz if monitor else None,
        "output_current_a": snapshot.output_current_a if monitor else None,
        "output_voltage_v": snapshot.output_voltage_v if monitor else None,
        "output_torque_percent": snapshot.output_torque_percent if monitor else None,
        "power_kw": snapshot.power_kw if monitor else None,
        "set_frequency_hz": snapshot.set_frequency_hz
        if now - snapshot.set_frequency_at <= stale_after_s
        else None,
        "trip": None if trip is None else trip_json(trip),
        "trips_time": unix_time(snapshot, snapshot.trips_at),
        "parameters": parameters,
    }
