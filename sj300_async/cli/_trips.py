"""``sj300 trips``: a drive's trip count and its latest trips, newest first (command 05).

Each trip shows its code and meaning (``E07 over-voltage``, from
:class:`~sj300_async.sj300.TripCode`; a code the reference does not list
reads ``unknown trip``). ``sj300 trips --codes`` lists every known code with
its meaning, without asking a drive.

JSON: ``{"node": 1, "total_count": 3, "records": [{"error_code": "E07",
"name": "OVER_VOLTAGE", "meaning": "over-voltage", "trip_factor": 7,
"status_a": "RUNNING", "status_b": 8, "status_c": "CONSTANT_SPEED",
"output_frequency_hz": 50.0, ...}]}``: the fields of
:class:`~sj300_async.TripHistory` and :class:`~sj300_async.TripRecord`, with
``error_code``, ``name`` and ``meaning`` added and the empty slots of the
six-deep history left out. ``status_b`` is a bit field
(:class:`~sj300_async.TripStatusB`). With ``--codes``: ``{"codes":
[{"code": "E01", "number": 1, "name": "OVER_CURRENT_CONSTANT", "meaning":
"over-current at constant speed"}, ...]}``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..sj300._codes import TripCode
from ..sj300._payloads import TripRecord
from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus
from ._output import Column, human, jsonable, print_json, print_table
from ._session import run_async
from ._tripinfo import sj300_trip

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> None:
    """Add ``trips`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "trips",
        help="trip history",
        description="Read the trip count and the six latest trips (command 05), each with "
        "its meaning; --codes lists every trip code the reference gives.",
    )
    p.add_argument(
        "--codes", action="store_true", help="list the trip codes and their meanings (no drive)"
    )
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the trip history (or with ``--codes`` the code table); return 0."""
    if args.codes:
        return _codes(args)
    return run_async(_trips(args))


def _codes(args: argparse.Namespace) -> int:
    trips = [sj300_trip(code) for code in TripCode]
    if args.json:
        print_json({"codes": [trip.as_json() for trip in trips]})
    else:
        rows = [(trip.code, trip.meaning or "", trip.name or "") for trip in trips]
        print_table((Column("code"), Column("meaning"), Column("name")), rows)
    return 0


def _record_json(record: TripRecord) -> dict[str, Any]:
    code = record.trip_code
    return {
        "error_code": record.error_code,
        "name": code.name,
        "meaning": code.description,
        **jsonable(record),
    }


async def _trips(args: argparse.Namespace) -> int:
    async with open_cli_bus(args) as bus:
        history = await bus.drive(args.node).read_trip_history()
    if args.json:
        records = [_record_json(r) for r in history.trips]
        print_json({"node": args.node, "total_count": history.total_count, "records": records})
        return 0
    title = f"node {args.node:02d}: {history.total_count} trip(s) in total"
    if not history.trips:
        print(f"{title}, none recorded")
        return 0
    columns = (
        Column("#", "right"),
        Column("trip"),
        Column("meaning"),
        Column("state"),
        Column("output"),
        Column("causes"),
        Column("Hz", "right"),
        Column("A", "right"),
        Column("V", "right"),
        Column("run h", "right"),
        Column("on h", "right"),
    )
    rows = [
        (
            str(i),
            r.error_code,
            r.trip_code.description,
            human(r.status_a),
            human(r.status_c),
            human(r.status_b),
            f"{r.output_frequency_hz:.1f}",
            f"{r.output_current_a:.1f}",
            f"{r.output_voltage_v:.1f}",
            str(r.run_time_h),
            str(r.power_on_time_h),
        )
        for i, r in enumerate(history.trips, 1)
    ]
    print_table(columns, rows, title=f"{title}, newest first")
    return 0
