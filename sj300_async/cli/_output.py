"""How results are printed: JSON, a rich table on a terminal, aligned plain text otherwise.

``--json`` prints one JSON document (one object per line for streams) whose
keys are the result dataclasses' field names. Values are made JSON-able one
way everywhere (:func:`jsonable`): an enumeration becomes its member's name
(``"RUNNING"``; an undocumented code ``"UNKNOWN_12"``), a bit field
(terminals, trip status B) its integer value, a nested dataclass an object.

A drive's state in words is its profile's (:mod:`sj300_async.profiles`),
never worked out here.

Tables go to stdout. On a terminal they are rich tables; otherwise (a pipe,
a file, a CI log) the same rows as space-aligned plain text without colour
or box characters, so ``grep`` and ``awk`` work on them.
"""

from __future__ import annotations

import contextvars
import dataclasses
import enum
import json
import math
import sys
from collections.abc import Mapping, Sequence
from typing import Any, Literal, TextIO

from ..profiles import ParameterSpec, words

__all__ = [
    "Column",
    "format_raw",
    "human",
    "is_terminal",
    "jsonable",
    "print_json",
    "print_table",
    "simulated_output",
]

#: True once a command runs on the simulator nobody asked for (no --url, no --sim, no
#: $SJ300_URL): :func:`print_json` then adds ``"simulated": true`` to every JSON object.
#: Set by ``open_cli_bus``; a context variable, so it ends with the command's event loop.
simulated_output: contextvars.ContextVar[bool] = contextvars.ContextVar(
    "sj300_simulated_output", default=False
)

Justify = Literal["left", "right"]


@dataclasses.dataclass(frozen=True, slots=True)
class Column:
    """A table column: its header and how its cells line up."""

    header: str
    justify: Justify = "left"


def is_terminal(stream: TextIO | None = None) -> bool:
    """True when *stream* (default stdout) is an interactive terminal."""
    stream = sys.stdout if stream is None else stream
    try:
        return stream.isatty()
    except ValueError:  # closed
        return False


def jsonable(value: Any) -> Any:
    """*value* as plain JSON data (see the module docstring for enums and flags)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, enum.Flag):
        return value.value
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, set | frozenset):  # a sample's unavailable parameters: in order
        return [jsonable(v) for v in sorted(value, key=str)]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def print_json(value: Any) -> None:
    """Print *value* as one line of JSON and flush (a reader may be waiting for it).

    An object gets ``"simulated": true`` last while :data:`simulated_output` is set.
    """
    data = jsonable(value)
    if isinstance(data, dict) and simulated_output.get():
        data["simulated"] = True
    print(json.dumps(data), flush=True)


def human(member: enum.Enum) -> str:
    """An enum member as a person reads it: ``CONSTANT_SPEED`` -> ``constant speed``.

    A bit field lists its set members' names: ``OVER_VOLTAGE|THERMAL``, ``-`` for none.
    """
    return words(member)


def format_raw(info: ParameterSpec, raw: int) -> str:
    """A raw parameter value in engineering units, at the parameter's resolution: ``30.00 s``."""
    digits = len(str(info.scale)) - 1 if str(info.scale).strip("0") == "1" else 3
    text = f"{info.from_raw(raw):.{digits}f}"
    return f"{text} {info.unit}" if info.unit else text


def print_table(
    columns: Sequence[Column],
    rows: Sequence[Sequence[str]],
    *,
    title: str | None = None,
    show_header: bool = True,
) -> None:
    """Print *rows* under *columns*: a rich table on a terminal, plain text otherwise."""
    if is_terminal():
        from rich.console import Console

        Console().print(rich_table(columns, rows, title=title, show_header=show_header))
        return
    if title:
        print(title)
    for line in plain_lines(columns, rows, show_header=show_header):
        print(line)
    sys.stdout.flush()


def rich_table(
    columns: Sequence[Column],
    rows: Sequence[Sequence[str]],
    *,
    title: str | None = None,
    show_header: bool = True,
) -> Any:
    """The rich ``Table`` of *rows* (typed Any so rich is imported only when used)."""
    from rich import box
    from rich.table import Table

    table = Table(title=title, box=box.SIMPLE_HEAD, show_header=show_header)
    for column in columns:
        table.add_column(column.header, justify=column.justify)
    for row in rows:
        table.add_row(*row)
    return table


def plain_lines(
    columns: Sequence[Column], rows: Sequence[Sequence[str]], *, show_header: bool = True
) -> list[str]:
    """*rows* as space-aligned lines (a header line first when *show_header*)."""
    all_rows = [[c.header for c in columns], *rows] if show_header else list(rows)
    widths = [max((len(r[i]) for r in all_rows), default=0) for i in range(len(columns))]
    lines = []
    for row in all_rows:
        cells = [
            cell.rjust(width) if column.justify == "right" else cell.ljust(width)
            for cell, width, column in zip(row, widths, columns, strict=True)
        ]
        lines.append("  ".join(cells).rstrip())
    return lines
