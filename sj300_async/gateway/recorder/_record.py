"""A trip record's content: its JSON object and its id (its CSV: :mod:`._samples_csv`).

A record is one JSON object (``format`` :data:`~._store.FORMAT`, ``version``
1) with the drive's name, the trip (code, meaning, the values the drive
kept at it), the samples around it, the writes to the drive in its window,
and the name of its pcapng. docs/guide/trips.md shows one whole.

Decisions:

- **The id says what it is**: the trip's UTC time to the millisecond, the
  line and the node (``20261204T153012.345Z-hall-3``): sortable, readable
  in a file listing, safe in a URL and a file name (a line name is
  letters, digits, ``_``, ``.`` and ``-``).
- ``trip_sample`` is the index of the first sample at or after the trip's
  instant: the one a chart marks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from typing import Any, Final

from ...profiles import Trip
from ._samples_csv import utc_text
from ._store import FORMAT

__all__ = ["VERSION", "record_id", "trip_fields"]

VERSION: Final = 1


def record_id(unix: float, line: str, node: int) -> str:
    """The id of a record of a trip at Unix time *unix* on *line*, *node*."""
    at = datetime.fromtimestamp(round(unix, 3), UTC)
    return f"{at:%Y%m%dT%H%M%S}.{at.microsecond // 1000:03d}Z-{line}-{node}"


def trip_fields(trip: Trip | None) -> dict[str, Any] | None:
    """The trip as a record keeps it, and the HTTP API serves one: its code and meaning,
    the values the drive kept, the protocol's own details."""
    if trip is None:
        return None
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


def new_record(
    *,
    record: str,
    gateway: str,
    line: str,
    node: int,
    unit: int,
    protocol: str,
    unix: float,
    seen_by: str,
    interval_s: float,
    before_s: float,
    after_s: float,
    trip: Trip | None,
    samples: Mapping[str, Sequence[object]],
    writes: Sequence[Mapping[str, object]],
) -> dict[str, Any]:
    """A record's JSON object (see the module docstring)."""
    times = samples.get("time", [])
    first = next((i for i, t in enumerate(times) if isinstance(t, float) and t >= unix), None)
    return {
        "format": FORMAT,
        "version": VERSION,
        "id": record,
        "gateway": gateway,
        "line": line,
        "node": node,
        "unit": unit,
        "protocol": protocol,
        "time": unix,
        "time_utc": utc_text(unix),
        "seen_by": seen_by,
        "interval_s": interval_s,
        "before_s": before_s,
        "after_s": after_s,
        "trip": trip_fields(trip),
        "trip_sample": first,
        "samples": dict(samples),
        "writes": list(writes),
        "frames": f"{record}.pcapng",
    }
