"""``sj300 read CODE...``: parameter values in engineering units (SJ300 command 06, FR-700 Pr.N).

The protocol's parameter catalogue (its profile's) gives each code its
scale and unit (SJ300: a code it does not know is read at the default
x 10); a code is checked against the protocol before anything is sent.
``--raw`` shows the unscaled integers the drive sends. A code the protocol
addresses that the catalogue does not describe (an FR-700's Pr.13: the
catalogue names the few dozen the library models, the drive has hundreds)
is read all the same, shown as its integer marked ``(raw)``: its unit and
increment are unknown (JSON: name, value and unit null).

JSON: ``{"node": 1, "parameters": [{"code": "F002", "name": "acceleration
time 1", "value": 30.0, "unit": "s", "raw": 3000}, ...]}``, value and raw
both, whatever ``--raw`` says.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..profiles import ParameterSpec, Profile, parameter_code
from ..wire import LocalProtocolError, NakError
from ._common import add_bus_options, add_json_option, add_node_option, cli_profile, open_cli_bus
from ._errors import FAILURE, CliError
from ._output import Column, format_raw, print_json, print_table
from ._session import run_async

__all__ = ["NOT_CATALOGUED", "add_parser", "parameter_json", "parameter_target", "read_raw"]

#: The name shown for a code the protocol addresses and its catalogue does not describe.
NOT_CATALOGUED = "(not in the catalogue)"


def parameter_target(
    profile: Profile, text: str, *, argument: str = "CODE"
) -> tuple[str, ParameterSpec | None]:
    """The code *text* names, in the protocol's own spelling, and its catalogue entry:
    None for a code the protocol addresses that the catalogue does not describe.

    Raises:
        CliError: not a parameter code of the protocol (exit 2, nothing sent).
    """
    try:
        info = profile.parameters.spec(text)
        return info.code, info
    except LocalProtocolError as exc:
        try:
            return parameter_code(profile, text), None
        except LocalProtocolError:
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


async def read_raw(drive: Any, code: str, profile: Profile | None = None) -> int:
    """Read *code*; a NAK names the code, and says when it means *profile*'s drive
    has no such parameter (SJ300 NAK 16, FR-700 NAK B: :meth:`Profile.absent`).

    Raises:
        CliError: the drive answered NAK (status 1).
        ReplyTimeoutError, RemoteProtocolError, TransportError.
    """
    try:
        return int(await drive.read_parameter_raw(code))
    except NakError as exc:
        absent = profile is not None and profile.absent(int(exc.code))
        why = ": the drive has no such parameter" if absent else ""
        raise CliError(f"{code}: {exc}{why}", status=FAILURE) from None


def parameter_json(code: str, info: ParameterSpec | None, raw: int) -> dict[str, Any]:
    """A parameter's JSON object: code, name, engineering value, unit, raw value
    (an uncatalogued code's name, value and unit null)."""
    return {
        "code": code,
        "name": None if info is None else info.name,
        "value": None if info is None else info.from_raw(raw),
        "unit": None if info is None else info.unit,
        "raw": raw,
    }


def shown(info: ParameterSpec | None, raw: int, *, as_raw: bool) -> str:
    """*raw* as a person reads it: in its unit, or the integer (``(raw)`` when no unit is known)."""
    if as_raw:
        return str(raw)
    return f"{raw} (raw)" if info is None else format_raw(info, raw)


async def _read(args: argparse.Namespace) -> int:
    values: list[tuple[str, ParameterSpec | None, int]] = []
    profile = cli_profile(args)
    targets = [parameter_target(profile, text) for text in args.codes]  # all, before anything
    async with open_cli_bus(args) as bus:
        drive = bus.drive(args.node)
        for code, info in targets:
            values.append((code, info, await read_raw(drive, code, profile)))
    if args.json:
        params = [parameter_json(code, info, raw) for code, info, raw in values]
        print_json({"node": args.node, "parameters": params})
        return 0
    rows = []
    for code, info, raw in values:
        name = NOT_CATALOGUED if info is None else info.name
        rows.append((code, name, shown(info, raw, as_raw=args.raw)))
    print_table((Column("code"), Column("name"), Column("value", "right")), rows)
    return 0
