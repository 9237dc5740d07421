"""``sj300 status``: a drive's status A/B/C and its monitor block.

JSON: ``{"node": 1, "status": {"a": "RUNNING", "b": "RUNNING", "c":
"CONSTANT_SPEED"}, "monitor": {"output_frequency_hz": 50.0, ...}}``, the
fields of :class:`~sj300_async.InverterStatus` and
:class:`~sj300_async.MonitorData`.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..sj300._payloads import InverterStatus, MonitorData
from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus
from ._output import Column, human, print_json, print_table
from ._session import run_async

__all__ = ["add_parser", "status_rows"]


def add_parser(subparsers: Any) -> None:
    """Add ``status`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "status",
        help="a drive's state and its monitor values",
        description="Read status A/B/C (command 04) and the monitor block (command 03).",
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
        drive = bus.drive(args.node)
        status = await drive.read_status()
        monitor = await drive.read_monitor()
    if args.json:
        print_json({"node": args.node, "status": status, "monitor": monitor})
    else:
        print_table(
            (Column("item"), Column("value")),
            status_rows(status, monitor),
            title=f"node {args.node:02d}",
            show_header=False,
        )
    return 0


def status_rows(status: InverterStatus, monitor: MonitorData) -> list[tuple[str, str]]:
    """The status and monitor values as (label, value-with-unit) rows."""
    m = monitor
    return [
        ("state (A)", human(status.a)),
        ("run (B)", human(status.b)),
        ("output (C)", human(status.c)),
        ("output frequency", f"{m.output_frequency_hz:.2f} Hz"),
        ("direction", human(m.direction)),
        ("output current", f"{m.output_current_a:.1f} A"),
        ("output voltage", f"{m.output_voltage_v:.1f} V"),
        ("output torque", f"{m.output_torque_percent} %"),
        ("power", f"{m.power_kw:.1f} kW"),
        ("PID feedback", f"{m.pid_feedback_percent:.2f} %"),
        ("frequency conversion", f"{m.frequency_conversion:.2f}"),
        ("input terminals", human(m.input_terminals)),
        ("output terminals", human(m.output_terminals)),
        ("run time", f"{m.run_time_h} h"),
        ("power-on time", f"{m.power_on_time_h} h"),
    ]
