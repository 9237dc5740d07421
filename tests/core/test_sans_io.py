"""The protocol core is sans-IO: none of its modules imports asyncio, sockets, clocks or serial.

Two checks: a static scan of every core module's imports (the required one),
and a fresh interpreter that imports the core modules *without* running the
package's ``__init__`` (which may later pull in the async layers, legitimately).
"""

from __future__ import annotations

import ast
import importlib.util
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

CORE_MODULES = (
    "_bcc",
    "_codes",
    "_commands",
    "_constants",
    "_errors",
    "_events",
    "_framing",
    "_matching",
    "_parameters",
    "_parser",
    "_payloads",
    "_reply_encoding",
    "_request_parser",
    "_requests",
    "_terminals",
    "_line",
    "_timing",
    "_url",
    "_dialect",
)

#: Top-level modules a sans-IO core must not import: event loops, I/O, clocks, threads.
FORBIDDEN = frozenset(
    {
        "asyncio",
        "anyio",
        "trio",
        "socket",
        "ssl",
        "select",
        "selectors",
        "signal",
        "subprocess",
        "multiprocessing",
        "concurrent",
        "threading",
        "time",
        "serial",
        "serial_asyncio",
        "serial_asyncio_fast",
        "importlib",  # a dynamic import would slip past this scan
    }
)

#: Modules that must still be absent after importing the whole core at run time.
#: (threading and time are not listed: the standard library's logging imports them.)
FORBIDDEN_AT_RUNTIME = ("asyncio", "anyio", "trio", "socket", "ssl", "selectors", "serial")


def package_dir() -> Path:
    # find_spec locates the package without executing its __init__.
    spec = importlib.util.find_spec("sj300_async")
    assert spec is not None
    assert spec.submodule_search_locations
    return Path(next(iter(spec.submodule_search_locations)))


def import_violations(source: str) -> list[str]:
    """Return a description of every import in *source* a core module may not make."""
    problems = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in FORBIDDEN:
                    problems.append(f"import {alias.name}")
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if (node.module or "").split(".")[0] in FORBIDDEN:
                    problems.append(f"from {node.module} import ...")
            elif node.level > 1:
                problems.append(f"relative import beyond the package: level {node.level}")
            elif node.module is not None:
                if node.module.split(".")[0] not in CORE_MODULES:
                    problems.append(f"from .{node.module} import ... (not a core module)")
            else:
                problems += [
                    f"from . import {alias.name} (not a core module)"
                    for alias in node.names
                    if alias.name not in CORE_MODULES
                ]
        elif isinstance(node, ast.Name) and node.id == "__import__":
            problems.append("__import__")
    return problems


@pytest.mark.parametrize("module", CORE_MODULES)
def test_core_module_imports_nothing_io(module: str) -> None:
    path = package_dir() / f"{module}.py"
    assert path.is_file(), f"core module {module} is missing"
    assert import_violations(path.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize(
    "source",
    [
        "import asyncio",
        "import asyncio.events",
        "from asyncio import Future",
        "import time as _t",
        "def f():\n    import socket",
        "from serial import Serial",
        "from .bus import Bus",
        "from . import bus",
        "from .. import other",
        "import importlib",
        "x = __import__('asyncio')",
        "try:\n    import threading\nexcept ImportError:\n    pass",
    ],
)
def test_the_scan_catches_forbidden_imports(source: str) -> None:
    # The scan must be able to fail, or the test above proves nothing.
    assert import_violations(textwrap.dedent(source))


def test_the_scan_allows_core_and_pure_imports() -> None:
    source = "import re\nimport enum\nfrom ._bcc import bcc\nfrom . import _codes\n"
    assert import_violations(source) == []


_PROBE = """
import json, sys, types, importlib
forbidden = {forbidden!r}
before = sorted(m for m in forbidden if m in sys.modules)
package = types.ModuleType("sj300_async")
package.__path__ = [{path!r}]
sys.modules["sj300_async"] = package  # the package's __init__ never runs
for name in {modules!r}:
    importlib.import_module("sj300_async." + name)
after = sorted(m for m in forbidden if m in sys.modules)
loaded = sorted(m for m in sys.modules if m.startswith("sj300_async."))
print(json.dumps({{"before": before, "after": after, "loaded": loaded}}))
"""


def test_importing_the_core_loads_no_io_modules() -> None:
    probe = _PROBE.format(
        forbidden=FORBIDDEN_AT_RUNTIME, path=str(package_dir()), modules=CORE_MODULES
    )
    # -I: ignore PYTHON* variables and the user site; -S: no site, so no .pth hooks.
    result = subprocess.run(
        [sys.executable, "-I", "-S", "-c", probe],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["before"] == [], "the bare interpreter already loaded them: the check is void"
    assert report["after"] == []
    # Every core module really was imported from the package directory, and nothing else of it.
    assert report["loaded"] == sorted(f"sj300_async.{m}" for m in CORE_MODULES)
