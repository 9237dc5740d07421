"""``sj300 params backup|restore|diff FILE``: a drive's parameters to and from a JSON snapshot.

For the protocols whose profile has a parameter backup format (the
``parameter_backup`` capability: SJ300); the others are refused with one
line before anything is opened. Codes, names, units, the absent-code NAK
and the communication settings below come from the protocol's profile.

- ``backup FILE`` reads every parameter of the catalogue (SJ300: the
  function-code table, 335 codes; or ``--codes``) and saves
  each one's code, name, unit, value in its unit and raw value, with the
  node, the protocol, the time (UTC) and the library version (format:
  :mod:`._snapshot`). A code the drive answers NAK 16 for is recorded as
  absent with the reason, not an error: drives differ by firmware. A
  progress bar shows on a terminal. FILE's directory must exist (checked
  before anything is sent: one line, exit 2, as for a missing file).
- ``restore FILE`` refuses a file taken from another node than the target
  (``-n``) unless ``--force``, and a file of another protocol always (an
  FR-700 file's codes are not SJ300 parameters; ``--force`` cannot make
  them so). It then writes every raw value with command 07 (exact: raw,
  not the value in its unit), then reads each back and compares. Any
  mismatch is listed and the exit status is 1. A write refused with a NAK
  is tried again after the others, since drives check some values against
  others (a base frequency above the maximum frequency is refused until
  the maximum is written). ``--store`` stores to EEPROM at the end if
  everything matched. Absent codes are not written. Ctrl-C stops it with
  exit status 130, as every command, and one line on stderr saying how far
  it got: ``interrupted after 112 of 330 parameters written; the drive
  holds a mix of the file's values and its own`` (while verifying or
  storing, what was done and what was not).
- ``diff FILE`` compares the file with the drive code by code (the file's
  codes, absent ones included), showing values in their units: exit 0 when
  equal, 1 when different, 2 on trouble (diff(1)'s convention). Comparing
  with another node is allowed (nothing is written).

Communication settings are not restored: C072 (node address) never, the
line settings C071 (speed), C073 (data bits), C074 (parity) and C075 (stop
bits) only with ``--include-comm``. Writing them changes how the drive
talks: a different value cuts the drive off the line the tool is talking
on, and C072 from another drive's backup would re-address this one. Use
``sj300 write C072 N`` to re-address a drive on purpose.

``--node`` defaults to 1 for a backup and to the file's node for restore
and diff.

FR-700 buses (``--protocol fr700``, ``protocol=fr700`` in the URL) are
refused with one line, exit 2: a decision, not an oversight. The FR-700
catalogue names only the parameters the library models: a backup of a few
dozen of several hundred parameters would pass for a whole one. The file's
``protocol`` field keeps one protocol's file from ever being restored onto
another's drive.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from ..profiles import Profile
from ..wire import NakError
from ._common import (
    DEFAULT_URL,
    add_bus_options,
    add_json_option,
    add_node_option,
    bus_url,
    cli_profile,
    open_cli_bus,
)
from ._errors import FAILURE, USAGE, CliError
from ._output import Column, format_raw, print_json, print_table
from ._progress import progress
from ._read import parameter_spec
from ._session import run_async
from ._snapshot import Snapshot, utc_now

__all__ = ["add_parser"]


def _code_list(text: str) -> list[str]:
    return [code for code in text.replace(" ", "").split(",") if code]


def add_parser(subparsers: Any) -> None:
    """Add ``params`` and its actions to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "params",
        help="back up, restore or compare a drive's parameters",
        description="Back up, restore or compare a drive's parameters as a JSON file.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)

    backup = actions.add_parser(
        "backup",
        help="save the drive's parameters to FILE",
        description="Read every parameter of the catalogue (SJ300: the function-code table; or "
        "--codes) and "
        "save each one's code, name, unit, value and raw value as JSON, with the node, the "
        "protocol and the time. Codes the drive does not have (NAK 16) are recorded as absent.",
    )
    backup.add_argument(
        "--codes",
        type=_code_list,
        metavar="LIST",
        help="only these codes, e.g. F002,F003,A004 (default: the whole catalogue)",
    )
    restore = actions.add_parser(
        "restore",
        help="write FILE's parameters and verify them",
        description="Write FILE's values (raw, command 07), read each back and compare; exit 1 "
        "on any mismatch. A file from another node is refused unless --force, one of another "
        "protocol always. C072 (node address) is never written, the line settings C071 and "
        "C073-C075 only with --include-comm: a new value there cuts the drive off this line.",
    )
    restore.add_argument(
        "--force",
        action="store_true",
        help="restore a file taken from another node than -n names",
    )
    restore.add_argument(
        "--include-comm",
        action="store_true",
        help="also restore the line settings C071, C073-C075 (may cut the link)",
    )
    restore.add_argument("--store", action="store_true", help="store to EEPROM if all match")
    diff = actions.add_parser(
        "diff",
        help="compare FILE with the drive (exit 1 when different)",
        description="Compare FILE with the drive. Exit 0 when equal, 1 when different, "
        "2 on trouble, as diff(1).",
    )
    steps = (("backup", backup, _backup), ("restore", restore, _restore), ("diff", diff, _diff))
    for name, action, step in steps:
        action.add_argument("file", type=Path, metavar="FILE", help="the JSON snapshot")
        add_node_option(action, default=1 if name == "backup" else None)
        add_json_option(action)
        add_bus_options(action)
        action.set_defaults(run=_runner(step), command_name=f"params {name}")
    diff.set_defaults(failure_status=USAGE)


def _runner(
    step: Callable[[argparse.Namespace], Coroutine[Any, Any, int]],
) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        return run_async(step(args))

    return run


def _absent_reason(exc: NakError) -> str:
    description = getattr(exc.code, "description", None) or "no description"
    return f"NAK {int(exc.code):02d} ({description})"


async def _read_or_absent(profile: Profile, drive: Any, code: str) -> int | str:
    """The raw value of *code*, or why it is absent (SJ300 NAK 16: the drive does not have it)."""
    try:
        return int(await drive.read_parameter_raw(code))
    except NakError as exc:
        if profile.absent(int(exc.code)):
            return _absent_reason(exc)
        raise CliError(f"{code}: {exc}", status=FAILURE) from None


async def _read_all(
    profile: Profile,
    drive: Any,
    codes: list[str],
    what: str,
    into: dict[str, int | str] | None = None,
) -> dict[str, int | str]:
    """Each code's raw value, or the reason it is absent, with a progress bar on a terminal.

    Each goes into *into* (or a new dict) as it is read, so a caller sees how far it got
    if it is interrupted; that dict is returned.
    """
    into = {} if into is None else into
    with progress(what, len(codes)) as advance:
        for code in codes:
            into[code] = await _read_or_absent(profile, drive, code)
            advance(code)
    return into


def _raw_or_none(value: int | str) -> int | None:
    return value if isinstance(value, int) else None


# -- backup ---------------------------------------------------------------------


def _check_destination(file: Path) -> None:
    """Refuse (exit 2, nothing sent) a backup file whose directory is missing or unwritable."""
    directory = file.parent
    if not directory.is_dir():
        what = "Not a directory" if directory.exists() else "No such file or directory"
        raise CliError(f"{directory}: {what}")
    if file.is_dir():
        raise CliError(f"{file}: Is a directory")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise CliError(f"{directory}: Permission denied")


def _profile(args: argparse.Namespace) -> Profile:
    """The drives' protocol's profile; one without a backup format refused (exit 2)."""
    profile = cli_profile(args)
    if not profile.capabilities.parameter_backup:
        raise CliError(
            f"{args.command_name} needs a parameter backup format, which {profile.model} "
            f"drives (protocol {profile.name}) do not have here"
        )
    return profile


async def _backup(args: argparse.Namespace) -> int:
    profile = _profile(args)
    _check_destination(args.file)
    given = [parameter_spec(profile, code, argument="--codes").code for code in args.codes or ()]
    codes: list[str] = list(dict.fromkeys(given or profile.parameters.codes()))
    taken_at = utc_now()
    async with open_cli_bus(args, needs="parameter_backup") as bus:
        values = await _read_all(profile, bus.drive(args.node), codes, "reading")
    snapshot = Snapshot(
        node=args.node,
        url=bus_url(args) or DEFAULT_URL,
        parameters={code: raw for code, raw in values.items() if isinstance(raw, int)},
        absent={code: why for code, why in values.items() if isinstance(why, str)},
        taken_at=taken_at,
        protocol=profile.name,
    )
    snapshot.save(args.file, profile)
    if args.json:
        print_json(
            {
                "node": args.node,
                "file": str(args.file),
                "parameters": len(snapshot.parameters),
                "absent": list(snapshot.absent),
            }
        )
    else:
        absent = f"; absent: {', '.join(snapshot.absent)}" if snapshot.absent else ""
        print(
            f"{profile.node_noun} {args.node:02d}: {len(snapshot.parameters)} parameters "
            f"saved to {args.file}{absent}"
        )
    return 0


# -- restore --------------------------------------------------------------------


@dataclass
class _Restored:
    """How far a restore got: what the line on stderr says when Ctrl-C stops it."""

    total: int
    phase: Literal["writing", "verifying", "storing"] = "writing"
    written: list[str] = field(default_factory=list)
    verified: dict[str, int | str] = field(default_factory=dict)  # code -> raw read back

    def interrupted(self) -> str:
        """Where it stopped, and what the drive holds."""
        if self.phase == "writing":
            return (
                f"interrupted after {len(self.written)} of {self.total} parameters written; "
                "the drive holds a mix of the file's values and its own"
            )
        if self.phase == "verifying":
            return (
                f"interrupted while verifying, after {len(self.verified)} of {self.total} "
                f"parameters read back ({len(self.written)} written): params diff checks them"
            )
        return (
            f"interrupted while storing to EEPROM: the {self.total} parameters were written "
            "and verified, whether they were stored is unknown (--store again)"
        )


async def _write_all(drive: Any, values: dict[str, int], restored: _Restored) -> dict[str, str]:
    """Write *values*; retry NAK'd ones while a pass makes progress. Returns code -> last error.

    Each code goes into ``restored.written`` as it is written.
    """
    pending = list(values)
    errors: dict[str, str] = {}
    with progress("writing", len(pending)) as advance:
        while pending:
            errors = {}
            for code in pending:
                try:
                    await drive.write_parameter_raw(code, values[code])
                except NakError as exc:
                    errors[code] = str(exc)
                    continue
                restored.written.append(code)
                advance(code)
            if len(errors) == len(pending):  # no progress: the rest stays refused
                break
            pending = list(errors)
    return errors


async def _restore(args: argparse.Namespace) -> int:
    profile = _profile(args)
    snapshot = Snapshot.load(args.file, profile)
    node: int = args.node if args.node is not None else snapshot.node
    noun = profile.node_noun
    if node != snapshot.node and not args.force:
        raise CliError(
            f"{args.file} was taken from {noun} {snapshot.node:02d}, not {noun} {node:02d}: "
            "--force restores it there"
        )
    address = () if profile.address_parameter is None else (profile.address_parameter,)
    skipped = sorted([*address, *(() if args.include_comm else profile.line_parameters)])
    values = {c: raw for c, raw in snapshot.parameters.items() if c not in skipped}
    args.node = node  # for the range check
    restored = _Restored(len(values))
    try:
        async with open_cli_bus(args, needs="parameter_backup") as bus:
            drive = bus.drive(node)
            errors = await _write_all(drive, values, restored)
            restored.phase = "verifying"
            read = await _read_all(profile, drive, list(values), "verifying", restored.verified)
            back = {c: _raw_or_none(v) for c, v in read.items()}
            mismatches = [code for code, raw in values.items() if back[code] != raw]
            stored = bool(args.store and not mismatches)
            if stored:
                restored.phase = "storing"
                await drive.store()
    except (asyncio.CancelledError, KeyboardInterrupt):  # Ctrl-C: say how far, exit 130
        print(f"sj300 {args.command_name}: {restored.interrupted()}", file=sys.stderr, flush=True)
        raise
    skipped = [c for c in skipped if c in snapshot.parameters]
    if args.json:
        print_json(
            {
                "node": node,
                "file": str(args.file),
                "written": [c for c in values if c not in errors],
                "skipped": skipped,
                "mismatches": [
                    {"code": c, "expected": values[c], "actual": back[c], "error": errors.get(c)}
                    for c in mismatches
                ],
                "stored": stored,
            }
        )
    else:
        if mismatches:
            rows = [
                (c, _show(profile, c, values[c]), _show(profile, c, back[c]), errors.get(c, ""))
                for c in mismatches
            ]
            columns = (Column("code"), Column("file"), Column("drive"), Column("write error"))
            print_table(columns, rows, title="not restored")
        note = f"; skipped {', '.join(skipped)}" if skipped else ""
        done = len(values) - len(mismatches)
        print(
            f"{noun} {node:02d}: {done} of {len(values)} parameters restored and verified"
            f"{' and stored' if stored else ''}{note}"
        )
    if mismatches:
        raise CliError(f"{len(mismatches)} parameter(s) do not match {args.file}", status=FAILURE)
    return 0


def _show(profile: Profile, code: str, raw: int | None) -> str:
    return "(absent)" if raw is None else format_raw(profile.parameters.spec(code), raw)


# -- diff -----------------------------------------------------------------------


async def _diff(args: argparse.Namespace) -> int:
    profile = _profile(args)
    snapshot = Snapshot.load(args.file, profile)
    node: int = args.node if args.node is not None else snapshot.node
    noun = profile.node_noun
    expected: dict[str, int | None] = dict(snapshot.parameters)
    expected.update(dict.fromkeys(snapshot.absent))
    args.node = node  # for the range check
    async with open_cli_bus(args, needs="parameter_backup") as bus:
        read = await _read_all(profile, bus.drive(node), list(expected), "reading")
    actual = {code: _raw_or_none(value) for code, value in read.items()}
    different = [code for code in expected if expected[code] != actual[code]]
    if args.json:
        print_json(
            {
                "node": node,
                "file": str(args.file),
                "equal": not different,
                "differences": [_difference(profile, c, expected[c], actual[c]) for c in different],
            }
        )
    elif different:
        rows = [
            (
                c,
                profile.parameters.spec(c).name,
                _show(profile, c, expected[c]),
                _show(profile, c, actual[c]),
            )
            for c in different
        ]
        columns = (Column("code"), Column("name"), Column("file"), Column("drive"))
        print_table(columns, rows, title=f"{noun} {node:02d} differs from {args.file}")
    else:
        print(f"{noun} {node:02d} matches {args.file} ({len(expected)} parameters)")
    return 1 if different else 0


def _difference(
    profile: Profile, code: str, file_raw: int | None, drive_raw: int | None
) -> dict[str, Any]:
    info = profile.parameters.spec(code)
    return {
        "code": code,
        "name": info.name,
        "unit": info.unit,
        "file_raw": file_raw,
        "drive_raw": drive_raw,
        "file_value": None if file_raw is None else info.from_raw(file_raw),
        "drive_value": None if drive_raw is None else info.from_raw(drive_raw),
    }
