"""One import scanner for every sans-IO check (core, simulator, FR-700).

Each test names the modules it proves sans-IO; they may import the standard
library minus :data:`FORBIDDEN` (plus the test's own extras) and, inside
``sj300_async``, only modules in the allowed set — in particular
:data:`CORE_MODULES`, which tests/core/test_sans_io.py proves once for all.
"""

from __future__ import annotations

import ast
import importlib.util
from collections.abc import Collection
from pathlib import Path

#: The SJ300 protocol core (package-relative module names).
CORE_MODULES = (
    "_bcc",
    "_codes",
    "_commands",
    "_constants",
    "_dialect",
    "_errors",
    "_events",
    "_framing",
    "_line",
    "_matching",
    "_parameters",
    "_parser",
    "_payloads",
    "_reply_encoding",
    "_request_parser",
    "_requests",
    "_terminals",
    "_timing",
    "_url",
)

#: Top-level modules no sans-IO module may import: event loops, I/O, clocks, threads.
FORBIDDEN = frozenset(
    {"asyncio", "anyio", "trio", "socket", "ssl", "select", "selectors", "signal"}
    | {"subprocess", "multiprocessing", "concurrent", "threading", "time"}
    | {"serial", "serial_asyncio", "serial_asyncio_fast"}
    | {"importlib"}  # a dynamic import would slip past the scan
)


def package_dir() -> Path:
    """The sj300_async directory, found without running its ``__init__``."""
    spec = importlib.util.find_spec("sj300_async")
    assert spec is not None
    assert spec.submodule_search_locations
    return Path(next(iter(spec.submodule_search_locations)))


def violations(
    source: str,
    package: tuple[str, ...],
    allowed: Collection[str],
    forbidden: Collection[str] = FORBIDDEN,
) -> list[str]:
    """Every import in *source* (a module of ``sj300_async.<package>``) that is not allowed.

    *allowed* holds dotted paths inside sj300_async (``"_bcc"``, ``"fr700._codec"``).
    """
    problems = []
    for node in ast.walk(ast.parse(source)):
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
            names = [node.module] if node.module else [a.name for a in node.names]
            for name in names:
                target = ".".join((*package[:depth], *name.split(".")))
                if target not in allowed:
                    problems.append(f"imports sj300_async.{target} (not sans-IO)")
        elif isinstance(node, ast.Name) and node.id == "__import__":
            problems.append("__import__")
    return problems
