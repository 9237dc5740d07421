"""``sj300 write CODE VALUE``: write a parameter, read it back, print both.

VALUE is in the catalogue's engineering unit (``write F002 12.5`` for 12.50
s), or the raw integer with ``--raw``; a code the protocol addresses that
the catalogue does not describe (an FR-700's Pr.13) takes only ``--raw``,
its unit and increment being unknown. It is checked against the protocol's
catalogue (range and resolution) before anything is sent. An SJ300 writes
RAM (command 07): ``--store`` also stores every setting to EEPROM (command
0A), which a power cycle otherwise forgets; a protocol whose drives have no
such separate store refuses ``--store``.

JSON: ``{"node": 1, "code": "F002", "name": ..., "unit": "s", "old_value":
30.0, "old_raw": 3000, "value": 12.5, "raw": 1250, "stored": false}``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..profiles import ParameterSpec
from ..wire import NakError
from ._common import add_bus_options, add_json_option, add_node_option, cli_profile, open_cli_bus
from ._errors import FAILURE, CliError
from ._output import print_json
from ._read import NOT_CATALOGUED, parameter_target, read_raw, shown
from ._session import run_async

__all__ = ["add_parser", "write_raw"]


def add_parser(subparsers: Any) -> None:
    """Add ``write`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "write",
        help="write a parameter and read it back",
        description="Write a parameter and read it back (SJ300: commands 07 and 06; FR-700: "
        "the parameter's write and read instruction codes).",
    )
    p.add_argument("code", metavar="CODE", help="e.g. F002 (FR-700: Pr.7)")
    p.add_argument("value", metavar="VALUE", help="engineering value, e.g. 12.5 (--raw: integer)")
    p.add_argument("--raw", action="store_true", help="VALUE is the unscaled integer")
    p.add_argument(
        "--store",
        action="store_true",
        help="then store settings to EEPROM (SJ300 command 0A; FR-700 drives have no such "
        "separate store: refused)",
    )
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Write, verify and print; return 0."""
    return run_async(_write(args))


def _raw_value(info: ParameterSpec | None, text: str, raw: bool, raw_range: tuple[int, int]) -> int:
    """VALUE as the raw integer to send, checked before anything is sent.

    Raises:
        CliError: VALUE is not a number, or a raw value outside the wire's range.
        LocalProtocolError: out of range or finer than the parameter's resolution.
    """
    try:
        number = int(text) if raw else float(text)
    except ValueError:
        raise CliError(
            f"VALUE must be {'an integer' if raw else 'a number'}, got {text!r}"
        ) from None
    if not raw:
        assert info is not None  # _write asks an uncatalogued code for --raw first
        return info.to_raw(number)
    low, high = raw_range
    if not low <= number <= high:
        raise CliError(f"a raw value is {low}..{high}, got {text!r}")
    return int(number)


async def write_raw(drive: Any, code: str, raw: int) -> None:
    """Write *code*; a NAK names the code.

    Raises:
        CliError: the drive answered NAK (status 1).
        LocalProtocolError, ReplyTimeoutError, RemoteProtocolError, TransportError.
    """
    try:
        await drive.write_parameter_raw(code, raw)
    except NakError as exc:
        raise CliError(f"{code} = {raw}: {exc}", status=FAILURE) from None


async def _write(args: argparse.Namespace) -> int:
    profile = cli_profile(args)
    code, info = parameter_target(profile, args.code)
    if info is None and not args.raw:
        raise CliError(
            f"argument CODE: {code} is not in the {profile.model} parameter catalogue, so "
            "its unit and increment are unknown: give the raw integer with --raw"
        )
    raw = _raw_value(info, args.value, args.raw, profile.parameters.raw_range)
    async with open_cli_bus(args, needs="store" if args.store else None) as bus:
        drive = bus.drive(args.node)
        old = await read_raw(drive, code, profile)
        await write_raw(drive, code, raw)
        back = await read_raw(drive, code)
        if back != raw:
            raise CliError(f"{code}: wrote {raw}, read back {back}", status=FAILURE)
        if args.store:
            await drive.store()
    if args.json:
        print_json(
            {
                "node": args.node,
                "code": code,
                "name": None if info is None else info.name,
                "unit": None if info is None else info.unit,
                "old_value": None if info is None else info.from_raw(old),
                "old_raw": old,
                "value": None if info is None else info.from_raw(back),
                "raw": back,
                "stored": args.store,
            }
        )
    else:
        before, after = (shown(info, v, as_raw=args.raw) for v in (old, back))
        stored = " (stored)" if args.store else ""
        noun = profile.node_noun
        name = NOT_CATALOGUED if info is None else info.name
        print(f"{noun} {args.node:02d} {code} {name}: {before} -> {after}{stored}")
    return 0
