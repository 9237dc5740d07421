"""What every benchmark shares: run settings, timing, results and the markdown table.

A benchmark module exposes ``TITLE`` and ``run(config) -> Section``. It times
our code and the peer in the same process and the same run, interleaved, so
that drift of the machine (turbo, other load) hits both alike; the ratio is
what the project tracks, the absolute numbers only describe this machine.

Not every row has a peer: a row may instead measure against a limit (the
wire time of a line), a target given as an absolute number (transactions/s)
or nothing at all (a latency percentile). :attr:`Result.against` names the
reference, and the ratio is always "how many times better than the
reference" so that one column reads the same way for every row.
"""

from __future__ import annotations

import asyncio
import gc
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

__all__ = [
    "DEFAULT_SEED",
    "Config",
    "EventLoop",
    "Result",
    "Section",
    "Timing",
    "best_time",
    "compare",
    "format_number",
    "interleave",
    "markdown_table",
    "new_runner",
]


#: Seed of every random input unless ``--seed`` says otherwise.
DEFAULT_SEED = 300

#: The event loops a benchmark can run on: asyncio's default, or uvloop (``--uvloop``).
EventLoop = Literal["asyncio", "uvloop"]


@dataclass(frozen=True, slots=True)
class Config:
    """Settings of one ``python -m benchmarks`` run."""

    #: Small sizes and few repeats: proves the benchmarks work, measures nothing.
    quick: bool = False
    #: Timed runs per side; the fastest counts (after one untimed warm-up run).
    repeats: int = 5
    #: Seed of every random choice, so that two runs measure the same input.
    seed: int = DEFAULT_SEED
    #: The event loop of the benchmarks that use one (the targets hold for "asyncio").
    loop: EventLoop = "asyncio"
    #: Whole runs of the wire benchmark, each with fresh simulator processes; with more
    #: than one it also reports how many of them met the target ("k of N runs").
    wire_runs: int = 1


@dataclass(frozen=True, slots=True)
class Result:
    """One row of the table: a measurement of ours against a reference in the same unit.

    The reference is the peer's same measurement, unless :attr:`against` names
    something else (``"target"``, ``"wire limit"``); None when there is none.
    """

    name: str
    ours: float
    #: The reference value: the peer's measurement, a limit or a target (None: none).
    peer: float | None
    unit: str
    #: The ratio (see :attr:`ratio`) the project aims for, or None for information only.
    target: float | None = None
    #: False for times and sizes, where less is better; the ratio is then peer / ours.
    higher_is_better: bool = True
    #: What the reference is, when it is not the peer: "target", "wire limit"...
    against: str | None = None
    #: Show the ratio and its target as percentages (an efficiency against a limit).
    percent: bool = False
    #: For a cost (``higher_is_better=False``): show ours ÷ reference and the target as its
    #: upper bound ("0.69x", "<= 0.7x") rather than how many times better.
    as_multiple: bool = False

    @property
    def ratio(self) -> float | None:
        """How many times better ours is: > 1 means ours wins, whatever the unit.

        None without a reference; infinite when ours is a cost of zero or less
        (no growth at all against a growth budget).
        """
        if self.peer is None:
            return None
        if self.higher_is_better:
            return self.ours / self.peer if self.peer else float("inf")
        return self.peer / self.ours if self.ours > 0 else float("inf")

    @property
    def met(self) -> bool | None:
        """Whether the target is met, or None when there is no target (or no reference)."""
        ratio = self.ratio
        return None if self.target is None or ratio is None else ratio >= self.target


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


@dataclass(frozen=True, slots=True)
class Timing:
    """The timed runs of one side (see :func:`interleave`): wall and CPU seconds of each."""

    wall_s: tuple[float, ...]
    #: ``time.process_time()`` of this process over each run (user + system, all threads).
    cpu_s: tuple[float, ...]

    @property
    def best_wall_s(self) -> float:
        """The fastest run's wall time: the estimate least disturbed by the machine."""
        return min(self.wall_s)

    @property
    def best_cpu_s(self) -> float:
        """The least CPU time a run took, by the same reasoning."""
        return min(self.cpu_s)


def interleave(sides: Sequence[Callable[[], object]], repeats: int) -> list[Timing]:
    """Time every side *repeats* times, interleaved; return each side's wall and CPU times.

    As :func:`compare` for any number of sides, with the process's CPU time of
    each run besides its wall time: each side runs once untimed, then each
    repeat runs every side once, starting one side further on each time, so
    that no side always follows the same one (or the collection before it).

    Raises:
        ValueError: *repeats* is less than 1.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    for side in sides:
        side()
    walls: list[list[float]] = [[] for _ in sides]
    cpus: list[list[float]] = [[] for _ in sides]
    for repeat in range(repeats):
        for step in range(len(sides)):
            index = (repeat + step) % len(sides)
            gc.collect()
            cpu, start = time.process_time(), time.perf_counter()
            sides[index]()
            walls[index].append(time.perf_counter() - start)
            cpus[index].append(time.process_time() - cpu)
    return [Timing(tuple(w), tuple(c)) for w, c in zip(walls, cpus, strict=True)]


def best_time(fn: Callable[[], object], repeats: int) -> float:
    """Time *fn* once untimed, then *repeats* times; return the best wall time in seconds.

    For measurements without a peer to interleave with (see :func:`compare`).
    """
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    fn()
    return min(_time_once(fn) for _ in range(repeats))


def new_runner(loop: EventLoop) -> asyncio.Runner:
    """An asyncio runner on the chosen event loop; benchmarks time ``runner.run(...)`` calls.

    One runner keeps connections open across timed runs, so that only the
    transactions are timed, not the set-up.

    Raises:
        ModuleNotFoundError: *loop* is "uvloop" and uvloop is not installed.
    """
    if loop == "uvloop":
        import uvloop  # optional: only with --uvloop

        return asyncio.Runner(loop_factory=uvloop.new_event_loop)
    return asyncio.Runner()


def format_number(value: float) -> str:
    """Thousands separators for large values, three significant digits for small ones."""
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.3g}"


def _format_ratio(r: Result) -> tuple[str, str]:
    ratio = r.ratio
    if r.percent:
        shown = "—" if ratio is None else f"{ratio * 100:.1f} %"
        return shown, "—" if r.target is None else f">= {r.target * 100:.3g} %"
    if r.as_multiple:
        shown = "—" if ratio is None else f"{1 / ratio:.2f}x" if ratio else "∞"
        return shown, "—" if r.target is None else f"<= {1 / r.target:.3g}x"
    if ratio is None:
        shown = "—"
    elif ratio == float("inf"):
        shown = "∞"
    else:
        shown = f"{ratio:.2f}x"
    return shown, "—" if r.target is None else f">= {r.target:.3g}x"


def markdown_table(results: Sequence[Result], peer_name: str) -> str:
    """Render the results as one markdown table; *peer_name* names the peer's references."""
    lines = [
        "| benchmark | ours | reference | unit | reference is | ours vs reference | target | met |",
        "|---|---:|---:|---|---|---:|---:|:---:|",
    ]
    for r in results:
        ratio, target = _format_ratio(r)
        met = {None: "—", True: "yes", False: "**no**"}[r.met]
        reference = "—" if r.peer is None else format_number(r.peer)
        against = "—" if r.peer is None else (r.against or peer_name)
        lines.append(
            f"| {r.name} | {format_number(r.ours)} | {reference} | {r.unit} | {against} "
            f"| {ratio} | {target} | {met} |"
        )
    return "\n".join(lines)
