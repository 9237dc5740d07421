"""The simulator's model is sans-IO: the drives, the lines, the faults and the pacing import no I/O.

The model is the shared part of :mod:`sj300_async.simulator`
(:data:`sans_io_scan.SIMULATOR_MODEL`) and the simulated SJ300 drives of
:mod:`sj300_async.simulator.sj300` (the FR-700 ones are checked by
tests/fr700/test_fr700_sans_io.py). Only the servers
(:data:`sans_io_scan.SIMULATOR_IO`) touch the event loop. Checks: the module
lists cover the packages, an AST scan of every sans-IO module's imports, and
a fresh interpreter that imports them without running the ``__init__`` of
the packages that re-export the servers or the async drives, legitimately.
"""

from __future__ import annotations

import textwrap

import pytest
from sans_io_scan import (
    CORE_MODULES,
    SIMULATOR_FORBIDDEN,
    SIMULATOR_IO,
    SIMULATOR_MODEL,
    SIMULATOR_SJ300,
    module_violations,
    modules_in,
    params,
    probe,
    proven,
    violations,
)

SANS_IO = (*SIMULATOR_MODEL, *SIMULATOR_SJ300)
ALLOWED = proven(CORE_MODULES, SANS_IO)


def import_violations(source: str, package: tuple[str, ...] = ("simulator",)) -> list[str]:
    """Every import in *source* a sans-IO simulator module may not make."""
    return violations(source, package, ALLOWED, SIMULATOR_FORBIDDEN)


@pytest.mark.parametrize(
    ("package", "sans_io", "io"),
    [("simulator", SIMULATOR_MODEL, SIMULATOR_IO), ("simulator.sj300", SIMULATOR_SJ300, ())],
)
def test_the_module_lists_cover_the_package(
    package: str, sans_io: tuple[str, ...], io: tuple[str, ...]
) -> None:
    assert not set(sans_io) & set(io)
    assert modules_in(package) == set(sans_io) | set(io)


@pytest.mark.parametrize("module", params(SANS_IO))
def test_sans_io_module_imports_nothing_io(module: str) -> None:
    assert module_violations(module, ALLOWED, SIMULATOR_FORBIDDEN) == []


@pytest.mark.parametrize(
    ("source", "package"),
    [
        ("import asyncio", ("simulator",)),
        ("from asyncio import get_running_loop", ("simulator",)),
        ("def f():\n    import time", ("simulator",)),
        ("import os", ("simulator",)),
        ("import random", ("simulator", "sj300")),
        ("from ._endpoint import SimulatorEndpoint", ("simulator",)),
        ("from . import _tcp", ("simulator",)),
        ("from .. import Bus", ("simulator",)),
        ("from .._bus import Bus", ("simulator",)),
        ("from ..bus import Bus", ("simulator",)),
        ("from ..sj300._drive import Drive", ("simulator",)),
        ("from ..sj300._dialect import SJ300_DIALECT", ("simulator",)),
        ("from .._endpoint import SimulatorEndpoint", ("simulator", "sj300")),
        ("from .. import _tcp", ("simulator", "sj300")),
        ("from ...sj300._drive import Drive", ("simulator", "sj300")),
        ("from ...bus._bus import Bus", ("simulator", "sj300")),
        ("from ...fr700._dialect import Fr700Dialect", ("simulator", "sj300")),
        ("x = __import__('socket')", ("simulator",)),
    ],
)
def test_the_scan_can_fail(source: str, package: tuple[str, ...]) -> None:
    assert import_violations(textwrap.dedent(source), package)


def test_the_scan_allows_the_model_and_the_codec() -> None:
    source = (
        "import math\nfrom ...sj300._codes import NakCode\nfrom .._motion import RunState\n"
        "from ._memory import ParameterMemory\nfrom ...wire._enums import Direction\n"
    )
    assert import_violations(source, ("simulator", "sj300")) == []


def test_importing_the_model_loads_no_io_modules() -> None:
    report = probe(
        SANS_IO, forbidden=("asyncio", "socket", "selectors", "ssl", "serial", "termios")
    )
    assert report["before"] == [], "the bare interpreter already loaded them: the check is void"
    assert report["after"] == []
    # They were all imported, and nothing of the package outside the proven modules ran.
    assert set(SANS_IO) <= set(report["loaded"]) <= ALLOWED
