"""``sj300 read CODE...``: parameter values in engineering units (command 06).

The catalogue (:data:`sj300_async.PARAMETERS`) gives each code its scale
and unit; a code it does not know is read at the SJ300's default x 10.
``--raw`` shows the unscaled integers the drive sends.

JSON: ``{"node": 1, "parameters": [{"code": "F002", "name": "acceleration
time 1", "value": 30.0, "unit": "s", "raw": 3000}, ...]}``, value and raw
both, whatever ``--raw`` says.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..sj300._drive import Drive
from ..sj300._parameters import normalize_code, parameter_info
from ..wire._errors import NakError
from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus
from ._errors import FAILURE, CliError
from ._output import Column, format_raw, print_json, print_table
from ._session import run_async

__all__ = ["add_parser", "parameter_code", "parameter_json", "read_raw"]


def parameter_code(text: str) -> str:
    """argparse type: a parameter code, upper-cased (``b084`` -> ``B084``)."""
    try:
        return normalize_code(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_parser(subparsers: Any) -> None:
    """Add ``read`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "read",
        help="read parameters",
        description="Read parameters (command 06), scaled to engineering units by the catalogue.",
    )
    p.add_argument("codes", nargs="+", type=parameter_code, metavar="CODE", help="e.g. F002 A004")
    p.add_argument("--raw", action="store_true", help="show the unscaled integers")
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the parameters; return 0."""
    return run_async(_read(args))


async def read_raw(drive: Drive, code: str) -> int:
    """Read *code*; a NAK names the code.

    Raises:
        CliError: the drive answered NAK (status 1).
        ReplyTimeoutError, RemoteProtocolError, TransportError.
    """
    try:
        return await drive.read_parameter_raw(code)
    except NakError as exc:
        raise CliError(f"{code}: {exc}", status=FAILURE) from None


def parameter_json(code: str, raw: int) -> dict[str, Any]:
    """A parameter's JSON object: code, name, engineering value, unit, raw value."""
    info = parameter_info(code)
    return {
        "code": code,
        "name": info.name,
        "value": info.from_raw(raw),
        "unit": info.unit,
        "raw": raw,
    }


async def _read(args: argparse.Namespace) -> int:
    values: dict[str, int] = {}
    async with open_cli_bus(args) as bus:
        drive = bus.drive(args.node)
        for code in args.codes:
            values[code] = await read_raw(drive, code)
    if args.json:
        params = [parameter_json(code, raw) for code, raw in values.items()]
        print_json({"node": args.node, "parameters": params})
        return 0
    rows = []
    for code, raw in values.items():
        info = parameter_info(code)
        rows.append((code, info.name, str(raw) if args.raw else format_raw(info, raw)))
    print_table((Column("code"), Column("name"), Column("value", "right")), rows)
    return 0
