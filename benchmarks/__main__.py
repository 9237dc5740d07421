"""``python -m benchmarks``: run the benchmarks and print the notes and one markdown table."""

from __future__ import annotations

import argparse
import os
import platform
import sys
from collections.abc import Sequence
from importlib.metadata import version

from . import BENCHMARKS, load
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
        choices=sorted(BENCHMARKS),
        metavar="NAME",
        help=f"one of: {', '.join(BENCHMARKS)}",
    )
    parser.add_argument("--repeats", type=int, help="timed runs per side (default 5, quick 2)")
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED, help="seed of every random input")
    return parser.parse_args(argv)


def _environment() -> str:
    return "\n".join(
        (
            f"- Python {platform.python_version()} ({platform.python_implementation()}), "
            f"{platform.platform()}, {platform.machine()}, {os.cpu_count()} CPUs",
            f"- sj300_async {version('sj300-async')}, pymodbus {version('pymodbus')}",
        )
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run the chosen benchmarks; return the exit status."""
    args = _parse_args(argv)
    repeats = args.repeats if args.repeats is not None else (2 if args.quick else 5)
    config = Config(quick=args.quick, repeats=repeats, seed=args.seed)
    names = [args.only] if args.only else list(BENCHMARKS)

    print(
        "# sj300_async benchmarks"
        + (" (quick: sizes too small to mean anything)" if config.quick else "")
    )
    print()
    print(_environment())
    print(f"- best of {config.repeats} interleaved runs per side, after one warm-up run")
    results: list[Result] = []
    for name in names:
        section = load(name).run(config)
        print()
        print(f"## {section.title}")
        print()
        print("\n".join(section.notes))
        results += section.results
    print()
    print("## results")
    print()
    print(markdown_table(results, f"pymodbus {version('pymodbus')}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
