"""Where our client's time per TCP round trip goes, against the same minimal responder.

``python -m benchmarks.profile_tcp [-n N] [--top K] [--callgrind N1,N2 | --no-callgrind]``
runs ``Drive.read_status()`` round trips against the minimal SJ300 responder
(``python -m benchmarks._servers sj300-minimal``, a process of its own, not
profiled) over loopback TCP, the bus opened with
``line=LineSettings(baudrate=0)`` as in the tcp benchmark, and prints three
markdown tables (``--top K`` rows each):

1. **Unprofiled**, for scale: wall and client CPU µs per round trip, ours
   and the bare asyncio floor (``echo``), interleaved, best of 5.

The floor here is the bare client on the buffered read path
(:class:`~benchmarks._floor.BufferedEchoClient`), which reads as our
adapter does: "beyond the floor" is then what the stack costs, not the
difference between asyncio's two ways of reading a socket.
2. **cProfile**: the top functions by own time (``tottime``), in µs per
   round trip, with calls per round trip and the layer (library, event
   loop, builtins...). cProfile slows Python code down unevenly (a C
   builtin called from Python is charged its full cost, a Python function
   gets the profiler's overhead per call); its µs add up to more than the
   unprofiled round trip. A map of where to look.
3. **Bytecodes** per round trip by Python function (``sys.settrace`` with
   opcode events, ours and the floor): deterministic, and by Python
   function, which callgrind cannot tell apart.
4. **callgrind** (when ``valgrind`` is installed): instructions executed
   per round trip in this client process, ours and the floor, by C function
   of the interpreter and its libraries (Python functions themselves are
   invisible to callgrind: they show as ``_PyEval_EvalFrameDefault`` and the
   object code they call), and by source file. Deterministic where timings
   are not: a child process runs N1 and then N2 round trips under
   ``valgrind --tool=callgrind`` (``PYTHONHASHSEED=0``), and the difference
   of the two counts divided by N2 - N1 removes start-up, imports,
   connection and warm-up. The kernel's part of each system call is not
   counted (valgrind sees user space only).

``--child ours|floor --port P -n N`` is the child's side: N round trips
after a fixed warm-up, nothing printed.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import cProfile
import os
import pstats
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sj300_async import Drive, LineSettings, open_bus

from ._floor import EchoClient, connect_echo, echo_round_trips
from ._harness import interleave
from ._servers import ServerProcess
from .hotspots import Hotspot, layer

__all__ = [
    "CallgrindCount",
    "Unprofiled",
    "bytecodes",
    "callgrind",
    "main",
    "parse_annotate",
    "profile",
    "unprofiled",
]

#: Round trips profiled under cProfile, and the two counts run under callgrind.
DEFAULT_ROUND_TRIPS = 20_000
DEFAULT_CALLGRIND = (2_000, 6_000)
#: Round trips every run makes before the measured ones (imports, caches, connection).
WARM_UP = 300
_ROOT = Path(__file__).resolve().parent.parent
_INSTANT_LINE = LineSettings(baudrate=0)

_Workload = Callable[[int], Coroutine[Any, Any, int]]


async def _ours_round_trips(drive: Drive, n: int) -> int:
    for _ in range(n):
        await drive.read_status()
    return n


@contextlib.asynccontextmanager
async def _connected(kind: str, port: int) -> Any:
    """Yield a workload: *n* round trips of *kind* (``ours`` or ``floor``) to 127.0.0.1:*port*."""
    if kind == "ours":
        async with open_bus(f"tcp://127.0.0.1:{port}", line=_INSTANT_LINE) as bus:
            drive = bus.drive(1)

            def ours(n: int) -> Coroutine[Any, Any, int]:
                return _ours_round_trips(drive, n)

            yield ours
    else:
        echo: EchoClient = await connect_echo(port, buffered=True)  # as our adapter reads

        def floor(n: int) -> Coroutine[Any, Any, int]:
            return echo_round_trips(echo, b"S", n)

        yield floor


# -- 1. unprofiled -------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Unprofiled:
    """Seconds per round trip, best of the interleaved runs: (wall, client CPU)."""

    ours: tuple[float, float]
    floor: tuple[float, float]


def unprofiled(ours_port: int, floor_port: int, n: int, repeats: int = 5) -> Unprofiled:
    """Time ours and the floor, interleaved, without a profiler."""
    with asyncio.Runner() as runner:
        stack = contextlib.AsyncExitStack()
        try:
            ours = runner.run(stack.enter_async_context(_connected("ours", ours_port)))
            floor = runner.run(stack.enter_async_context(_connected("floor", floor_port)))
            timings = interleave(
                [lambda: runner.run(ours(n)), lambda: runner.run(floor(n))], repeats
            )
        finally:
            runner.run(stack.aclose())
    ours_t, floor_t = ((t.best_wall_s / n, t.best_cpu_s / n) for t in timings)
    return Unprofiled(ours_t, floor_t)


# -- 2. cProfile ---------------------------------------------------------------------


def profile(port: int, n: int) -> list[Hotspot]:
    """*n* round trips of ours under cProfile (after an unprofiled warm-up); by own time."""
    profiler = cProfile.Profile()
    with asyncio.Runner() as runner:
        stack = contextlib.AsyncExitStack()
        try:
            ours = runner.run(stack.enter_async_context(_connected("ours", port)))
            runner.run(ours(WARM_UP))
            profiler.enable()
            runner.run(ours(n))
            profiler.disable()
        finally:
            runner.run(stack.aclose())
    raw: dict[tuple[str, int, str], tuple[int, int, float, float, object]]
    raw = pstats.Stats(profiler).stats  # type: ignore[attr-defined]
    spots = [Hotspot(key, calls, own, cum) for key, (_p, calls, own, cum, _c) in raw.items()]
    spots.sort(key=lambda s: s.own_s, reverse=True)
    return spots


def _waits(spot: Hotspot) -> bool:
    """The selector's system call: under cProfile's wall clock, mostly the wait for the reply."""
    return spot.file == "~" and "of 'select." in spot.function


def _profile_table(spots: list[Hotspot], n: int, top: int) -> str:
    us = 1e6
    total = sum(s.own_s for s in spots)
    waiting = sum(s.own_s for s in spots if _waits(s))
    by_layer: dict[str, float] = {}
    for s in spots:
        by_layer[layer(s.file)] = by_layer.get(layer(s.file), 0.0) + s.own_s
    layers = ", ".join(
        f"{name} {seconds / n * us:.1f}"
        for name, seconds in sorted(by_layer.items(), key=lambda kv: -kv[1])
    )
    lines = [
        f"{n:,} round trips under cProfile (a wall clock): {total / n * us:.1f} µs per round "
        f"trip ({layers}), of which {waiting / n * us:.1f} in the selector's `poll`, mostly "
        f"waiting for the reply; the rest, {(total - waiting) / n * us:.1f} µs, is this "
        "process working, slowed down by the profiler.",
        "",
        "| function | layer | own µs / rt | cumulative µs / rt | calls / rt |",
        "|---|---|---:|---:|---:|",
    ]
    for s in spots[:top]:
        note = " (waiting for the reply)" if _waits(s) else ""
        lines.append(
            f"| `{s.where}`{note} | {layer(s.file)} | {s.own_s / n * us:.2f} "
            f"| {s.cumulative_s / n * us:.2f} | {s.calls / n:.2f} |"
        )
    return "\n".join(lines)


# -- 3. bytecodes -------------------------------------------------------------------


def bytecodes(kind: str, port: int, n: int) -> dict[tuple[str, int, str], float]:
    """Bytecode instructions per round trip by Python function, counted with ``sys.settrace``.

    Deterministic, as callgrind's counts, and by Python function where
    callgrind sees only the interpreter: every opcode executed in a frame is
    counted for its code object (``f_trace_opcodes``). What C code does on a
    Python function's behalf (a builtin, a method of ``bytes``) is not counted.
    """
    counts: dict[Any, int] = {}

    def local(frame: Any, event: str, _arg: object) -> Any:
        if event == "opcode":
            code = frame.f_code
            counts[code] = counts.get(code, 0) + 1
        return local

    def on_call(frame: Any, _event: str, _arg: object) -> Any:
        frame.f_trace_opcodes = True
        frame.f_trace_lines = False
        return local

    with asyncio.Runner() as runner:
        stack = contextlib.AsyncExitStack()
        try:
            workload = runner.run(stack.enter_async_context(_connected(kind, port)))
            runner.run(workload(WARM_UP))
            sys.settrace(on_call)
            try:
                runner.run(workload(n))
            finally:
                sys.settrace(None)
        finally:
            runner.run(stack.aclose())
    return {
        (code.co_filename, code.co_firstlineno, code.co_qualname): count / n
        for code, count in counts.items()
    }


def _bytecode_table(
    ours: dict[tuple[str, int, str], float], floor: dict[tuple[str, int, str], float], top: int
) -> str:
    total, base = sum(ours.values()), sum(floor.values())
    by_layer: dict[str, float] = {}
    for (file, _line, _name), count in ours.items():
        by_layer[layer(file)] = by_layer.get(layer(file), 0.0) + count
    layers = ", ".join(
        f"{name} {count:,.0f}" for name, count in sorted(by_layer.items(), key=lambda kv: -kv[1])
    )
    lines = [
        f"Bytecodes per round trip: ours {total:,.0f} ({layers}), the floor {base:,.0f}.",
        "",
        "| function (Python) | layer | bytecodes / rt | share | the floor's |",
        "|---|---|---:|---:|---:|",
    ]
    for key, count in sorted(ours.items(), key=lambda kv: -kv[1])[:top]:
        where = Hotspot(key, 0, 0.0, 0.0).where
        lines.append(
            f"| `{where}` | {layer(key[0])} | {count:,.1f} | {count / total:.1%} "
            f"| {floor.get(key, 0.0):,.1f} |"
        )
    return "\n".join(lines)


# -- 4. callgrind --------------------------------------------------------------------

# callgrind_annotate --inclusive=no: "  1,234 ( 5.67%)  path/file.c:function [object]"
_ANNOTATE_LINE = re.compile(r"^\s*([\d,]+)\s+\(\s*[\d.]+%\)\s+(.+?)(?:\s+\[(.+)\])?\s*$")


@dataclass(frozen=True, slots=True)
class CallgrindCount:
    """Instructions per round trip, in all and by function and by source file."""

    total: float
    by_function: dict[str, float]
    by_file: dict[str, float]


def parse_annotate(text: str) -> tuple[int, dict[tuple[str, str], int]]:
    """``callgrind_annotate --inclusive=no`` output: the total and (file, function) -> Ir.

    A function's recursion suffix (``'2``) is dropped, so its levels add up; the
    file is the source file's name (or the object's, when there is no debug
    information).
    """
    total = 0
    counts: dict[tuple[str, str], int] = {}
    for line in text.splitlines():
        match = _ANNOTATE_LINE.match(line)
        if match is None:
            continue
        ir = int(match.group(1).replace(",", ""))
        where, obj = match.group(2), match.group(3) or ""
        if where == "PROGRAM TOTALS":
            total = ir
            continue
        path, _, function = where.rpartition(":")
        function = function.split("'", 1)[0]
        source = os.path.basename(path) if path and path != "???" else os.path.basename(obj)
        key = (source or "???", function)
        counts[key] = counts.get(key, 0) + ir
    return total, counts


def _run_child(kind: str, port: int, n: int, out: Path) -> tuple[int, dict[tuple[str, str], int]]:
    env = dict(os.environ, PYTHONHASHSEED="0")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_ROOT), env.get("PYTHONPATH", "")) if p)
    command = [
        "valgrind",
        "--tool=callgrind",
        f"--callgrind-out-file={out}",
        sys.executable,
        "-m",
        "benchmarks.profile_tcp",
        "--child",
        kind,
        "--port",
        str(port),
        "-n",
        str(n),
    ]
    done = subprocess.run(command, cwd=_ROOT, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"valgrind exited with {done.returncode}: {done.stderr[-2000:]}")
    annotated = subprocess.run(
        ["callgrind_annotate", "--inclusive=no", "--threshold=100", str(out)],
        capture_output=True,
        text=True,
        check=True,
    )
    return parse_annotate(annotated.stdout)


def callgrind(kind: str, port: int, sizes: tuple[int, int]) -> CallgrindCount:
    """Instructions per round trip of *kind*: the difference of two runs under callgrind."""
    small, large = sizes
    with tempfile.TemporaryDirectory(prefix="sj300-callgrind-") as scratch:
        total_a, a = _run_child(kind, port, small, Path(scratch) / "a.out")
        total_b, b = _run_child(kind, port, large, Path(scratch) / "b.out")
    per = large - small
    by_function: dict[str, float] = {}
    by_file: dict[str, float] = {}
    for key in set(a) | set(b):
        delta = (b.get(key, 0) - a.get(key, 0)) / per
        source, function = key
        by_function[function] = by_function.get(function, 0.0) + delta
        by_file[source] = by_file.get(source, 0.0) + delta
    return CallgrindCount((total_b - total_a) / per, by_function, by_file)


def _callgrind_tables(ours: CallgrindCount, floor: CallgrindCount, top: int) -> str:
    lines = [
        f"Instructions per round trip (user space): ours {ours.total:,.0f}, the floor "
        f"{floor.total:,.0f}, ours beyond the floor {ours.total - floor.total:,.0f} "
        f"({ours.total / floor.total:.2f}x).",
        "",
        "| function (C) | ours Ir / rt | share | floor Ir / rt | ours - floor |",
        "|---|---:|---:|---:|---:|",
    ]
    ranked = sorted(ours.by_function.items(), key=lambda kv: -kv[1])
    for function, ir in ranked[:top]:
        base = floor.by_function.get(function, 0.0)
        lines.append(
            f"| `{function}` | {ir:,.0f} | {ir / ours.total:.1%} | {base:,.0f} "
            f"| {ir - base:+,.0f} |"
        )
    lines += [
        "",
        "| source file | ours Ir / rt | share | floor Ir / rt | ours - floor |",
        "|---|---:|---:|---:|---:|",
    ]
    files = sorted(ours.by_file.items(), key=lambda kv: -kv[1])
    for source, ir in files[: max(10, top // 2)]:
        base = floor.by_file.get(source, 0.0)
        lines.append(
            f"| `{source}` | {ir:,.0f} | {ir / ours.total:.1%} | {base:,.0f} | {ir - base:+,.0f} |"
        )
    return "\n".join(lines)


# -- the command line ----------------------------------------------------------------


def _child(kind: str, port: int, n: int) -> int:
    async def run() -> int:
        async with _connected(kind, port) as workload:
            await workload(WARM_UP)
            return int(await workload(n))

    asyncio.run(run())
    return 0


def _sizes(text: str) -> tuple[int, int]:
    small, large = (int(part) for part in text.split(","))
    if not 0 < small < large:
        raise argparse.ArgumentTypeError("N1,N2 with 0 < N1 < N2")
    return small, large


def main(argv: Sequence[str] | None = None) -> int:
    """Profile our client's round trips; print the tables; return the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.profile_tcp",
        description="Where our client's time per TCP round trip goes (minimal responder).",
    )
    parser.add_argument("-n", "--round-trips", type=int, default=DEFAULT_ROUND_TRIPS)
    parser.add_argument("--top", type=int, default=20, help="functions listed (default 20)")
    parser.add_argument(
        "--callgrind",
        type=_sizes,
        default=DEFAULT_CALLGRIND,
        metavar="N1,N2",
        help="round trips of the two callgrind runs (default %(default)s)",
    )
    parser.add_argument("--no-callgrind", action="store_true", help="skip callgrind")
    parser.add_argument("--child", choices=("ours", "floor"), help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return _child(args.child, args.port, args.round_trips)

    n = args.round_trips
    us = 1e6
    with ServerProcess("sj300-minimal") as ours_server, ServerProcess("echo") as floor_server:
        with contextlib.redirect_stdout(sys.stderr):
            plain = unprofiled(ours_server.port, floor_server.port, min(n, 2_000))
            spots = profile(ours_server.port, n)
        print("## where the time goes: `drive.read_status()` against the minimal responder")
        print()
        print("| unprofiled, per round trip | wall µs | client CPU µs |")
        print("|---|---:|---:|")
        print(f"| ours | {plain.ours[0] * us:.1f} | {plain.ours[1] * us:.1f} |")
        print(f"| bare asyncio floor | {plain.floor[0] * us:.1f} | {plain.floor[1] * us:.1f} |")
        print(
            f"| ours beyond the floor | {(plain.ours[0] - plain.floor[0]) * us:.1f} "
            f"| {(plain.ours[1] - plain.floor[1]) * us:.1f} |"
        )
        print()
        print("### cProfile")
        print()
        print(_profile_table(spots, n, args.top))
        print()
        with contextlib.redirect_stdout(sys.stderr):
            traced_n = min(n, 2_000)
            ours_codes = bytecodes("ours", ours_server.port, traced_n)
            floor_codes = bytecodes("floor", floor_server.port, traced_n)
        print("### bytecodes by Python function")
        print()
        print(
            f"`sys.settrace` with opcode events over {traced_n:,} round trips (after "
            f"{WARM_UP} of warm-up): deterministic, by Python function."
        )
        print()
        print(_bytecode_table(ours_codes, floor_codes, args.top))
        print()
        print("### callgrind")
        print()
        if args.no_callgrind:
            print("(skipped: --no-callgrind)")
        elif shutil.which("valgrind") is None or shutil.which("callgrind_annotate") is None:
            print("(skipped: valgrind is not installed; apt-get install valgrind)")
        else:
            small, large = args.callgrind
            print("running callgrind (a minute or two) ...", file=sys.stderr, flush=True)
            ours = callgrind("ours", ours_server.port, args.callgrind)
            floor = callgrind("floor", floor_server.port, args.callgrind)
            print(
                f"`valgrind --tool=callgrind`, runs of {small:,} and {large:,} round trips "
                f"(after {WARM_UP} of warm-up), the difference divided by {large - small:,}:"
            )
            print()
            print(_callgrind_tables(ours, floor, args.top))
    return 0


if __name__ == "__main__":
    sys.exit(main())
