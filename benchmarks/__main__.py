"""``python -m benchmarks``: run the benchmarks and print the notes and one markdown table.

With ``--uvloop``, the benchmarks that run an event loop run once more on
uvloop and get a table of their own: the targets hold on asyncio's default
loop, uvloop is an optional speed-up.

With ``--json PATH``, the rows are also written to PATH as a JSON list, one
object per row (the fields of :class:`~benchmarks._harness.Result` and the
``loop`` it ran on), for ``python -m benchmarks.compare``.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import os
import platform
import sys
import time
from collections.abc import Sequence
from importlib.metadata import version

from . import BENCHMARKS, load
from ._allocator import allocator_note, pin_or_reexec
from ._harness import DEFAULT_SEED, Config, Result, markdown_table


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks", description="Benchmark sj300_async against pymodbus."
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="tiny sizes, 2 repeats: proves it runs, measures nothing",
    )
    parser.add_argument(
        "--only",
        action="append",
        choices=list(BENCHMARKS),
        metavar="NAME",
        help=f"run only this one (repeatable): {', '.join(BENCHMARKS)}",
    )
    parser.add_argument(
        "--uvloop",
        action="store_true",
        help="also run the event-loop benchmarks on uvloop, in a table of their own",
    )
    parser.add_argument("--repeats", type=int, help="timed runs per side (default 5, quick 2)")
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED, help="seed of every random input")
    parser.add_argument(
        "--wire-runs",
        type=int,
        default=1,
        metavar="N",
        help="run the wire benchmark N times and report how many runs met the target",
    )
    parser.add_argument("--json", metavar="PATH", help="also write the rows to PATH as JSON")
    args = parser.parse_args(argv)
    if args.wire_runs < 1:
        parser.error("--wire-runs must be at least 1")
    if args.uvloop and importlib.util.find_spec("uvloop") is None:
        parser.error("--uvloop needs uvloop: pip install uvloop")
    return args


def _environment(uvloop: bool) -> str:
    lines = [
        f"- Python {platform.python_version()} ({platform.python_implementation()}), "
        f"{platform.platform()}, {platform.machine()}, {os.cpu_count()} CPUs",
        f"- sj300_async {version('sj300-async')}, pymodbus {version('pymodbus')}",
        "- event loop: asyncio's default"
        + (f"; then uvloop {version('uvloop')} in a table of its own" if uvloop else ""),
        allocator_note(),
    ]
    return "\n".join(lines)


def _run_all(names: Sequence[str], config: Config, suffix: str = "") -> tuple[list[Result], bool]:
    """Run and print each benchmark; return the rows and whether every one ran."""
    results: list[Result] = []
    ok = True
    for name in names:
        module = load(name)
        print()
        print(f"## {module.TITLE}{suffix}")
        print()
        start = time.perf_counter()
        try:
            section = module.run(config)
        except Exception as exc:  # one broken benchmark must not hide the others' results
            ok = False
            print(f"**failed**: {type(exc).__name__}: {exc}")
            continue
        print("\n".join(section.notes))
        print()
        print(f"_{time.perf_counter() - start:.1f} s_")
        results += section.results
    return results, ok


def main(argv: Sequence[str] | None = None) -> int:
    """Run the chosen benchmarks; return the exit status (1 if one of them failed)."""
    args = _parse_args(argv)
    repeats = args.repeats if args.repeats is not None else (2 if args.quick else 5)
    config = Config(quick=args.quick, repeats=repeats, seed=args.seed, wire_runs=args.wire_runs)
    names = list(dict.fromkeys(args.only)) if args.only else list(BENCHMARKS)
    peer = f"pymodbus {version('pymodbus')}"

    print(
        "# sj300_async benchmarks"
        + (" (quick: sizes too small to mean anything)" if config.quick else "")
    )
    print()
    print(_environment(args.uvloop))
    print(f"- best of {config.repeats} interleaved runs per side, after one warm-up run")
    results, ok = _run_all(names, config)
    print()
    print("## results")
    print()
    print(markdown_table(results, peer))

    uv_results: list[Result] = []
    if args.uvloop:
        on_loop = [name for name in names if load(name).USES_EVENT_LOOP]
        uv_config = dataclasses.replace(config, loop="uvloop")
        uv_results, uv_ok = _run_all(on_loop, uv_config, " (uvloop)")
        ok = ok and uv_ok
        print()
        print(f"## results on uvloop {version('uvloop')} (the targets are for the default loop)")
        print()
        print(markdown_table(uv_results, peer))
    if args.json:
        rows = [{**dataclasses.asdict(r), "loop": "asyncio"} for r in results]
        rows += [{**dataclasses.asdict(r), "loop": "uvloop"} for r in uv_results]
        with open(args.json, "w", encoding="utf-8") as file:
            json.dump(rows, file, indent=1)
    return 0 if ok else 1


if __name__ == "__main__":
    pin_or_reexec("benchmarks", sys.argv[1:])  # every process of the run allocates alike
    sys.exit(main())
