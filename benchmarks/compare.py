"""``python -m benchmarks.compare --ref REF``: the benchmarks of a commit against the working tree.

Usage::

    python -m benchmarks.compare --ref REF [--only NAME ...] [benchmark args]

Checks REF out in a temporary ``git worktree`` (detached), runs that tree's
benchmarks with that tree's code (``python -m benchmarks`` with the worktree
as the current directory and as ``PYTHONPATH``, on this same Python), then
the working tree's, and prints one row per benchmark row, matched by name,
unit and event loop: REF's value of ours, the working tree's, the unit and
the change in percent, where + is better whatever the unit (a rate that rose,
a time that fell); and, for a row with a reference measured in the same run
(pymodbus, a floor, a limit), that same-run ratio on each side and its change.
Rows more than 5 % worse are flagged: by their same-run ratio where they
have one (drift of the machine between the two runs cancels out of it), by
their value otherwise. The worktree is
removed at the end, also on error.

With ``--same-benchmarks``, REF's worktree gets the working tree's
``benchmarks/`` before it runs: both sides then run the same benchmark code
on their own library, so rows added since REF (issue 18's tcp headline, the
scale ratio) are compared too. REF's library must have what those
benchmarks use.

Any other argument (``--quick``, ``--repeats N``, ``--seed N``,
``--uvloop``, ``--wire-runs N``) goes to both runs. The rows are read from ``--json``; a
commit older than that option is read from its printed markdown table, whose
values have three significant digits (thousands are whole numbers).

The two runs are sequential, not interleaved: drift of the machine between
them shows as change. Run it on a quiet machine, and repeat a surprising row.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ._allocator import pinned_environment

__all__ = ["Row", "change_percent", "higher_is_better", "main", "parse_table"]

#: A row this much worse (in percent) than REF is flagged.
THRESHOLD_PERCENT = 5.0

_REPO = Path(__file__).resolve().parent.parent

#: Units where less is better; anything "per second" is better when higher.
_LOWER_IS_BETTER = frozenset(
    {"s", "ms", "µs", "us", "ns", "B", "bytes", "kB", "KB", "KiB", "MB", "MiB", "GB", "GiB"}
)


@dataclass(frozen=True, slots=True)
class Row:
    """One benchmark row: our value (not the reference's) and how to read it."""

    name: str
    value: float
    unit: str
    #: The event loop of its table: "asyncio" (the main table) or "uvloop".
    loop: str = "asyncio"
    #: The row's own flag, used only for a unit this script does not know.
    higher_is_better: bool | None = None
    #: The row's reference measured in the same run (pymodbus, a floor, a limit), if any.
    peer: float | None = None


def higher_is_better(row: Row) -> bool:
    """Whether more is better for this row, from its unit first (rates up, times and sizes down).

    The unit decides because the rows' own flag matters only for their ratio
    against a reference, and a row without a reference may leave it unset.
    """
    unit = row.unit.strip()
    if "/s" in unit or unit.endswith("ps"):
        return True
    if unit in _LOWER_IS_BETTER:
        return False
    return True if row.higher_is_better is None else row.higher_is_better


def change_percent(old: Row, new: Row) -> float | None:
    """The change from *old* to *new* in percent of *old*; + is better. None when *old* is 0."""
    if old.value == 0 or not (math.isfinite(old.value) and math.isfinite(new.value)):
        return 0.0 if old.value == new.value else None
    change = (new.value - old.value) / abs(old.value) * 100
    return change if higher_is_better(new) else -change


def same_run_ratio(row: Row) -> float | None:
    """How many times better than its same-run reference the row is; None without one.

    The figure the targets are set on: drift of the machine between the two
    runs moves a row's value and its reference alike, so this ratio is steadier
    than the value.
    """
    if row.peer is None or not row.peer or not row.value:
        return None
    if not (math.isfinite(row.peer) and math.isfinite(row.value)):
        return None
    return row.value / row.peer if higher_is_better(row) else row.peer / row.value


def _number(text: str) -> float | None:
    text = text.strip().replace(",", "")
    if text in ("—", "-", ""):
        return None
    if text == "∞":
        return math.inf
    try:
        return float(text)
    except ValueError:
        return None


def parse_table(output: str) -> list[Row]:
    """The rows of the printed results tables (``| name | ours | reference | unit | ...``).

    The table under ``## results`` is asyncio's; the one under ``## results on
    uvloop`` is uvloop's. Rows whose value does not parse are skipped.
    """
    rows: list[Row] = []
    loop: str | None = None
    for line in output.splitlines():
        if line.startswith("## "):
            heading = line[3:].strip()
            if heading == "results":
                loop = "asyncio"
            elif heading.startswith("results on uvloop"):
                loop = "uvloop"
            else:
                loop = None
            continue
        if loop is None or not line.startswith("|"):
            continue
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) < 4 or cells[0] == "benchmark" or set(cells[0]) <= set("-:"):
            continue
        value = _number(cells[1])
        if value is not None:
            rows.append(Row(cells[0], value, cells[3], loop, peer=_number(cells[2])))
    return rows


def _read_json(path: Path) -> list[Row]:
    return [
        Row(
            item["name"],
            float(item["ours"]),
            item["unit"],
            item.get("loop", "asyncio"),
            item.get("higher_is_better"),
            None if item.get("peer") is None else float(item["peer"]),
        )
        for item in json.loads(path.read_text(encoding="utf-8"))
    ]


def _git(*args: str, cwd: Path = _REPO) -> str:
    done = subprocess.run(
        ["git", *args], cwd=cwd, check=True, capture_output=True, text=True, encoding="utf-8"
    )
    return done.stdout.strip()


def _env(tree: Path) -> dict[str, str]:
    # Both trees run with the allocator pinned (._allocator), a commit from before
    # the pin included: the same malloc behaviour on both sides.
    env = pinned_environment()
    env["PYTHONPATH"] = str(tree)
    return env


def _check_imports_from(tree: Path) -> None:
    """Fail unless ``sj300_async`` and ``benchmarks`` import from *tree* (not an installed copy)."""
    code = "import sj300_async, benchmarks; print(sj300_async.__file__); print(benchmarks.__file__)"
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tree,
        env=_env(tree),
        check=True,
        capture_output=True,
        text=True,
        encoding="utf-8",
    )
    for path in done.stdout.split():
        if not Path(path).resolve().is_relative_to(tree.resolve()):
            raise RuntimeError(f"{tree}: imports {path} from outside the tree")


def _run(tree: Path, label: str, args: Sequence[str], json_path: Path) -> tuple[list[Row], bool]:
    """Run *tree*'s benchmarks with *tree*'s code; return its rows and whether every one ran."""
    _check_imports_from(tree)
    command = [sys.executable, "-m", "benchmarks"]
    has_json = (
        "--json"
        in subprocess.run(
            [*command, "--help"],
            cwd=tree,
            env=_env(tree),
            capture_output=True,
            text=True,
            encoding="utf-8",
        ).stdout
    )
    if has_json:
        command += ["--json", str(json_path)]
    command += args
    print(f"running the benchmarks of {label} ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    done = subprocess.run(
        command, cwd=tree, env=_env(tree), capture_output=True, text=True, encoding="utf-8"
    )
    print(f"  {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    if done.returncode != 0:
        print(f"{label}: python -m benchmarks exited with {done.returncode}:", file=sys.stderr)
        print(done.stdout[-4000:] + done.stderr[-4000:], file=sys.stderr)
    if has_json and json_path.exists():
        return _read_json(json_path), done.returncode == 0
    return parse_table(done.stdout), done.returncode == 0


def _key(rows: Sequence[Row]) -> dict[tuple[str, str, str, int], Row]:
    """Rows by (loop, name, unit, occurrence): the same name may repeat, in another unit."""
    keyed: dict[tuple[str, str, str, int], Row] = {}
    for row in rows:
        n = 0
        while (row.loop, row.name, row.unit, n) in keyed:
            n += 1
        keyed[(row.loop, row.name, row.unit, n)] = row
    return keyed


def _format(value: float) -> str:
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.3g}"


def render(old: Sequence[Row], new: Sequence[Row], ref_label: str) -> tuple[str, int]:
    """The side-by-side table, and how many rows are more than the threshold worse."""
    old_keyed, new_keyed = _key(old), _key(new)
    keys = list(new_keyed) + [key for key in old_keyed if key not in new_keyed]
    lines = [
        f"| benchmark | {ref_label} | working tree | unit | change "
        "| same-run ratio, REF | working tree | ratio change | |",
        "|---|---:|---:|---|---:|---:|---:|---:|---|",
    ]
    worse = 0
    for key in keys:
        loop, name, unit, _ = key
        shown = name if loop == "asyncio" else f"{name} ({loop})"
        before, after = old_keyed.get(key), new_keyed.get(key)
        flag = ""
        ratios = ["—", "—"]
        ratio_change = "—"
        if before is None or after is None:
            change = "—"
            flag = "only in the working tree" if before is None else f"only in {ref_label}"
        else:
            percent = change_percent(before, after)
            change = "—" if percent is None else f"{percent:+.1f} %"
            old_ratio, new_ratio = same_run_ratio(before), same_run_ratio(after)
            ratios = [_format_ratio(old_ratio), _format_ratio(new_ratio)]
            if old_ratio is not None and new_ratio is not None:
                # The ratio decides where there is one: it is what the targets are set on.
                percent = (new_ratio - old_ratio) / old_ratio * 100
                ratio_change = f"{percent:+.1f} %"
            if percent is not None and percent < -THRESHOLD_PERCENT:
                flag = f"**worse by more than {THRESHOLD_PERCENT:g} %**"
                worse += 1
        lines.append(
            f"| {shown} | {'—' if before is None else _format(before.value)} "
            f"| {'—' if after is None else _format(after.value)} | {unit} | {change} "
            f"| {ratios[0]} | {ratios[1]} | {ratio_change} | {flag} |"
        )
    return "\n".join(lines), worse


def _format_ratio(ratio: float | None) -> str:
    return "—" if ratio is None else f"{ratio:.3g}x"


def _parse_args(argv: Sequence[str] | None) -> tuple[argparse.Namespace, list[str]]:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.compare",
        description="Run the benchmarks of a commit and of the working tree; print both.",
        epilog="Other arguments (--quick, --repeats N, --seed N, --uvloop) go to both runs.",
    )
    parser.add_argument("--ref", required=True, help="the commit to compare with (any git ref)")
    parser.add_argument(
        "--only", action="append", default=[], metavar="NAME", help="run only this one (repeatable)"
    )
    parser.add_argument(
        "--same-benchmarks",
        action="store_true",
        help="run the working tree's benchmarks/ on REF's library too (rows added since REF)",
    )
    return parser.parse_known_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Compare; return 0, 1 when a run failed (the rows it printed are still compared), 2 on
    a bad ref."""
    args, rest = _parse_args(argv)
    bench_args = [arg for name in args.only for arg in ("--only", name)] + rest
    try:
        commit = _git("rev-parse", "--verify", "--quiet", f"{args.ref}^{{commit}}")
    except subprocess.CalledProcessError:
        print(f"python -m benchmarks.compare: no commit called {args.ref!r}", file=sys.stderr)
        return 2
    ref_label = f"{args.ref} ({commit[:10]})" if not commit.startswith(args.ref) else commit[:10]
    # SIGTERM unwinds like Ctrl-C, so that the worktree is removed either way.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    scratch = Path(tempfile.mkdtemp(prefix="sj300-bench-compare-"))
    worktree = scratch / "ref"
    try:
        _git("worktree", "add", "--detach", str(worktree), commit)
        if args.same_benchmarks:
            shutil.rmtree(worktree / "benchmarks", ignore_errors=True)
            shutil.copytree(
                _REPO / "benchmarks",
                worktree / "benchmarks",
                ignore=shutil.ignore_patterns("__pycache__"),
            )
            ref_label += " + working tree's benchmarks"
        old, old_ok = _run(worktree, ref_label, bench_args, scratch / "ref.json")
        new, new_ok = _run(_REPO, "the working tree", bench_args, scratch / "working.json")
    finally:
        if worktree.exists():
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(worktree)],
                cwd=_REPO,
                check=False,
                capture_output=True,
            )
        shutil.rmtree(scratch, ignore_errors=True)
        subprocess.run(["git", "worktree", "prune"], cwd=_REPO, check=False, capture_output=True)

    table, worse = render(old, new, ref_label)
    print(f"# benchmarks: {ref_label} against the working tree")
    print()
    print(
        "Our value of each row (not the reference's); change: + is better, whatever the unit. "
        "Same-run ratio: times better than the row's reference in the same run (the flag "
        "follows it where there is one)."
    )
    print()
    print(table)
    print()
    print(f"{worse} of {len(new)} rows more than {THRESHOLD_PERCENT:g} % worse than {ref_label}.")
    if not (old_ok and new_ok):
        failed = [
            label for label, ok in ((ref_label, old_ok), ("the working tree", new_ok)) if not ok
        ]
        print(f"Not every benchmark ran in {' and '.join(failed)}: see the output above.")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
