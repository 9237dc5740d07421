"""The simulator's model is sans-IO: the drive, the bus, the faults and the pacing import no I/O.

Only the servers (``IO_MODULES``) touch the event loop. Two checks:
an AST scan of every sans-IO module's imports, and a fresh interpreter that
imports them without running either package ``__init__`` (which imports the
servers, legitimately).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from sans_io_scan import CORE_MODULES, FORBIDDEN, package_dir, violations

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
IO_MODULES = ("_device", "_endpoint", "_fd_link", "_precise_loop", "_pty", "_tcp")

#: Beyond the core's list: the model is deterministic and touches no descriptor.
EXTRA_FORBIDDEN = FORBIDDEN | {"os", "pty", "tty", "termios", "fcntl", "random"}
ALLOWED = {*CORE_MODULES, *(f"simulator.{m}" for m in SANS_IO)}


def simulator_dir() -> Path:
    return package_dir() / "simulator"


def import_violations(source: str) -> list[str]:
    """Every import in *source* a sans-IO simulator module may not make."""
    return violations(source, ("simulator",), ALLOWED, EXTRA_FORBIDDEN)


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
