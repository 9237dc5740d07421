"""Tables that fit the terminal: the richest of a table's layouts whose columns fit its width.

Shared by the bus monitor's live table (:mod:`._board`) and the fleet
view's (:mod:`._fleet`). A fixed column is as wide as its header, its
``width`` (what its values take: ``100.00``), or a wider cell: numbers are
never cut. The flexible ones (a state, an error, a name) share the room
the others leave, each at least its ``min_width``: one with a ``width``
wants that (its text is cut with ``…`` beyond), one without wants its
widest cell.

A table keeps its width over a run: the widths come from the columns, not
from the values shown at the moment (a drive that trips, or goes offline,
moves no column), except a name column's (a gateway's, a line's: as wide
as the longest name) and a number wider than its column's ``width``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from ._output import Justify

__all__ = ["STATE_WIDTH", "FitColumn", "clip", "fit"]

#: How wide a monitor's state column is, on a terminal and in plain lines: every state
#: in words (the longest, ``running reverse``, 15) and most trips; a longer trip
#: (``tripped E.OC1 overcurrent trip during acceleration``) is cut with ``…``.
STATE_WIDTH: Final = 32


def clip(text: str, width: int) -> str:
    """*text* cut to *width* characters, its last one ``…`` when cut."""
    return text if len(text) <= width else text[: width - 1] + "…"


@dataclass(frozen=True, slots=True)
class FitColumn:
    """A column of a live table: its header, how it lines up, the cell it shows."""

    header: str
    #: The cell's key in a row.
    key: str
    justify: Justify = "right"
    #: Takes the room the others leave, cut with … when short (never a number column).
    flexible: bool = False
    #: A flexible column's least width.
    min_width: int = 0
    #: A fixed column's least width (a wider cell widens it); the width a flexible one
    #: wants (0: its widest cell's).
    width: int = 0


def fit(
    layouts: Sequence[tuple[FitColumn, ...]], width: int, rows: Sequence[dict[str, str]]
) -> tuple[tuple[FitColumn, ...], dict[str, int]]:
    """The first of *layouts* (richest first) that fits *width* columns, else the last; and
    each of its columns' width."""
    from rich.cells import cell_len

    def natural(column: FitColumn) -> int:
        return max(
            [cell_len(column.header), column.width, *(cell_len(row[column.key]) for row in rows)]
        )

    def wanted(column: FitColumn) -> int:
        return max(cell_len(column.header), column.width) if column.width else natural(column)

    columns: tuple[FitColumn, ...] = ()
    fixed: dict[str, int] = {}
    flexible: list[FitColumn] = []
    left = 0
    for columns in layouts:
        # Per column: one space of padding each side and a divider; the edges: 1 more.
        fixed = {c.key: natural(c) for c in columns if not c.flexible}
        flexible = [c for c in columns if c.flexible]
        left = width - (3 * len(columns) + 1) - sum(fixed.values())
        if left >= sum(c.min_width for c in flexible):
            break
    widths = dict(fixed)
    for i, column in enumerate(flexible):
        later = sum(c.min_width for c in flexible[i + 1 :])
        widths[column.key] = max(1, min(wanted(column), left - later))
        left -= widths[column.key]
    return columns, widths
