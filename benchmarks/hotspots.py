"""Where the time goes: cProfile over a benchmark's workload, hot spots per transaction.

``python -m benchmarks.hotspots loopback|scale|tcp [-n N] [--top K]`` runs
our side of one benchmark's workload under :mod:`cProfile` and prints two
markdown tables: the share of time by layer (library, simulator, event
loop, ...), and the top functions by their own time with their calls per
transaction. cProfile slows Python code down several times and unevenly, so
the shares are a map of where to look, not a measurement; the benchmarks
themselves run without it. A coroutine counts one call each time it is
resumed, so an ``async def`` awaited once shows 2 calls per transaction.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import cProfile
import pstats
import sys
from collections.abc import Callable, Coroutine, Sequence
from typing import Any

from sj300_async import LineSettings, open_bus

from ._servers import ServerProcess
from ._sim import instant_simulator
from .bench_scale import Size, poll

__all__ = ["WORKLOADS", "Hotspot", "layer", "main", "profile"]

# pstats: (file, line, function) -> (primitive calls, calls, own s, cumulative s, callers)
_Key = tuple[str, int, str]


def layer(path: str) -> str:
    """The layer a function's file belongs to, for the by-layer table."""
    path = path.replace("\\", "/")
    if "/sj300_async/simulator/" in path:
        return "simulator"
    if "/sj300_async/" in path:
        return "library"
    if "/anyio/" in path:
        return "anyio"
    if "/asyncio/" in path or path.endswith("selectors.py"):
        return "event loop"
    if path == "~":
        return "builtins"
    if "/benchmarks/" in path:
        return "benchmark"
    return "other"


_Run = Callable[[int], Coroutine[Any, Any, int]]


async def _loopback(n: int) -> int:
    opened = open_bus("sim://?nodes=1", simulator=instant_simulator([1]))
    async with opened as bus:
        drive = bus.drive(1)
        for _ in range(n):
            await drive.read_status()
    return n


async def _scale(n: int) -> int:
    scale = await poll(Size(buses=64, drives=32, warm_up=1, polls=n))
    return scale.polls


def _prepare_tcp(resources: contextlib.ExitStack) -> _Run:
    # The server process starts outside the profile: only the client is profiled.
    server = resources.enter_context(ServerProcess("sj300"))

    async def requests(n: int) -> int:
        url = f"tcp://127.0.0.1:{server.port}"
        async with open_bus(url, line=LineSettings(baudrate=0)) as bus:
            drive = bus.drive(1)
            for _ in range(n):
                await drive.read_status()
        return n

    return requests


#: name -> (default transactions, set-up that returns the workload to profile)
WORKLOADS: dict[str, tuple[int, Callable[[contextlib.ExitStack], _Run]]] = {
    "loopback": (20_000, lambda _resources: _loopback),
    "scale": (100_000, lambda _resources: _scale),
    "tcp": (5_000, _prepare_tcp),
}


class Hotspot:
    """One function's line in the profile."""

    def __init__(self, key: _Key, calls: int, own_s: float, cumulative_s: float) -> None:
        self.file, self.line, self.function = key
        self.calls = calls
        self.own_s = own_s
        self.cumulative_s = cumulative_s

    @property
    def where(self) -> str:
        """``module.py:line function``, the path cut at the package."""
        path = self.file.replace("\\", "/")
        for root in ("/sj300_async/", "/site-packages/", "/lib/python"):
            if root in path:
                path = path.split(root, 1)[1]
                break
        return f"{path}:{self.line} {self.function}"


def profile(name: str, n: int) -> tuple[list[Hotspot], int]:
    """Run workload *name* for *n* transactions under cProfile; return hot spots and the count."""
    _default, prepare = WORKLOADS[name]
    profiler = cProfile.Profile()
    with contextlib.ExitStack() as resources, asyncio.Runner() as runner:
        workload = prepare(resources)
        runner.run(workload(min(n, 200)))  # warm-up: imports and caches out of the profile
        profiler.enable()
        done = runner.run(workload(n))
        profiler.disable()
    raw: dict[_Key, tuple[int, int, float, float, object]] = pstats.Stats(profiler).stats  # type: ignore[attr-defined]
    spots = [Hotspot(key, calls, own, cum) for key, (_prim, calls, own, cum, _c) in raw.items()]
    spots.sort(key=lambda s: s.own_s, reverse=True)
    return spots, done


def _tables(spots: list[Hotspot], transactions: int, top: int, only: str | None) -> str:
    total = sum(s.own_s for s in spots)
    by_layer: dict[str, float] = {}
    for s in spots:
        by_layer[layer(s.file)] = by_layer.get(layer(s.file), 0.0) + s.own_s
    lines = [
        f"{transactions:,} transactions, {total:.2f} s profiled "
        f"({total / transactions * 1e6:.1f} µs per transaction under cProfile)",
        "",
        "| layer | share of time |",
        "|---|---:|",
    ]
    for name, seconds in sorted(by_layer.items(), key=lambda kv: kv[1], reverse=True):
        lines.append(f"| {name} | {seconds / total:.1%} |")
    lines += [
        "",
        "| function | layer | own time | cumulative | calls / transaction |",
        "|---|---|---:|---:|---:|",
    ]
    listed = [s for s in spots if only is None or layer(s.file) == only]
    for s in listed[:top]:
        lines.append(
            f"| `{s.where}` | {layer(s.file)} | {s.own_s / total:.1%} "
            f"| {s.cumulative_s / total:.1%} | {s.calls / transactions:.2f} |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Profile one workload and print its hot spots; return the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.hotspots",
        description="Profile our side of a benchmark's workload.",
    )
    parser.add_argument("workload", choices=list(WORKLOADS))
    parser.add_argument("-n", "--transactions", type=int, help="default: per workload")
    parser.add_argument("--top", type=int, default=25, help="functions listed (default 25)")
    parser.add_argument(
        "--layer",
        choices=("library", "simulator", "event loop", "anyio", "builtins", "other"),
        help="list only this layer's functions (shares stay of the whole)",
    )
    args = parser.parse_args(argv)
    n = args.transactions or WORKLOADS[args.workload][0]
    with contextlib.redirect_stdout(sys.stderr):  # nothing but the tables on stdout
        spots, done = profile(args.workload, n)
    print(f"## hot spots: {args.workload}")
    print()
    print(_tables(spots, done, args.top, args.layer))
    return 0


if __name__ == "__main__":
    sys.exit(main())
