"""Tables that fit the terminal: the richest of a table's layouts whose columns fit its width.

Shared by the bus monitor's live table (:mod:`._board`) and the fleet
view's (:mod:`._fleet`). A fixed column is as wide as its widest cell or
header: numbers are never cut. The flexible ones (a state, an error, a
name) share the room the others leave, each at least its ``min_width``
(and at most its ``max_width``), and rich cuts their text with ``…``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ._output import Justify

__all__ = ["FitColumn", "fit"]


@dataclass(frozen=True, slots=True)
class FitColumn:
    """A column of a live table: its header, how it lines up, the cell it shows."""

    header: str
    #: The cell's key in a row.
    key: str
    justify: Justify = "right"
    #: Takes the room the others leave, cut with … when short (never a number column).
    flexible: bool = False
    #: A flexible column's least width (and, with ``max_width``, its most).
    min_width: int = 0
    max_width: int | None = None


def fit(
    layouts: Sequence[tuple[FitColumn, ...]], width: int, rows: Sequence[dict[str, str]]
) -> tuple[tuple[FitColumn, ...], dict[str, int]]:
    """The first of *layouts* (richest first) that fits *width* columns, else the last; and
    each of its columns' width."""
    from rich.cells import cell_len

    def natural(column: FitColumn) -> int:
        return max([cell_len(column.header), *(cell_len(row[column.key]) for row in rows)])

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
        want = min(natural(column), column.max_width or natural(column))
        widths[column.key] = max(1, min(want, left - later))
        left -= widths[column.key]
    return columns, widths
