"""One import scanner, one probe and one classification of the package for every sans-IO check.

Every module of ``sj300_async`` is classified here: either claimed sans-IO (it may
import the standard library minus :data:`FORBIDDEN` and, inside sj300_async,
only modules claimed sans-IO) or listed as I/O (the async stack, the drives,
the servers, the package ``__init__`` modules that re-export them). The tests check
that the lists cover the package, so a new module has to be classified.

Modules are named by their dotted path inside sj300_async: ``"sj300._bcc"`` is
``sj300_async/sj300/_bcc.py``, and a package's own name (``"wire"``) is its
``__init__.py``; ``""`` is the root ``__init__``.

Two rules of the scan:

- *Package ``__init__`` modules.* Python runs every enclosing package's
  ``__init__`` before a module, and those of the root (the user's API),
  :mod:`sj300_async.sj300`, :mod:`sj300_async.fr700`, :mod:`sj300_async.bus` and
  :mod:`sj300_async.simulator` import async classes (see the ``*_IO`` lists).
  Sans-IO is therefore proved of the modules' own code: the run-time
  :func:`probe` stands each such package in with an empty one
  (:data:`STUBBED_PACKAGES`), and checks that nothing but the proved modules
  got loaded. (A plain ``import sj300_async.sj300._parser`` runs the root
  ``__init__`` first, which opens the whole user API, asyncio included: that
  is the price of one import for users, and docs/ARCHITECTURE.md says so.)
- *``if TYPE_CHECKING:``.* Its body never runs, so an import of a package
  module there is not a run-time dependency and is not checked (the type
  checker needs ``Channel`` in :mod:`sj300_async.bus._dialect`, for instance).
  The exemption holds only where ``TYPE_CHECKING`` is imported from
  :mod:`typing` and never rebound; the ``else:`` branch is scanned; a
  :data:`FORBIDDEN` module stays forbidden even there.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import subprocess
import sys
from collections.abc import Collection, Iterable, Iterator
from pathlib import Path
from typing import Final, TypedDict

import pytest
from _pytest.mark.structures import ParameterSet

# -- the classification ----------------------------------------------------------------------

#: The neutral wire pieces (its ``__init__`` included: ``from ..wire import BadFrame`` runs it).
WIRE: Final = (
    "wire",
    "wire._enums",
    "wire._errors",
    "wire._events",
    "wire._fast_construct",
    "wire._frames",
    "wire._line",
    "wire._parser_stats",
    "wire._pcapng",
)

#: The SJ300 codec. Its ``_dialect`` is *not* here any more: it imports the drive classes
#: (``Drive``, ``Broadcast``), and the drive imports ``sj300_async.bus`` and so asyncio.
SJ300_CODEC: Final = tuple(
    f"sj300.{m}"
    for m in (
        "_bcc",
        "_codes",
        "_commands",
        "_constants",
        "_events",
        "_framing",
        "_line_frames",
        "_matching",
        "_parameters",
        "_parser",
        "_payloads",
        "_reply_encoding",
        "_request_parser",
        "_requests",
        "_terminals",
        "codec",  # the codec's public face, for the simulated drives
    )
)

#: The bus's interfaces and arithmetic.
BUS_SANS_IO: Final = (
    "bus._chunklog",
    "bus._dialect",
    "bus._sniffer",
    "bus._timing",
    "bus._trace",
)

#: The protocol core (tests/core/test_sans_io.py): the wire, the SJ300 codec, the bus's arithmetic.
CORE_MODULES: Final = (*WIRE, *SJ300_CODEC, *BUS_SANS_IO)

#: The FR-700 codec and its parameter catalogue (``_parameters``, which the simulator's table
#: reads). Its ``_dialect`` is not here any more: ``make_drive`` imports
#: :class:`~sj300_async.fr700.Fr700Drive` (asyncio) and ``configure`` imports sj300_async.bus.
FR700_CODEC: Final = tuple(
    f"fr700.{m}"
    for m in (
        "_codec",
        "_codes",
        "_events",
        "_faults",
        "_line_frames",
        "_parameters",
        "_parser",
        "_payloads",
        "_request_parser",
        "_requests",
        "codec",  # the codec's public face, for the simulated drives
    )
)

#: The simulator's shared model: line model interface, faults, motion, electrical, pacing.
SIMULATOR_MODEL: Final = tuple(
    f"simulator.{m}"
    for m in ("_command_line", "_electrical", "_faults", "_model", "_motion", "_pacing")
)
#: The simulated SJ300 drives and line (the package's ``__init__`` only re-exports them).
SIMULATOR_SJ300: Final = (
    "simulator.sj300",
    *(
        f"simulator.sj300.{m}"
        for m in (
            "_bus",
            "_command_line",
            "_drive",
            "_drive_model",
            "_memory",
            "_parameters_table",
            "_status",
            "_trips",
        )
    ),
)
#: The simulated FR-700 drives and line.
SIMULATOR_FR700: Final = (
    "simulator.fr700",
    *(
        f"simulator.fr700.{m}"
        for m in ("_bus", "_command_line", "_drive", "_parameters", "_readings")
    ),
)

#: Not sans-IO, by design. The package ``__init__`` modules re-export the async classes.
#: A protocol's profile reads its drives (``read_trips``...) and names its drive class.
SJ300_IO: Final = ("sj300", "sj300._dialect", "sj300._drive", "sj300._profile")
FR700_IO: Final = ("fr700", "fr700._dialect", "fr700._drive", "fr700._profile")
#: The async stack. (``_stats`` and ``_channel`` import no asyncio themselves, but are the
#: stack's bookkeeping and the drives' door to the arbiter: not claimed.)
BUS_IO: Final = (
    "bus",
    "bus._arbiter",
    "bus._attempts",
    "bus._bus",
    "bus._capture",  # writes files
    "bus._channel",
    "bus._line_connector",
    "bus._linequeue",
    "bus._link",
    "bus._listen",
    "bus._open",
    "bus._protocol",
    "bus._recovery",
    "bus._replay_open",  # reads files
    # The registry imports a protocol's dialect by name when asked for one (and with it
    # the protocol's drive and the async stack); the URL parser asks it for node ranges
    # and options. Neither imports I/O at import time (see the probe), but neither is
    # sans-IO in what it does.
    "bus._registry",
    "bus._stats",
    "bus._url",
)
SIMULATOR_IO: Final = (
    "simulator",
    "simulator._device",
    "simulator._endpoint",
    "simulator._fd_link",
    "simulator._precise_loop",
    "simulator._pty",
    "simulator._sim_connector",  # the bus's connector for sim:// (found by its scheme)
    "simulator._tap",
    "simulator._tcp",
)
#: The root: the user's API (open_bus, the poller), ``python -m`` and the version.
ROOT_MODULES: Final = ("", "__main__", "_open", "_poller", "_poll_results", "version")
#: Whole packages that are I/O by nature, not scanned module by module. The
#: gateway is a process (servers, pollers, leases); its register map does no
#: I/O itself but works on the drives' payload types, which come with the
#: protocol packages and so with the async stack. The profiles' model is
#: plain data, but their registry finds a profile through the bus's registry.
IO_PACKAGES: Final = ("cli", "gateway", "profiles", "transports")

#: Every package whose modules are classified one by one above.
CLASSIFIED_PACKAGES: Final = (
    "",
    "wire",
    "sj300",
    "bus",
    "fr700",
    "simulator",
    "simulator.sj300",
    "simulator.fr700",
)

#: Every module claimed sans-IO.
SANS_IO: Final = (*CORE_MODULES, *FR700_CODEC, *SIMULATOR_MODEL, *SIMULATOR_SJ300, *SIMULATOR_FR700)


def proven(*groups: Iterable[str]) -> frozenset[str]:
    """The modules of *groups* (each one proved sans-IO by the scan)."""
    return frozenset(m for group in groups for m in group)


#: Packages whose ``__init__`` is not proved sans-IO: the probes replace them by empty ones.
STUBBED_PACKAGES: Final = tuple(p for p in CLASSIFIED_PACKAGES if p not in proven(SANS_IO))

# -- the scan --------------------------------------------------------------------------------

#: Top-level modules no sans-IO module may import: event loops, I/O, clocks, threads.
FORBIDDEN: Final = frozenset(
    {"asyncio", "anyio", "trio", "socket", "ssl", "select", "selectors", "signal"}
    | {"subprocess", "multiprocessing", "concurrent", "threading", "time"}
    | {"serial", "serial_asyncio", "serial_asyncio_fast"}
    | {"importlib"}  # a dynamic import would slip past the scan
)
#: The simulator's model is deterministic too, and touches no descriptor.
SIMULATOR_FORBIDDEN: Final = FORBIDDEN | {"os", "pty", "tty", "termios", "fcntl", "random"}


def package_dir() -> Path:
    """The sj300_async directory, found without running its ``__init__``."""
    spec = importlib.util.find_spec("sj300_async")
    assert spec is not None
    assert spec.submodule_search_locations
    return Path(next(iter(spec.submodule_search_locations)))


def _parts(module: str) -> tuple[str, ...]:
    return tuple(module.split(".")) if module else ()


def is_package(module: str) -> bool:
    """Whether *module* (a dotted path inside sj300_async) names a package."""
    return (package_dir().joinpath(*_parts(module)) / "__init__.py").is_file()


def module_path(module: str) -> Path:
    """The source file of *module*: a package's ``__init__.py``, or ``<name>.py``."""
    if is_package(module):
        return package_dir().joinpath(*_parts(module)) / "__init__.py"
    *package, name = _parts(module)
    return package_dir().joinpath(*package) / f"{name}.py"


def modules_in(package: str) -> set[str]:
    """Every module of *package* (its ``__init__`` included), not those of its subpackages."""
    directory = package_dir().joinpath(*_parts(package))
    prefix = f"{package}." if package else ""
    return {
        package if path.stem == "__init__" else prefix + path.stem
        for path in directory.glob("*.py")
    }


def subpackages_of(package: str) -> set[str]:
    """The names of *package*'s direct subpackages (directories with an ``__init__.py``)."""
    directory = package_dir().joinpath(*_parts(package))
    return {p.parent.name for p in directory.glob("*/__init__.py")}


def _type_checking_guard(tree: ast.Module) -> bool:
    """Whether ``TYPE_CHECKING`` in *tree* is typing's constant: imported once, never rebound."""
    imported = any(
        isinstance(node, ast.ImportFrom)
        and node.module == "typing"
        and node.level == 0
        and any(a.name == "TYPE_CHECKING" and a.asname is None for a in node.names)
        for node in tree.body
    )
    bindings = 0
    for node in ast.walk(tree):
        if isinstance(node, ast.alias):
            bound = node.asname or node.name.split(".")[0]
        elif isinstance(node, ast.Name) and not isinstance(node.ctx, ast.Load):
            bound = node.id
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            bound = node.name
        elif isinstance(node, ast.ExceptHandler | ast.MatchAs | ast.MatchStar):
            bound = node.name or ""
        elif isinstance(node, ast.Global | ast.Nonlocal):
            bound = "TYPE_CHECKING" if "TYPE_CHECKING" in node.names else ""
        else:
            continue
        bindings += bound == "TYPE_CHECKING"
    return imported and bindings == 1


def _nodes(tree: ast.Module) -> Iterator[tuple[ast.AST, bool]]:
    """Every node of *tree*, with whether it only runs for a type checker."""
    guard = _type_checking_guard(tree)

    def visit(node: ast.AST, type_only: bool) -> Iterator[tuple[ast.AST, bool]]:
        if (
            guard
            and isinstance(node, ast.If)
            and isinstance(node.test, ast.Name)
            and node.test.id == "TYPE_CHECKING"
        ):
            for statement in node.body:
                yield from visit(statement, True)
            for statement in node.orelse:
                yield from visit(statement, type_only)
            return
        yield node, type_only
        for child in ast.iter_child_nodes(node):
            yield from visit(child, type_only)

    yield from visit(tree, False)


def violations(
    source: str,
    package: tuple[str, ...],
    allowed: Collection[str],
    forbidden: Collection[str] = FORBIDDEN,
) -> list[str]:
    """Every import in *source* (a module of ``sj300_async.<package>``) that is not allowed.

    *allowed* holds dotted paths inside sj300_async (``"sj300._bcc"``, ``"wire"``).
    For a package's ``__init__``, *package* is the package itself.
    """
    problems = []
    for node, type_only in _nodes(ast.parse(source)):
        if isinstance(node, ast.Import):
            problems += [
                f"import {a.name}" for a in node.names if a.name.split(".")[0] in forbidden
            ]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if (node.module or "").split(".")[0] in forbidden:
                    problems.append(f"from {node.module} import ...")
                continue
            depth = len(package) - (node.level - 1)
            if depth < 0:
                problems.append(f"relative import beyond the package: level {node.level}")
                continue
            if type_only:
                continue  # never runs
            names = [node.module] if node.module else [a.name for a in node.names]
            for name in names:
                target = ".".join((*package[:depth], *name.split(".")))
                if target not in allowed:
                    problems.append(f"imports sj300_async.{target} (not sans-IO)")
        elif isinstance(node, ast.Name) and node.id == "__import__":
            problems.append("__import__")
    return problems


def module_violations(
    module: str, allowed: Collection[str], forbidden: Collection[str] = FORBIDDEN
) -> list[str]:
    """Every import of *module* (a dotted path inside sj300_async) that is not allowed."""
    path = module_path(module)
    assert path.is_file(), f"sans-IO module {module} is missing"
    package = _parts(module) if is_package(module) else _parts(module)[:-1]
    return violations(path.read_text(encoding="utf-8"), package, allowed, forbidden)


def params(modules: Iterable[str]) -> list[ParameterSet]:
    """*modules* as pytest parameters, each with its name as id."""
    return [pytest.param(m, id=m) for m in modules]


# -- the run-time probe ----------------------------------------------------------------------

#: Modules that must still be absent after the import (threading and time are not listed:
#: the standard library's logging imports them).
FORBIDDEN_AT_RUNTIME: Final = ("asyncio", "anyio", "trio", "socket", "ssl", "selectors", "serial")


class ProbeFailed(Exception):
    """The probe's interpreter failed (its stderr is the message)."""


class ProbeReport(TypedDict):
    """What a fresh interpreter loaded: forbidden modules before and after, and our modules."""

    before: list[str]
    after: list[str]
    loaded: list[str]


_PROBE = """
import importlib, json, sys, types
args = json.loads({args!r})
sys.path += args["path"]
before = sorted(m for m in args["forbidden"] if m in sys.modules)
for name, path in args["stubs"]:  # parents first
    package = types.ModuleType(name)
    package.__path__ = [path]
    sys.modules[name] = package  # this package's __init__ never runs
for name in args["modules"]:
    importlib.import_module(name)
after = sorted(m for m in args["forbidden"] if m in sys.modules)
loaded = sorted(
    name for name, module in sys.modules.items()
    if (name == "sj300_async" or name.startswith("sj300_async."))
    and getattr(module, "__file__", None)  # the stand-ins have none
)
print(json.dumps({{"before": before, "after": after, "loaded": loaded}}))
"""


def _full(module: str) -> str:
    return f"sj300_async.{module}" if module else "sj300_async"


def probe(
    modules: Iterable[str],
    *,
    stubs: Iterable[str] = STUBBED_PACKAGES,
    forbidden: Iterable[str] = FORBIDDEN_AT_RUNTIME,
    site_packages: bool = False,
) -> ProbeReport:
    """Import *modules* in a fresh interpreter where the packages *stubs* are empty stand-ins.

    ``loaded`` names every sj300_async module that ran (dotted, inside sj300_async). The
    interpreter sees the standard library only, unless *site_packages*: then it gets this
    process's ``sys.path`` too (without running any ``.pth`` hook).

    Raises:
        ProbeFailed: the import itself failed.
    """
    args = {
        "path": [p for p in sys.path if p] if site_packages else [],
        "forbidden": list(forbidden),
        "stubs": [(_full(p), str(package_dir().joinpath(*_parts(p)))) for p in stubs],
        "modules": [_full(m) for m in modules],
    }
    # -I: ignore PYTHON* variables and the user site; -S: no site, so no .pth hooks.
    result = subprocess.run(
        [sys.executable, "-I", "-S", "-c", _PROBE.format(args=json.dumps(args))],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    )
    if result.returncode != 0:
        raise ProbeFailed(result.stderr)
    report = json.loads(result.stdout)
    return ProbeReport(
        before=report["before"],
        after=report["after"],
        loaded=[n.removeprefix("sj300_async").removeprefix(".") for n in report["loaded"]],
    )
