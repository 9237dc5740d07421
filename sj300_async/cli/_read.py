"""``sj300 read CODE...``: parameter values in engineering units (SJ300 command 06, FR-700 Pr.N).

The protocol's parameter catalogue (its profile's) gives each code its
scale and unit (SJ300: a code it does not know is read at the default
x 10); a code is checked against the protocol before anything is sent.
``--raw`` shows the unscaled integers the drive sends.

JSON: ``{"node": 1, "parameters": [{"code": "F002", "name": "acceleration
time 1", "value": 30.0, "unit": "s", "raw": 3000}, ...]}``, value and raw
both, whatever ``--raw`` says.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..profiles import ParameterSpec, Profile
from ..wire import LocalProtocolError, NakError
from ._common import add_bus_options, add_json_option, add_node_option, cli_profile, open_cli_bus
from ._errors import FAILURE, CliError
from ._output import Column, format_raw, print_json, print_table
from ._session import run_async

__all__ = ["add_parser", "parameter_json", "parameter_spec", "read_raw"]


def parameter_spec(profile: Profile, text: str, *, argument: str = "CODE") -> ParameterSpec:
    """The catalogue entry of the code *text* names, in the protocol's own spelling.

    Raises:
        CliError: not a parameter code of the protocol (exit 2, nothing sent).
    """
    try:
        return profile.parameters.spec(text)
    except LocalProtocolError as exc:
        raise CliError(f"argument {argument}: {exc}") from None


def add_parser(subparsers: Any) -> None:
    """Add ``read`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "read",
        help="read parameters",
        description="Read parameters (SJ300: command 06; FR-700: the parameter's read "
        "instruction code), scaled to engineering units by the protocol's catalogue.",
    )
    p.add_argument("codes", nargs="+", metavar="CODE", help="e.g. F002 A004 (FR-700: Pr.7)")
    p.add_argument("--raw", action="store_true", help="show the unscaled integers")
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the parameters; return 0."""
    return run_async(_read(args))


async def read_raw(drive: Any, code: str) -> int:
    """Read *code*; a NAK names the code.

    Raises:
        CliError: the drive answered NAK (status 1).
        ReplyTimeoutError, RemoteProtocolError, TransportError.
    """
    try:
        return int(await drive.read_parameter_raw(code))
    except NakError as exc:
        raise CliError(f"{code}: {exc}", status=FAILURE) from None


def parameter_json(info: ParameterSpec, raw: int) -> dict[str, Any]:
    """A parameter's JSON object: code, name, engineering value, unit, raw value."""
    return {
        "code": info.code,
        "name": info.name,
        "value": info.from_raw(raw),
        "unit": info.unit,
        "raw": raw,
    }


async def _read(args: argparse.Namespace) -> int:
    values: list[tuple[ParameterSpec, int]] = []
    profile = cli_profile(args)
    specs = [parameter_spec(profile, text) for text in args.codes]  # all, before anything
    async with open_cli_bus(args) as bus:
        drive = bus.drive(args.node)
        for info in specs:
            values.append((info, await read_raw(drive, info.code)))
    if args.json:
        params = [parameter_json(info, raw) for info, raw in values]
        print_json({"node": args.node, "parameters": params})
        return 0
    rows = []
    for info, raw in values:
        rows.append((info.code, info.name, str(raw) if args.raw else format_raw(info, raw)))
    print_table((Column("code"), Column("name"), Column("value", "right")), rows)
    return 0
