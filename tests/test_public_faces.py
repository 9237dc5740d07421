"""No package reaches into another's private modules: the library, the benchmarks, the examples.

The scanner is :mod:`import_faces`; these tests prove it finds what it must
(deliberately bad modules written to a temporary package) and that the
real trees have nothing for it to find. The tests themselves may import a
package's private modules to test them, as tests do.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import import_faces
import pytest
from import_faces import ROOT, module_name, private_imports, scan, unit_of_module


def test_the_library_benchmarks_and_examples_use_only_public_faces() -> None:
    found = scan("sj300_async", "benchmarks", "examples")
    assert found == [], "\n".join(map(str, found))


@pytest.fixture
def fake_package(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """A tree laid out like the repository, with its own ``sj300_async``."""
    monkeypatch.setattr(import_faces, "ROOT", tmp_path)
    for package in ("", "bus", "cli", "gateway", "gateway/modbus", "simulator", "simulator/sj300"):
        directory = tmp_path / "sj300_async" / package
        directory.mkdir(parents=True, exist_ok=True)
        (directory / "__init__.py").write_text("")
    return tmp_path


def _module(root: Path, relative: str, text: str) -> Path:
    path = root / relative
    path.write_text(textwrap.dedent(text))
    return path


def _found(path: Path) -> list[str]:
    return [finding.target for finding in private_imports(path)]


@pytest.mark.parametrize(
    ("relative", "text", "targets"),
    [
        # Another unit's private module, absolute and relative, and as an imported name.
        ("sj300_async/cli/x.py", "from sj300_async.bus._arbiter import Arbiter\n",
         ["sj300_async.bus._arbiter"]),
        ("sj300_async/cli/x.py", "from ..bus._arbiter import Arbiter\n",
         ["sj300_async.bus._arbiter"]),
        ("sj300_async/cli/x.py", "from ..bus import _arbiter\n", ["sj300_async.bus._arbiter"]),
        ("sj300_async/cli/x.py", "import sj300_async.bus._arbiter\n",
         ["sj300_async.bus._arbiter"]),
        # The root's private modules are the root's.
        ("sj300_async/cli/x.py", "from .._poller import Poller\n", ["sj300_async._poller"]),
        # A northbound package is a unit of its own: its parent's privates are not its.
        ("sj300_async/gateway/modbus/x.py", "from .._drive import GatewayDrive\n",
         ["sj300_async.gateway._drive"]),
        # Inside a function, or under TYPE_CHECKING: still a dependency.
        ("sj300_async/cli/x.py",
         "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..bus._bus import Bus\n",
         ["sj300_async.bus._bus"]),
        ("sj300_async/cli/x.py", "def f():\n    from ..bus._bus import Bus\n",
         ["sj300_async.bus._bus"]),
        # Outside the package: every private module is another unit's.
        ("bench.py", "from sj300_async.bus._stats import BusStats\n", ["sj300_async.bus._stats"]),
        # Allowed: its own unit's private modules, public faces, the simulator's protocol
        # packages reaching into the simulator's own modules, third-party privates.
        ("sj300_async/bus/x.py", "from ._arbiter import Arbiter\n", []),
        ("sj300_async/bus/__init__.py", "from ._arbiter import Arbiter\n", []),
        ("sj300_async/cli/x.py", "from ..bus import Bus\nfrom .. import __version__\n", []),
        ("sj300_async/simulator/sj300/x.py", "from .._pacing import LinePacing\n", []),
        ("sj300_async/gateway/modbus/x.py", "from .. import GatewayDrive\nfrom . import _y\n", []),
        ("sj300_async/cli/x.py", "from asyncio import _private\nimport pymodbus._version\n", []),
    ],
)  # fmt: skip
def test_the_scanner_finds_what_it_must(
    fake_package: Path, relative: str, text: str, targets: list[str]
) -> None:
    path = _module(fake_package, relative, text)
    assert _found(path) == targets


def test_units_are_packages_with_the_simulators_protocols_merged(fake_package: Path) -> None:
    assert unit_of_module("sj300_async.bus._arbiter", is_package=False) == "sj300_async.bus"
    assert unit_of_module("sj300_async.bus", is_package=True) == "sj300_async.bus"
    assert unit_of_module("sj300_async._poller", is_package=False) == "sj300_async"
    assert (
        unit_of_module("sj300_async.simulator.sj300._bus", is_package=False)
        == "sj300_async.simulator"
    )
    assert (
        unit_of_module("sj300_async.gateway.modbus._registers", is_package=False)
        == "sj300_async.gateway.modbus"
    )
    assert unit_of_module("benchmarks.bench_tcp", is_package=False) == "<outside>"
    assert module_name(fake_package / "sj300_async" / "cli" / "__init__.py") == "sj300_async.cli"


def test_the_scanner_reads_the_real_tree() -> None:
    """A guard against a scanner that finds nothing because it reads nothing."""
    modules = [module_name(path) for path in (ROOT / "sj300_async").rglob("*.py")]
    assert "sj300_async.bus._arbiter" in modules
    assert len(modules) > 150
