"""A :class:`~._snapshot.DriveSnapshot` from a drive's :class:`~._readings.DriveReadings`.

The one place the neutral model is assembled. The profile read each
result once when it arrived (its views are in the readings); this puts
them together with their read times:

- the direction is the monitor's when it tells one (SJ300's monitor item
  3), else the status's (FR-700's direction bits), each with its own time;
- the present trip is the newest record of a trip history read after the
  drive was first seen tripped, and only while it is tripped.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from ._profile import Profile
from ._readings import DriveReadings
from ._snapshot import NEVER, DriveSnapshot, ParameterReading, Trip

__all__ = ["build_snapshot"]

_NONE: frozenset[str] = frozenset()


def build_snapshot(
    profile: Profile,
    readings: DriveReadings,
    *,
    line: str,
    node: int,
    unit: int | None,
    now: float,
    wall: float,
) -> DriveSnapshot:
    """The drive as *readings* know it at loop time *now* (Unix time *wall*)."""
    status, monitor = readings.status_view, readings.monitor_view
    direction, direction_at = None, NEVER
    if monitor is not None and monitor.direction is not None:
        direction, direction_at = monitor.direction, readings.monitor_at
    elif status is not None and status.direction is not None:
        direction, direction_at = status.direction, readings.status_at
    return DriveSnapshot(
        line=line,
        node=node,
        protocol=profile.name,
        unit=unit,
        taken_at=now,
        time=wall,
        online=readings.online,
        last_ok=readings.last_ok,
        status_at=readings.status_at,
        running=None if status is None else status.running,
        tripped=None if status is None else status.tripped,
        state=None if status is None else status.state,
        status_fields=None if status is None else status.fields,
        monitor_at=readings.monitor_at,
        output_frequency_hz=None if monitor is None else monitor.output_frequency_hz,
        output_current_a=None if monitor is None else monitor.output_current_a,
        output_voltage_v=None if monitor is None else monitor.output_voltage_v,
        output_torque_percent=None if monitor is None else monitor.output_torque_percent,
        power_kw=None if monitor is None else monitor.power_kw,
        direction=direction,
        direction_at=direction_at,
        set_frequency_hz=readings.set_frequency_hz,
        set_frequency_at=readings.set_frequency_at,
        trip=_present_trip(readings),
        trips=readings.trip_log,
        trips_at=readings.trips_at,
        parameters=_parameters(profile, readings),
        unavailable_parameters=frozenset(readings.unavailable) if readings.unavailable else _NONE,
        extras=profile.extras(readings.status, readings.monitor, readings.trips),
    )


def _present_trip(readings: DriveReadings) -> Trip | None:
    since, log = readings.tripped_since, readings.trip_log
    if since is None or log is None or not log.records or readings.trips_at < since:
        return None
    return log.records[0]


def _parameters(profile: Profile, readings: DriveReadings) -> Mapping[str, ParameterReading]:
    if not readings.parameters:
        return MappingProxyType({})
    catalogue = profile.parameters
    out: dict[str, ParameterReading] = {}
    for code, raw in readings.parameters.items():
        spec = catalogue.spec(code)
        out[code] = ParameterReading(
            code, raw, float(spec.from_raw(raw)), spec.unit, readings.parameters_at[code]
        )
    return MappingProxyType(out)
