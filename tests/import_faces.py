"""The public-face rule's import scanner: no package reaches into another's private modules.

A *unit* is a package of ``sj300_async``: the root (its own modules,
``_poller``, ``_open``, ``version``), ``wire``, ``transports``, ``bus``,
``profiles``, ``sj300``, ``fr700``, ``simulator``, ``gateway`` and each
northbound package under it (``gateway.modbus``, ``gateway.mqtt``,
``gateway.http``), ``cli``. The simulator's protocol packages
(``simulator.sj300``, ``simulator.fr700``) are the simulator's own modules:
they belong to its unit; the gateway's ``recorder`` package is the gateway
core's own in the same way. A module may import its own unit's private
modules (a path component starting with ``_``: ``sj300_async.bus._arbiter``);
any other unit only through its public face (``sj300_async.bus``, whose
``__init__`` exports what other packages use). Code outside the package
(the benchmarks, the examples) is a unit of its own: public faces only.

The scan is static (``ast``), resolves relative imports, and looks at
``from X import _name`` too, where ``_name`` is a private module of X.
``if TYPE_CHECKING:`` blocks are scanned like any other: a private import is
a dependency on an internal whether or not it runs.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final

ROOT: Final = Path(__file__).resolve().parents[1]
PACKAGE: Final = "sj300_async"
#: Packages that are part of their parent's unit.
#: The gateway's trip recorder is the core's own (its records, its store), kept together.
MERGED: Final = frozenset(
    {"sj300_async.simulator.sj300", "sj300_async.simulator.fr700", "sj300_async.gateway.recorder"}
)


@dataclass(frozen=True, slots=True)
class PrivateImport:
    """One import of another unit's private module."""

    path: Path
    line: int
    #: The importing module's dotted name (``benchmarks.bench_tcp`` outside the package).
    importer: str
    #: The private module imported, dotted.
    target: str

    def __str__(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}: {self.importer} imports {self.target}"


def module_name(path: Path) -> str:
    """``sj300_async/bus/_arbiter.py`` -> ``sj300_async.bus._arbiter``; a package is its dir."""
    parts = list(path.resolve().relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def unit_of_package(package: str) -> str:
    """The unit that owns *package*'s private modules."""
    if not package.startswith(PACKAGE):
        return package
    return package.rpartition(".")[0] if package in MERGED else package


def unit_of_module(name: str, *, is_package: bool) -> str:
    """The unit a module belongs to: its package's (a package ``__init__``: itself)."""
    if not name.startswith(PACKAGE + ".") and name != PACKAGE:
        return "<outside>"
    package = name if is_package else name.rpartition(".")[0]
    return unit_of_package(package)


def _resolve(node: ast.ImportFrom, name: str, *, is_package: bool) -> str:
    if node.level == 0:
        return node.module or ""
    base = name.split(".")
    if not is_package:
        base.pop()
    if node.level > 1:
        base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _targets(tree: ast.Module, name: str, *, is_package: bool) -> Iterator[tuple[int, str]]:
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node, name, is_package=is_package)
            yield node.lineno, base
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    yield node.lineno, f"{base}.{alias.name}"


def _owner_of_private(target: str) -> str | None:
    """The package whose private module *target* reaches (None: all public)."""
    parts = target.split(".")
    if parts[0] != PACKAGE:
        return None
    for i, part in enumerate(parts[1:], start=1):
        if part.startswith("_"):
            return ".".join(parts[:i])
    return None


def private_imports(path: Path) -> Iterator[PrivateImport]:
    """Every import in the file *path* of another unit's private module."""
    name = module_name(path)
    is_package = path.name == "__init__.py"
    unit = unit_of_module(name, is_package=is_package)
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for line, target in _targets(tree, name, is_package=is_package):
        owner = _owner_of_private(target)
        if owner is not None and unit_of_package(owner) != unit:
            yield PrivateImport(path, line, name, target)


def scan(*trees: str) -> list[PrivateImport]:
    """Every cross-unit private import in the Python files under *trees* (relative to the repo)."""
    found: list[PrivateImport] = []
    for tree in trees:
        for path in sorted((ROOT / tree).rglob("*.py")):
            found.extend(private_imports(path))
    return found
