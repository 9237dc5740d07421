"""The protocol core is sans-IO: none of its modules imports asyncio, sockets, clocks or serial.

Two checks: a static scan of every core module's imports (the required one),
and a fresh interpreter that imports the core modules *without* running the
package's ``__init__`` (which may later pull in the async layers, legitimately).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest
from sans_io_scan import CORE_MODULES, package_dir, violations

#: Modules that must still be absent after importing the whole core at run time.
#: (threading and time are not listed: the standard library's logging imports them.)
FORBIDDEN_AT_RUNTIME = ("asyncio", "anyio", "trio", "socket", "ssl", "selectors", "serial")


def import_violations(source: str) -> list[str]:
    """Every import in *source* (a top-level module of the package) a core module may not make."""
    return violations(source, (), CORE_MODULES)


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
