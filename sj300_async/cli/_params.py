"""``sj300 params backup|restore|diff FILE``: a drive's parameters to and from a JSON snapshot.

For the protocols whose profile has a parameter backup format (the
``parameter_backup`` capability: SJ300 and FR-700); the others are refused
with one line before anything is opened. What a backup reads, names and
leaves alone comes from the protocol's profile: the codes
(:meth:`~sj300_async.profiles.ParameterCatalogue.addressable`), names and
units, the NAK that means absent, the communication settings and the
parameters a restore never writes or writes last. No protocol is named here.

- ``backup FILE`` reads every code a drive of the protocol can have and
  saves each one's code, name, unit, value in its unit and raw value, with
  the node, the protocol, the time (UTC) and the library version (format:
  :mod:`sj300_async.profiles._backup`); ``--codes`` reads only those. SJ300: the
  function-code table, 335 codes, which names every parameter a drive can
  have. FR-700: every number the computer link addresses, Pr.0..Pr.999
  (ten banks of the link-parameter extension), not the catalogue, which
  names only the few dozen parameters the library models, of the several
  hundred a drive has: a backup of those would pass for a whole one. The
  file holds what the drive has: a catalogued parameter with its name,
  unit and value, any other as its raw integer (name, unit and value
  null). A code the drive refuses as not its own (SJ300 NAK 16, FR-700 NAK
  B: the number addresses nothing on this model) is recorded as absent
  with the reason, not an error: drives differ by model and firmware. Any
  other refusal stops the backup (exit 1). A progress bar shows on a
  terminal. FILE's directory must exist (checked before anything is sent:
  one line, exit 2, as for a missing file). Time: one read per code; an
  FR-700 backup is 1000 reads and 10 bank selections, 11 s against the
  simulator over TCP at 19200 baud 8N1 (13 s at the drives' factory 8E2,
  20 s and 25 s at 9600), and a real drive adds its data check time to
  each (up to 30 ms a parameter, the reference): under a minute. The
  file is about 165 kB.
- ``restore FILE`` refuses a file taken from another node than the target
  (``-n``) unless ``--force``, and a file of another protocol always (an
  FR-700 file's codes are not SJ300 parameters; ``--force`` cannot make
  them so). It then writes every raw value (exact: raw, not the value in
  its unit; absent codes are not written), then reads each back and
  compares. Any mismatch is listed and the exit status is 1. A write
  refused with a NAK is tried again after the others while a pass makes
  progress, since drives check some values against others (SJ300: a base
  frequency above the maximum frequency is refused until the maximum is
  written; FR-700: with Pr.77 = 1 every write but Pr.77's is refused until
  Pr.77 is written). The profile's last parameters are written after every
  other (FR-700 Pr.77: a file from a write-locked drive locks it only once
  the rest is in). ``--store`` stores to EEPROM at the end if everything
  matched, for protocols that store apart (SJ300; refused with one line
  for FR-700, whose parameter writes are not stored apart). Ctrl-C stops
  it with exit status 130, as every command, and one line on stderr saying
  how far it got: ``interrupted after 112 of 330 parameters written; the
  drive holds a mix of the file's values and its own`` (while verifying or
  storing, what was done and what was not).
- ``diff FILE`` compares the file with the drive code by code (the file's
  codes, absent ones included), showing values in their units (raw for an
  uncatalogued code): exit 0 when equal, 1 when different, 2 on trouble
  (diff(1)'s convention). Comparing with another node is allowed (nothing
  is written).

What a restore leaves alone. The address never (SJ300 C072, FR-700
Pr.117): another drive's backup would re-address this one; ``sj300 write``
re-addresses a drive on purpose. The line settings only with
``--include-comm`` (SJ300 C071, C073-C075; FR-700 Pr.118-Pr.124 of the PU
connector, Pr.332-Pr.337 and Pr.341 of the RS-485 terminals, the protocol
selection Pr.549): a different value cuts the drive off the line the tool
is talking on. The profile's kept parameters never (FR-700: the RS-485
terminals' station number Pr.331, the read-only communication error count
Pr.343, and the calibration parameters Pr.900-Pr.999, the C-codes: a
calibration is the drive's own meter and analog inputs measured, another
drive's would spoil it, and each bias/gain parameter holds two values
behind the second-parameter switch of which a backup reads one). A backup
records them all, so ``diff`` shows a changed one. FR-700 writes need the
drive in network operation mode, and some stopped (Pr.79): refused with
NAK A, listed with the hint.

``--node`` defaults to 1 for a backup and to the file's node for restore
and diff. The file's ``protocol`` field keeps one protocol's file from
ever being restored onto or compared with another's drive.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
from collections.abc import Callable, Coroutine, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

from ..profiles import BackupFormatError, Profile, catalogued, parameter_code, utc_now
from ..profiles import ParameterBackup as Snapshot
from ..wire import (
    LocalProtocolError,
    NakError,
    RemoteProtocolError,
    ReplyTimeoutError,
    TransportError,
)
from ._common import (
    DEFAULT_URL,
    NEEDS,
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
from ._session import run_async

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
        description="Read every parameter a drive of the protocol can have (SJ300: the "
        "function-code table; FR-700: every number the link addresses, Pr.0-Pr.999; or --codes) "
        "and save each one's code, name, unit, value and raw value as JSON, with the node, the "
        "protocol and the time. Codes the drive does not have (SJ300 NAK 16, FR-700 NAK B) are "
        "recorded as absent.",
    )
    backup.add_argument(
        "--codes",
        type=_code_list,
        metavar="LIST",
        help="only these codes, e.g. F002,F003,A004 or Pr.7,Pr.13 (default: every one)",
    )
    restore = actions.add_parser(
        "restore",
        help="write FILE's parameters and verify them",
        description="Write FILE's raw values, read each back and compare; exit 1 on any "
        "mismatch. A file from another node is refused unless --force, one of another protocol "
        "always. The address (SJ300 C072, FR-700 Pr.117) is never written, nor FR-700's Pr.331, "
        "Pr.343 and calibration Pr.900-Pr.999; the line settings (SJ300 C071, C073-C075; FR-700 "
        "Pr.118-Pr.124, Pr.332-Pr.337, Pr.341, Pr.549) only with --include-comm: a new value "
        "there cuts the drive off this line.",
    )
    restore.add_argument(
        "--force",
        action="store_true",
        help="restore a file taken from another node than -n names",
    )
    restore.add_argument(
        "--include-comm",
        action="store_true",
        help="also restore the line settings (may cut the link)",
    )
    restore.add_argument(
        "--store", action="store_true", help="store to EEPROM if all match (SJ300)"
    )
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


def _load(path: Path, profile: Profile) -> Snapshot:
    """The backup file *path* (its trouble as one line: :class:`CliError`)."""
    try:
        return Snapshot.load(path, profile)
    except BackupFormatError as exc:
        raise CliError(str(exc)) from None


def _absent_reason(exc: NakError) -> str:
    """What the drive said, as its protocol writes it: ``NAK 16 (...)``, ``NAK B (...)``."""
    return str(exc).partition(" answered ")[2] or f"NAK {int(exc.code):02d}"


async def _read_or_absent(profile: Profile, drive: Any, code: str) -> int | str:
    """The raw value of *code*, or why it is absent (a NAK the profile says means "not here")."""
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


def _given_code(profile: Profile, text: str) -> str:
    """A ``--codes`` entry as the protocol spells it: catalogued, or any code a backup reads."""
    try:
        return parameter_code(profile, text)
    except LocalProtocolError as exc:
        raise CliError(f"argument --codes: {exc}") from None


#: A backup's line lists the absent codes up to this many; beyond, it counts them.
_ABSENT_LISTED: Final = 10


async def _backup(args: argparse.Namespace) -> int:
    profile = _profile(args)
    _check_destination(args.file)
    given = [_given_code(profile, code) for code in args.codes or ()]
    codes: list[str] = list(dict.fromkeys(given or profile.parameters.addressable()))
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
        absent = ""
        if len(snapshot.absent) > _ABSENT_LISTED:
            absent = f"; {len(snapshot.absent)} codes absent (the drive has no such parameter)"
        elif snapshot.absent:
            absent = f"; absent: {', '.join(snapshot.absent)}"
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

    def interrupted(self, verb: str = "interrupted") -> str:
        """Where it stopped (*verb*: how), and what the drive holds."""
        if self.phase == "writing":
            return (
                f"{verb} after {len(self.written)} of {self.total} parameters written; "
                "the drive holds a mix of the file's values and its own"
            )
        if self.phase == "verifying":
            return (
                f"{verb} while verifying, after {len(self.verified)} of {self.total} "
                f"parameters read back ({len(self.written)} written): params diff checks them"
            )
        return (
            f"{verb} while storing to EEPROM: the {self.total} parameters were written "
            "and verified, whether they were stored is unknown (--store again)"
        )


async def _write_all(
    drive: Any, values: dict[str, int], restored: _Restored
) -> dict[str, NakError]:
    """Write *values* in order; retry NAK'd ones while a pass makes progress.

    Returns code -> the last refusal. Each code goes into ``restored.written``
    as it is written.
    """
    pending = list(values)
    errors: dict[str, NakError] = {}
    with progress("writing", len(pending)) as advance:
        while pending:
            errors = {}
            for code in pending:
                try:
                    await drive.write_parameter_raw(code, values[code])
                except NakError as exc:
                    errors[code] = exc
                    continue
                restored.written.append(code)
                advance(code)
            if len(errors) == len(pending):  # no progress: the rest stays refused
                break
            pending = list(errors)
    return errors


def _skipped(profile: Profile, include_comm: bool) -> set[str]:
    """The codes a restore leaves alone: the address and the kept ones, the line's unless asked."""
    address = () if profile.address_parameter is None else (profile.address_parameter,)
    line = () if include_comm else profile.line_parameters
    return {*address, *profile.kept_parameters, *line}


def _in_order(profile: Profile, codes: Iterable[str]) -> list[str]:
    """*codes* in the order a backup reads them (others last, as they came)."""
    position = {code: i for i, code in enumerate(profile.parameters.addressable())}
    return sorted(codes, key=lambda code: position.get(code, len(position)))


def _write_order(profile: Profile, values: dict[str, int]) -> dict[str, int]:
    """*values* with the profile's last parameters moved to the end, in its order."""
    last = [code for code in profile.last_parameters if code in values]
    return {c: values[c] for c in values if c not in last} | {c: values[c] for c in last}


async def _restore(args: argparse.Namespace) -> int:
    profile = _profile(args)
    if args.store and not profile.capabilities.store:
        raise CliError(
            f"{args.command_name} --store needs {NEEDS['store']}, which {profile.model} drives "
            f"(protocol {profile.name}) do not have here"
        )
    snapshot = _load(args.file, profile)
    node: int = args.node if args.node is not None else snapshot.node
    noun = profile.node_noun
    if node != snapshot.node and not args.force:
        raise CliError(
            f"{args.file} was taken from {noun} {snapshot.node:02d}, not {noun} {node:02d}: "
            "--force restores it there"
        )
    left_alone = _skipped(profile, args.include_comm)
    values = _write_order(
        profile, {c: raw for c, raw in snapshot.parameters.items() if c not in left_alone}
    )
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
    except (ReplyTimeoutError, RemoteProtocolError, TransportError) as exc:  # how far, too
        raise CliError(f"{exc}; {restored.interrupted('stopped')}", status=FAILURE) from None
    skipped = _in_order(profile, (c for c in snapshot.parameters if c in left_alone))
    said = {c: str(exc) for c, exc in errors.items()}
    if args.json:
        print_json(
            {
                "node": node,
                "file": str(args.file),
                "written": [c for c in values if c not in errors],
                "skipped": skipped,
                "mismatches": [
                    {"code": c, "expected": values[c], "actual": back[c], "error": said.get(c)}
                    for c in mismatches
                ],
                "stored": stored,
            }
        )
    else:
        if mismatches:
            rows = [
                (c, _show(profile, c, values[c]), _show(profile, c, back[c]), said.get(c, ""))
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
        refusals = {int(errors[c].code) for c in mismatches if c in errors}
        hints = [h for h in (profile.nak_hint(code, "restore") for code in refusals) if h]
        hint = f": {'; '.join(hints)}" if hints else ""
        raise CliError(
            f"{len(mismatches)} parameter(s) do not match {args.file}{hint}", status=FAILURE
        )
    return 0


def _show(profile: Profile, code: str, raw: int | None) -> str:
    """*raw* in its unit; an uncatalogued code's raw integer, marked so."""
    if raw is None:
        return "(absent)"
    info = catalogued(profile, code)
    return f"{raw} (raw)" if info is None else format_raw(info, raw)


# -- diff -----------------------------------------------------------------------


async def _diff(args: argparse.Namespace) -> int:
    profile = _profile(args)
    snapshot = _load(args.file, profile)
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
            (c, _name(profile, c), _show(profile, c, expected[c]), _show(profile, c, actual[c]))
            for c in different
        ]
        columns = (Column("code"), Column("name"), Column("file"), Column("drive"))
        print_table(columns, rows, title=f"{noun} {node:02d} differs from {args.file}")
    else:
        print(f"{noun} {node:02d} matches {args.file} ({len(expected)} parameters)")
    return 1 if different else 0


def _name(profile: Profile, code: str) -> str:
    info = catalogued(profile, code)
    return "(not in the catalogue)" if info is None else info.name


def _difference(
    profile: Profile, code: str, file_raw: int | None, drive_raw: int | None
) -> dict[str, Any]:
    """One difference as JSON; an uncatalogued code has no name, unit or value (null)."""
    info = catalogued(profile, code)
    return {
        "code": code,
        "name": None if info is None else info.name,
        "unit": None if info is None else info.unit,
        "file_raw": file_raw,
        "drive_raw": drive_raw,
        "file_value": None if file_raw is None or info is None else info.from_raw(file_raw),
        "drive_value": None if drive_raw is None or info is None else info.from_raw(drive_raw),
    }
