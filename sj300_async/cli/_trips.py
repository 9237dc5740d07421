"""``sj300 trips``: a drive's trip count and its latest trips, newest first.

For a protocol whose profile reads trip histories (SJ300: command 05); the
others are refused with one line. Each trip shows its code and meaning
(``E07 over-voltage``; a code the reference does not list reads ``unknown
trip``), the drive's values at the trip and what else the protocol's
record says (SJ300: state, output, causes). ``sj300 trips --codes`` lists
every code the protocol's reference names, with its meaning, without
asking a drive.

JSON: ``{"node": 1, "total_count": 3, "records": [{"error_code": "E07",
"name": "OVER_VOLTAGE", "meaning": "over-voltage", ...}]}``: ``error_code``,
``name`` and ``meaning`` first, then the fields of the protocol's record as
its drive class reads it (SJ300 :class:`~sj300_async.TripRecord`: ``status_b``
is a bit field, :class:`~sj300_async.TripStatusB`), the empty slots left out.
With ``--codes``: ``{"codes": [{"code": "E01", "number": 1, "name":
"OVER_CURRENT_CONSTANT", "meaning": "over-current at constant speed"}, ...]}``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..profiles import Trip
from ._common import (
    add_bus_options,
    add_json_option,
    add_node_option,
    cli_profile,
    open_cli_bus,
    profile_of,
    require,
)
from ._output import Column, jsonable, print_json, print_table
from ._session import run_async
from ._trip_record import add_record_options, record

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> None:
    """Add ``trips`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "trips",
        help="trip history",
        description="Read the trip count and the latest trips (SJ300: command 05, six "
        "records), each with its meaning; --codes lists every trip code the reference gives; "
        "--record DIR watches the line and keeps a record of every new trip (the seconds "
        "before and after it, the line's frames) in DIR.",
    )
    p.add_argument(
        "--codes", action="store_true", help="list the trip codes and their meanings (no drive)"
    )
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    add_record_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the trip history (or with ``--codes`` the code table); return 0."""
    if args.codes:
        return _codes(args)
    if args.record is not None:
        return record(args)
    return run_async(_trips(args))


def _codes(args: argparse.Namespace) -> int:
    profile = cli_profile(args)
    require(args, profile, "trip_history")  # a protocol without a history names no codes here
    trips = profile.trip_codes()
    if args.json:
        print_json({"codes": [trip.as_json() for trip in trips]})
    else:
        rows = [(trip.code, trip.meaning or "", trip.name or "") for trip in trips]
        print_table((Column("code"), Column("meaning"), Column("name")), rows)
    return 0


def _record_json(trip: Trip) -> dict[str, Any]:
    own = jsonable(trip.record) if trip.record is not None else {}
    return {"error_code": trip.code, "name": trip.name, "meaning": trip.meaning, **own}


def _number(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


async def _trips(args: argparse.Namespace) -> int:
    async with open_cli_bus(args, needs="trip_history") as bus:
        profile = profile_of(bus)
        log = profile.trip_log(await profile.read_trips(bus.drive(args.node)))
    if args.json:
        records = [_record_json(trip) for trip in log.records]
        print_json({"node": args.node, "total_count": log.total_count, "records": records})
        return 0
    who = f"{profile.node_noun} {args.node:02d}"
    if log.total_count is None:  # the drive counts none: what it keeps is all there is
        title = f"{who}: {len(log.records)} trip(s) recorded"
    else:
        title = f"{who}: {log.total_count} trip(s) in total"
    if not log.records:
        print(f"{title}, none recorded" if log.total_count is not None else title)
        return 0
    labels = [label for label, _ in log.records[0].details]
    # The values at the trip, where the protocol's history records them (an FR-700's not).
    valued = any(trip.output_frequency_hz is not None for trip in log.records)
    values = (
        (
            Column("Hz", "right"),
            Column("A", "right"),
            Column("V", "right"),
            Column("run h", "right"),
            Column("on h", "right"),
        )
        if valued
        else ()
    )
    columns = (
        Column("#", "right"),
        Column("trip"),
        Column("meaning"),
        *(Column(label) for label in labels),
        *values,
    )
    rows = [
        (
            str(i),
            trip.code,
            trip.meaning or "",
            *(text for _, text in trip.details),
            *(
                (
                    _number(trip.output_frequency_hz, 1),
                    _number(trip.output_current_a, 1),
                    _number(trip.output_voltage_v, 1),
                    "-" if trip.run_time_h is None else str(trip.run_time_h),
                    "-" if trip.power_on_time_h is None else str(trip.power_on_time_h),
                )
                if valued
                else ()
            ),
        )
        for i, trip in enumerate(log.records, 1)
    ]
    print_table(columns, rows, title=f"{title}, newest first")
    return 0
