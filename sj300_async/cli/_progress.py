"""Progress of a long step (a parameter backup, a restore): a bar on stderr when it is a terminal.

Off a terminal nothing is shown: stdout carries the result, and a log of
fifty lines saying "read F002" would only bury it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from ._output import is_terminal

__all__ = ["progress"]


@contextmanager
def progress(description: str, total: int) -> Iterator[Callable[[str], None]]:
    """Yield ``advance(label)``, to call after each of *total* steps."""
    if not is_terminal(sys.stderr):
        yield lambda label: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    bar = Progress(
        TextColumn(f"{description} {{task.fields[label]:<5}}"),
        BarColumn(),
        MofNCompleteColumn(),
        console=Console(stderr=True),
        transient=True,
    )
    with bar:
        task = bar.add_task(description, total=total, label="")
        yield lambda label: bar.update(task, advance=1, label=label)
