"""What every benchmark shares: run settings, timing, results and the markdown table.

A benchmark module exposes ``TITLE`` and ``run(config) -> Section``. It times
our code and the peer in the same process and the same run, interleaved, so
that drift of the machine (turbo, other load) hits both alike; the ratio is
what the project tracks, the absolute numbers only describe this machine.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

__all__ = [
    "DEFAULT_SEED",
    "Config",
    "Result",
    "Section",
    "compare",
    "format_number",
    "markdown_table",
]


#: Seed of every random input unless ``--seed`` says otherwise.
DEFAULT_SEED = 300


@dataclass(frozen=True, slots=True)
class Config:
    """Settings of one ``python -m benchmarks`` run."""

    #: Small sizes and few repeats: proves the benchmarks work, measures nothing.
    quick: bool = False
    #: Timed runs per side; the fastest counts (after one untimed warm-up run).
    repeats: int = 5
    #: Seed of every random choice, so that two runs measure the same input.
    seed: int = DEFAULT_SEED


@dataclass(frozen=True, slots=True)
class Result:
    """One row of the table: a measurement of ours against the same one of the peer."""

    name: str
    ours: float
    peer: float
    unit: str
    #: The ratio (see :attr:`ratio`) the project aims for, or None for information only.
    target: float | None = None
    #: False for times and sizes, where less is better; the ratio is then peer / ours.
    higher_is_better: bool = True

    @property
    def ratio(self) -> float:
        """How many times better ours is: > 1 means ours wins, whatever the unit."""
        if self.higher_is_better:
            return self.ours / self.peer
        return self.peer / self.ours

    @property
    def met(self) -> bool | None:
        """Whether the target is met, or None when there is no target."""
        return None if self.target is None else self.ratio >= self.target


@dataclass(frozen=True, slots=True)
class Section:
    """What one benchmark module reports: notes printed above the table, and its rows."""

    title: str
    #: Markdown lines describing the input (composition, sizes, how the peer was matched).
    notes: tuple[str, ...] = ()
    results: tuple[Result, ...] = field(default=())


def _time_once(fn: Callable[[], object]) -> float:
    # Collect first so that one side does not pay for the garbage of the other;
    # the collector stays on during the run, as it is in a real program.
    gc.collect()
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def compare(
    ours: Callable[[], object], peer: Callable[[], object], repeats: int
) -> tuple[float, float]:
    """Time both callables, interleaved; return the best wall time of each, in seconds.

    Each side runs once untimed (imports, caches, enum pseudo-members), then
    ``repeats`` times alternating ours / peer. The minimum is the estimate
    least disturbed by the rest of the machine.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    ours()
    peer()
    best_ours = best_peer = float("inf")
    for _ in range(repeats):
        best_ours = min(best_ours, _time_once(ours))
        best_peer = min(best_peer, _time_once(peer))
    return best_ours, best_peer


def format_number(value: float) -> str:
    """Thousands separators for large values, three significant digits for small ones."""
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.3g}"


def markdown_table(results: Sequence[Result], peer_name: str) -> str:
    """Render the results as one markdown table."""
    lines = [
        f"| benchmark | ours | {peer_name} | unit | ours vs peer | target | met |",
        "|---|---:|---:|---|---:|---:|:---:|",
    ]
    for r in results:
        target = "—" if r.target is None else f">= {r.target:g}x"
        met = {None: "—", True: "yes", False: "**no**"}[r.met]
        lines.append(
            f"| {r.name} | {format_number(r.ours)} | {format_number(r.peer)} | {r.unit} "
            f"| {r.ratio:.2f}x | {target} | {met} |"
        )
    return "\n".join(lines)
