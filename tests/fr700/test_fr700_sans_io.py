"""The FR-700 protocol core and its simulator model are sans-IO: no asyncio, sockets, clocks.

Only :mod:`sj300_async.fr700._drive` (the async Drive API) may touch the
event loop. Two checks, as for the SJ300 core: an AST scan of every sans-IO
module's imports, and a fresh interpreter that imports them without running
any package ``__init__`` and finds no I/O module loaded.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from sans_io_scan import CORE_MODULES, package_dir
from sans_io_scan import violations as scan

#: package-relative module -> the modules it may import from (by dotted path in sj300_async).
CORE = ("_codec", "_codes", "_dialect", "_events", "_parser", "_payloads", "_requests")
SIM = ("_bus", "_drive", "_parameters", "_request_parser")
#: sj300_async modules proven sans-IO by the core's own test, or by this one.
ALLOWED = {
    *CORE_MODULES,
    *(f"fr700.{m}" for m in CORE),
    *(f"simulator.{m}" for m in ("_bus", "_electrical", "_faults", "_motion", "_pacing")),
    *(f"simulator.{m}" for m in ("_memory", "_parameters_table", "_status", "_trips", "_drive")),
    *(f"simulator.fr700.{m}" for m in SIM),
}


def fr700_violations(path: Path, package: tuple[str, ...]) -> list[str]:
    """Forbidden imports of the module at *path*, which lives in sj300_async.<package>."""
    return scan(path.read_text(encoding="utf-8"), package, ALLOWED)


@pytest.mark.parametrize("module", CORE)
def test_fr700_core_module_imports_nothing_io(module):
    assert fr700_violations(package_dir() / "fr700" / f"{module}.py", ("fr700",)) == []


@pytest.mark.parametrize("module", SIM)
def test_fr700_simulator_module_imports_nothing_io(module):
    path = package_dir() / "simulator" / "fr700" / f"{module}.py"
    assert fr700_violations(path, ("simulator", "fr700")) == []


def test_the_scan_can_fail(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import asyncio\nfrom .._bus import Bus\nfrom ._drive import Fr700Drive\n")
    assert len(fr700_violations(bad, ("fr700",))) == 3


_PROBE = """
import json, sys, types, importlib
forbidden = ("asyncio", "anyio", "trio", "socket", "ssl", "selectors", "serial")
root = {path!r}
for name, sub in (("sj300_async", ""), ("sj300_async.fr700", "/fr700"),
                  ("sj300_async.simulator", "/simulator"),
                  ("sj300_async.simulator.fr700", "/simulator/fr700")):
    package = types.ModuleType(name)
    package.__path__ = [root + sub]
    sys.modules[name] = package  # no package __init__ runs
for name in {modules!r}:
    importlib.import_module("sj300_async." + name)
print(json.dumps(sorted(m for m in forbidden if m in sys.modules)))
"""


def test_importing_the_fr700_core_and_model_loads_no_io_modules():
    modules = [f"fr700.{m}" for m in CORE] + [f"simulator.fr700.{m}" for m in SIM]
    probe = _PROBE.format(path=str(package_dir()), modules=modules)
    result = subprocess.run(
        [sys.executable, "-I", "-S", "-c", probe],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == []
