"""``sj300 status``: a drive's state, status and monitor values, as its profile words them.

The rows are the profile's (:meth:`~sj300_async.profiles.Profile.status_rows`):
the state in words first (``stopped``, ``accelerating``), then the
protocol's own status (SJ300 status A/B/C, FR-700 status bits) and the
monitor values with their units. A tripped drive's trip is named
(``trip  E07 over-voltage``), read from its history.

The set frequency (SJ300 F001, FR-700's set-frequency read) is shown
beside the output frequency; a drive that refuses to give it shows none
(``null`` in JSON).

JSON: ``{"node": 1, "state": "stopped", "trip": null, "direction": "stop",
"set_frequency_hz": 0.0, "status": {"a": "STOPPING",
"b": "STOPPED", "c": "STOP"}, "monitor": {"output_frequency_hz": 50.0, ...}}``:
``status`` and ``monitor`` are the fields of the drive class's results
(SJ300 :class:`~sj300_async.InverterStatus` and
:class:`~sj300_async.MonitorData`; FR-700 :class:`~sj300_async.Fr700Status`
and :class:`~sj300_async.Fr700Monitor`); ``direction`` is the monitor's
or the status's in the monitor record's words (``stop``, ``forward``,
``reverse``; null when neither says), for either protocol; ``trip`` is ``{"code": "E07",
"number": 7, "name": ..., "meaning": ...}`` when tripped and known.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..profiles import Profile, StatusView
from ..wire import Direction, NakError
from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus, profile_of
from ._output import Column, print_json, print_table
from ._record import direction_word
from ._session import run_async
from ._tripinfo import trip_or_none

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> None:
    """Add ``status`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "status",
        help="a drive's state and its monitor values",
        description="Read a drive's status and monitor values (SJ300: commands 04 and 03; "
        "FR-700: H7A and H6F/H70/H71).",
    )
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the status of ``--node``; return 0."""
    return run_async(_status(args))


async def _status(args: argparse.Namespace) -> int:
    async with open_cli_bus(args) as bus:
        profile = profile_of(bus)
        drive = bus.drive(args.node)
        status = await drive.read_status()
        monitor = await drive.read_monitor()
        view = profile.status_view(status)
        trip = await trip_or_none(profile, drive) if view.tripped else None
        setpoint = await _set_frequency(profile, drive)
    if args.json:
        print_json(
            {
                "node": args.node,
                "state": view.state,
                "trip": None if trip is None else trip.as_json(),
                "direction": direction_word(_direction(profile, view, monitor)),
                "set_frequency_hz": setpoint,
                "status": status,
                "monitor": monitor,
            }
        )
        return 0
    rows = profile.status_rows(status, monitor)
    if trip is not None:
        rows.insert(1, ("trip", str(trip)))
    if setpoint is not None:  # beside the output frequency, as a SCADA screen shows them
        at = next((i for i, (item, _) in enumerate(rows) if item == "output frequency"), 1)
        rows.insert(at, ("set frequency", f"{setpoint:.2f} Hz"))
    print_table(
        (Column("item"), Column("value")),
        rows,
        title=f"{profile.node_noun} {args.node:02d}",
        show_header=False,
    )
    return 0


def _direction(profile: Profile, view: StatusView, monitor: Any) -> Direction | None:
    """The monitor's direction, else the status's (as a snapshot takes it)."""
    direction = profile.monitor_view(monitor).direction
    return view.direction if direction is None else direction


async def _set_frequency(profile: Profile, drive: Any) -> float | None:
    """The drive's set frequency, None when it refuses to give it (a NAK)."""
    try:
        return await profile.read_set_frequency(drive)
    except NakError:
        return None
