"""The simulator's model is sans-IO: the drive, the bus, the faults and the pacing import no I/O.

Only the servers (``IO_MODULES``) touch the event loop. Two checks:
an AST scan of every sans-IO module's imports, and a fresh interpreter that
imports them without running either package ``__init__`` (which imports the
servers, legitimately).
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

SANS_IO = (
    "_bus",
    "_drive",
    "_electrical",
    "_faults",
    "_memory",
    "_motion",
    "_pacing",
    "_parameters_table",
    "_status",
    "_trips",
)
IO_MODULES = ("_device", "_endpoint", "_fd_link", "_pty", "_tcp")

# The core modules a sans-IO simulator module may import (the core proves them sans-IO).
CORE = (
    "_bcc",
    "_codes",
    "_commands",
    "_constants",
    "_errors",
    "_events",
    "_framing",
    "_line",
    "_parameters",
    "_parser",
    "_payloads",
    "_reply_encoding",
    "_request_parser",
    "_requests",
    "_terminals",
)

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
        "threading",
        "time",
        "os",
        "pty",
        "tty",
        "termios",
        "fcntl",
        "random",  # the model is deterministic
        "serial",
        "serial_asyncio_fast",
        "importlib",
    }
)


def simulator_dir() -> Path:
    spec = importlib.util.find_spec("sj300_async")
    assert spec is not None
    assert spec.submodule_search_locations
    return Path(next(iter(spec.submodule_search_locations))) / "simulator"


def import_violations(source: str) -> list[str]:
    """Every import in *source* a sans-IO simulator module may not make."""
    problems = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            problems += [
                f"import {a.name}" for a in node.names if a.name.split(".")[0] in FORBIDDEN
            ]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level == 0 and module.split(".")[0] in FORBIDDEN:
                problems.append(f"from {module} import ...")
            elif node.level == 1 and module.split(".")[0] not in SANS_IO:
                problems.append(f"from .{module} import ... (not a sans-IO module)")
            elif node.level == 2 and module.split(".")[0] not in CORE:
                problems.append(f"from ..{module} import ... (not a core module)")
            elif node.level > 2:
                problems.append(f"relative import of level {node.level}")
        elif isinstance(node, ast.Name) and node.id == "__import__":
            problems.append("__import__")
    return problems


def test_the_module_lists_cover_the_package() -> None:
    found = {p.stem for p in simulator_dir().glob("_*.py")} - {"__init__"}
    assert found == set(SANS_IO) | set(IO_MODULES)


@pytest.mark.parametrize("module", SANS_IO)
def test_sans_io_module_imports_nothing_io(module: str) -> None:
    source = (simulator_dir() / f"{module}.py").read_text(encoding="utf-8")
    assert import_violations(source) == []


@pytest.mark.parametrize(
    "source",
    [
        "import asyncio",
        "from asyncio import get_running_loop",
        "def f():\n    import time",
        "import os",
        "from ._endpoint import SimulatorEndpoint",
        "from . import _tcp",
        "from .. import Bus",
        "from .._bus import Bus",
        "x = __import__('socket')",
    ],
)
def test_the_scan_can_fail(source: str) -> None:
    assert import_violations(textwrap.dedent(source))


_PROBE = """
import json, sys, types, importlib
forbidden = {forbidden!r}
before = sorted(m for m in forbidden if m in sys.modules)
for name, path in (("sj300_async", {root!r}), ("sj300_async.simulator", {sim!r})):
    package = types.ModuleType(name)
    package.__path__ = [path]
    sys.modules[name] = package  # neither __init__ runs
for name in {modules!r}:
    importlib.import_module("sj300_async.simulator." + name)
after = sorted(m for m in forbidden if m in sys.modules)
print(json.dumps({{"before": before, "after": after}}))
"""


def test_importing_the_model_loads_no_io_modules() -> None:
    sim = simulator_dir()
    probe = _PROBE.format(
        forbidden=("asyncio", "socket", "selectors", "ssl", "serial", "termios"),
        root=str(sim.parent),
        sim=str(sim),
        modules=SANS_IO,
    )
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
