"""The plant's memory per drive, each northbound against the bare poll (issue 44).

Two measurements, both reported in KiB per drive and as a delta against
``bare`` of the same run:

- **RSS**: each full-scale configuration child's resident set at the end of
  its windows (``rss_bytes``, :mod:`benchmarks.bench_plant`). It is what the
  operating system counts (the interpreter, the libraries' code, malloc's
  free lists), but it says nothing about which code holds the bytes.
- **The traced heap, by package**: a child of its own per configuration
  (``python -m benchmarks.bench_plant heap --with ...``, :func:`heap_child`),
  never one of the CPU children: ``tracemalloc`` slows every allocation
  several times over, which would move their CPU per sample. It starts
  ``tracemalloc`` (one frame: the allocating line's file is all the grouping
  needs, and each further frame costs memory and time per trace) before the
  gateway is built, so that everything the gateway holds is traced, OPC UA's
  standard nodeset too (a fixed cost, divided here among the drives like the
  rest); our modules and the libraries they import are imported before it
  (:data:`AHEAD`): their code is the same at any size. It runs
  :data:`HEAP_LINES` lines of :data:`HEAP_DRIVES_PER_LINE`, the drives
  ramping as in the timed children and ``all``'s clients connected, for
  :data:`HEAP_WARM_UP_S` after the gateway's start, then takes a snapshot and
  groups its bytes by the package of the file that allocated them
  (:func:`package_of`). ``<string>`` is code compiled at run time (the
  ``__init__`` that ``dataclasses`` generates, for one).

The notes give one table: per configuration, both measurements, their
deltas, and the heap's :data:`TOP` packages by delta. Only the heap of
``all`` against ``bare`` is a row besides the RSS one (the bytes to track
from commit to commit); the rest is for reading.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import json
import pkgutil
import subprocess
import sys
import sysconfig
import tempfile
import tracemalloc
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any, Final, Protocol

from ._harness import Config, Result
from .bench_mqtt import _mosquitto

__all__ = [
    "HEAP_CONFIGURATIONS",
    "Heap",
    "heap_child",
    "measure_heap",
    "memory_notes",
    "memory_rows",
    "package_of",
]

#: The configurations whose heap is traced: the bare poll, each northbound alone, all.
HEAP_CONFIGURATIONS: Final = ("bare", "mqtt", "sparkplug", "opcua", "http", "modbus", "all")
#: --quick: the bare poll and one northbound, smallest. Not ``all``: OPC UA builds its
#: standard nodeset (some 30 MB of Python objects) whatever the plant's size, about a
#: minute under tracemalloc.
QUICK_HEAP_CONFIGURATIONS: Final = ("bare", "mqtt")
#: The heap children's plant: 256 drives. OPC UA's standard nodeset (about 30 MB, built
#: at any size) is then some 120 KiB of each drive's figure (480 at 64); the whole plant
#: traced is too slow (OPC UA alone starts in 40 s traced at 256 drives).
HEAP_LINES: Final = 8
HEAP_DRIVES_PER_LINE: Final = 32
QUICK_HEAP_LINES: Final = 1
QUICK_HEAP_DRIVES_PER_LINE: Final = 4
#: From the gateway's start to the snapshot: the births, discovery, OPC UA's start-up,
#: the first seconds of the workbench's trends (they grow for 900 s; not full here).
HEAP_WARM_UP_S: Final = 15.0
QUICK_HEAP_WARM_UP_S: Final = 1.0
#: From ``all``'s clients' subscriptions to the snapshot: the first values they are handed
#: (each drive's state as of subscribing) are passed on, their sessions' state settled.
HEAP_SETTLE_S: Final = 3.0
QUICK_HEAP_SETTLE_S: Final = 0.5
#: How long a heap child may take (OPC UA's start-up is several times slower traced).
HEAP_TIMEOUT_S: Final = 600.0
#: Packages shown per configuration, the largest delta against the bare poll first.
TOP: Final = 6

_KIB: Final = 1024
_STDLIB: Final = PurePath(sysconfig.get_paths()["stdlib"])
_SITE: Final = tuple(
    PurePath(p) for p in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
)
#: The repository: our package and the benchmarks, wherever the venv is.
_ROOT: Final = PurePath(__file__).parent.parent


def _under(path: PurePath, base: PurePath) -> tuple[str, ...] | None:
    try:
        return path.relative_to(base).parts
    except ValueError:
        return None


def package_of(filename: str) -> str:
    """The package *filename* (a traced frame's) is counted under.

    ``asyncua/<subpackage>/<file>`` for asyncua (its address space is most of
    OPC UA's heap: one level coarser would hide which part), the top-level
    package for any other installed library (``paho/``), ``sj300_async/<sub>/``
    (``sj300_async/gateway/opcua/``: one northbound each) and ``benchmarks/``
    for ours, ``stdlib:<module>`` for the standard library, else the name as is.
    """
    if filename.startswith("<frozen "):  # <frozen importlib._bootstrap>
        return "stdlib:" + filename.removeprefix("<frozen ").split(".")[0].rstrip(">")
    path = PurePath(filename)
    for site in _SITE:
        parts = _under(path, site)
        if parts:
            if parts[0] == "asyncua":
                return "/".join(parts[:3]) + ("/" if len(parts) > 3 else "")
            if parts[0] == "sj300_async":  # a non-editable install of ours
                return "/".join(parts[:-1][:3]) + "/"
            return parts[0].removesuffix(".py") + ("/" if len(parts) > 1 else "")
    parts = _under(path, _ROOT)
    if parts:
        if parts[0] == "sj300_async":  # its folder: one per northbound
            return "/".join(parts[:-1][:3]) + "/"
        return parts[0] + ("/" if len(parts) > 1 else "")
    parts = _under(path, _STDLIB)
    if parts:
        return "stdlib:" + parts[0].removesuffix(".py")
    return filename


# -- the heap child ------------------------------------------------------------------------


class Clients(Protocol):
    """``all``'s clients, as :class:`benchmarks.bench_plant._Clients` runs them."""

    async def ready(self, settle_s: float) -> None: ...

    async def close(self) -> None: ...


#: Imported before tracing starts: the gateway, every northbound, the simulator, and what
#: they import on first use (the poller's anyio backend, MQTT's JSON encoder, the modules
#: of asyncua's standard nodeset and cryptography's backend, which OPC UA's start imports).
#: A module's code and classes are the same whatever the plant's size: traced, they would
#: be charged to ``stdlib:importlib`` (some 11 MB with OPC UA), not to their package, and
#: divided among the drives. Packages are walked, modules imported; a missing one is skipped.
AHEAD: Final = (
    "sj300_async.gateway",
    "sj300_async.simulator",
    "asyncua.server.standard_address_space",
)
AHEAD_MODULES: Final = (
    *("anyio._backends._asyncio", "anyio._core._fileio", "orjson"),
    "cryptography.hazmat.backends.openssl",
)


def _import_ahead() -> None:
    for name in AHEAD_MODULES:
        with contextlib.suppress(ImportError):  # optional: then traced, as the gateway has it
            importlib.import_module(name)
    for name in AHEAD:
        try:
            package = importlib.import_module(name)
        except ImportError:
            continue
        for module in pkgutil.walk_packages(package.__path__, f"{name}."):
            if not module.name.endswith(".__main__"):  # a command line, run on import
                importlib.import_module(module.name)


def _by_package(snapshot: tracemalloc.Snapshot) -> dict[str, int]:
    out: dict[str, int] = {}
    for stat in snapshot.statistics("filename"):
        key = package_of(stat.traceback[0].filename)
        out[key] = out.get(key, 0) + stat.size
    return out


async def heap_child(
    which: str,
    text: str,
    warm_up_s: float,
    start_clients: Callable[[Any], Awaitable[Clients]] | None = None,
    settle_s: float = 0.0,
) -> dict[str, Any]:
    """Build the gateway of *text* under ``tracemalloc``, run it *warm_up_s* (and its
    clients, with *start_clients*), and return its traced bytes by package."""
    from sj300_async.gateway import Gateway, parse_config

    from .bench_opcua import _start_drives

    config = parse_config(text, "bench_plant.toml")
    _import_ahead()
    tracemalloc.start(1)  # before the gateway: whatever it builds
    loop = asyncio.get_running_loop()
    began = loop.time()
    async with Gateway(config, tune_collector=True) as gateway:
        started_s = loop.time() - began  # OPC UA's start-up: 40 s or more traced
        await _start_drives(gateway)
        clients = None if start_clients is None else await start_clients(gateway)
        try:  # from the start, as the timed children's warm-up: births, trends, sessions
            await asyncio.sleep(max(0.0, began + started_s + warm_up_s - loop.time()))
            if clients is not None:
                await clients.ready(settle_s)  # subscribed: their sessions' state is held
            snapshot = tracemalloc.take_snapshot()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            if clients is not None:
                await clients.close()
        drives = len(gateway.drives)
    tracemalloc.stop()
    # The snapshot's own bookkeeping is not the gateway's.
    snapshot = snapshot.filter_traces([tracemalloc.Filter(False, tracemalloc.__file__)])
    return {
        "which": which,
        "drives": drives,
        "started_s": started_s,
        "warm_up_s": warm_up_s,
        "peak_bytes": peak,
        "by_package": _by_package(snapshot),
    }


# -- the parent ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Heap:
    """One configuration's traced heap."""

    which: str
    drives: int
    #: Bytes by package (:func:`package_of`) at the snapshot.
    by_package: Mapping[str, int]
    #: The most traced at once, the start-up included.
    peak_bytes: int
    started_s: float
    warm_up_s: float

    @property
    def traced_bytes(self) -> int:
        return sum(self.by_package.values())

    @classmethod
    def from_json(cls, body: dict[str, Any]) -> Heap:
        return cls(
            body["which"],
            body["drives"],
            body["by_package"],
            body["peak_bytes"],
            body["started_s"],
            body["warm_up_s"],
        )


def _run_heap_child(which: str, quick: bool, broker: int, directory: str) -> Heap:
    """Run *which*'s heap child (``bench_plant heap``) to its end; its figures."""
    command = [
        sys.executable, "-m", "benchmarks.bench_plant", "heap", "--with", which,
        "--broker", str(broker), "--directory", directory,
        "--lines", str(QUICK_HEAP_LINES if quick else HEAP_LINES),
        "--per-line", str(QUICK_HEAP_DRIVES_PER_LINE if quick else HEAP_DRIVES_PER_LINE),
        "--warm-up", str(QUICK_HEAP_WARM_UP_S if quick else HEAP_WARM_UP_S),
        "--settle", str(QUICK_HEAP_SETTLE_S if quick else HEAP_SETTLE_S),
    ]  # fmt: skip
    done = subprocess.run(
        command, capture_output=True, text=True, timeout=HEAP_TIMEOUT_S, cwd=_ROOT, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"the {which} heap child failed ({done.returncode}): "
                           f"{done.stderr[-2000:]}")  # fmt: skip
    return Heap.from_json(json.loads(done.stdout.strip().splitlines()[-1]))


def measure_heap(config: Config) -> dict[str, Heap]:
    """Each configuration's heap child, one after the other, on a mosquitto of their own;
    never beside the timed children (tracing slows every allocation)."""
    quick = config.quick
    with _mosquitto() as port, tempfile.TemporaryDirectory(prefix="bench_plant_") as directory:
        return {
            which: _run_heap_child(which, quick, port, directory)
            for which in (QUICK_HEAP_CONFIGURATIONS if quick else HEAP_CONFIGURATIONS)
        }


# -- the report ----------------------------------------------------------------------------


def _top(heap: Heap, bare: Heap | None) -> list[tuple[str, float]]:
    """*heap*'s packages by their delta against *bare* (None: their own size), in KiB per
    drive, largest first."""
    against = {} if bare is None else bare.by_package
    deltas = {
        k: (heap.by_package.get(k, 0) - against.get(k, 0)) / heap.drives / _KIB
        for k in set(heap.by_package) | set(against)
    }
    grew = [item for item in deltas.items() if item[1] >= 0.05]  # shown: at least +0.1
    return sorted(grew, key=lambda item: -item[1])[:TOP]


def memory_rows(children: Mapping[str, Any], heap: Mapping[str, Heap] | None) -> list[Result]:
    """RSS per drive of ``all`` against ``bare`` (the full plant), and its traced heap."""
    bare, drives = children["bare"], children["bare"].drives
    rows = [
        Result(
            "plant: RSS per drive, every northbound on",
            children["all"].rss_bytes / drives / _KIB,
            bare.rss_bytes / drives / _KIB,
            "KiB",
            higher_is_better=False,
            against="bare poll",
            as_multiple=True,
        )
    ]
    if "all-without-recorder" in children:
        rows.append(
            Result(  # issue 45: the recorder reads the trends and line logs already kept
                "plant: RSS per drive, every northbound on, with the trip recorder",
                children["all"].rss_bytes / drives / _KIB,
                children["all-without-recorder"].rss_bytes / drives / _KIB,
                "KiB",
                higher_is_better=False,
                against="without it",
                as_multiple=True,
            )
        )
    if heap is not None and "all" in heap and "bare" in heap:
        rows.append(
            Result(
                f"plant: traced heap per drive, every northbound on ({heap['all'].drives} drives)",
                heap["all"].traced_bytes / heap["all"].drives / _KIB,
                heap["bare"].traced_bytes / heap["bare"].drives / _KIB,
                "KiB",
                higher_is_better=False,
                against="bare poll",
                as_multiple=True,
            )
        )
    return rows


def memory_notes(children: Mapping[str, Any], heap: Mapping[str, Heap] | None) -> list[str]:
    """One table: each configuration's RSS and traced heap per drive, deltas against
    ``bare``, and the heap's packages that grew most."""
    heap = heap or {}
    bare_rss = children["bare"].rss_bytes / children["bare"].drives / _KIB
    bare_heap = heap.get("bare")
    sizes = ""
    if bare_heap is not None:
        sizes = (
            f"; heap: what `tracemalloc` (one frame, started before the gateway was built) "
            f"traced after {bare_heap.warm_up_s:g} s, in children of their own at "
            f"{bare_heap.drives} drives (not the CPU children: tracing slows every "
            "allocation), our modules and their libraries imported before it, fixed costs "
            "(OPC UA's standard nodeset) shared among the drives; packages as "
            "`asyncua/<subpackage>/<file>`, `sj300_async/<subpackage>/`, an installed "
            "library's top level, `stdlib:<module>`"
        )
    lines = [
        "",
        f"Memory per drive, KiB, each against `bare` of this run (Δ). RSS: the CPU "
        f"children's at the end of their windows ({children['bare'].drives} drives){sizes}.",
        "",
        "| configuration | RSS | Δ RSS | heap | Δ heap | Δ heap by package, largest "
        "(bare: its own) |",
        "|---|---:|---:|---:|---:|---|",
    ]
    names = [*children, *(w for w in heap if w not in children)]
    for name in names:
        child, traced = children.get(name), heap.get(name)
        cells = ["—"] * 4
        if child is not None:
            rss = child.rss_bytes / child.drives / _KIB
            cells[0:2] = [f"{rss:.0f}", "" if name == "bare" else f"{rss - bare_rss:+.0f}"]
        packages = ""
        if traced is not None and bare_heap is not None:
            per = traced.traced_bytes / traced.drives / _KIB
            delta = per - bare_heap.traced_bytes / bare_heap.drives / _KIB
            cells[2:4] = [f"{per:.1f}", "" if name == "bare" else f"{delta:+.1f}"]
            if name == "bare":  # its own largest: what every other row's delta is over
                packages = ", ".join(f"`{k}` {v:.1f}" for k, v in _top(traced, None))
            else:
                packages = ", ".join(f"`{k}` {v:+.1f}" for k, v in _top(traced, bare_heap))
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {packages} |")
    lines.append("")
    return lines
