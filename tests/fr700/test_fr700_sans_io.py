"""The FR-700 protocol core and its simulator model are sans-IO: no asyncio, sockets, clocks.

Only the drive (:mod:`sj300_async.fr700._drive`, the async Drive API) and
the dialect (:mod:`sj300_async.fr700._dialect`, which hands out that drive
and parses URL options with the bus's helpers) may reach the event loop;
both are listed as I/O (:data:`sans_io_scan.FR700_IO`), so the dialect is no
longer in the codec list. Checks, as for the SJ300 core: the module lists
cover the packages, an AST scan of every sans-IO module's imports, and a
fresh interpreter that imports them without running the ``__init__`` of
the packages that re-export the async layers, and finds no I/O module loaded.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from sans_io_scan import (
    CORE_MODULES,
    FR700_CODEC,
    FR700_IO,
    SIMULATOR_FORBIDDEN,
    SIMULATOR_FR700,
    SIMULATOR_MODEL,
    SIMULATOR_SJ300,
    module_violations,
    modules_in,
    params,
    probe,
    proven,
)
from sans_io_scan import violations as scan

#: sj300_async modules proven sans-IO by the core's own test, the simulator's, or this one.
ALLOWED = proven(CORE_MODULES, FR700_CODEC, SIMULATOR_MODEL, SIMULATOR_SJ300, SIMULATOR_FR700)


def fr700_violations(path: Path, package: tuple[str, ...]) -> list[str]:
    """Forbidden imports of the module at *path*, which lives in sj300_async.<package>."""
    return scan(path.read_text(encoding="utf-8"), package, ALLOWED)


@pytest.mark.parametrize(
    ("package", "sans_io", "io"),
    [("fr700", FR700_CODEC, FR700_IO), ("simulator.fr700", SIMULATOR_FR700, ())],
)
def test_the_module_lists_cover_the_package(
    package: str, sans_io: tuple[str, ...], io: tuple[str, ...]
) -> None:
    assert not set(sans_io) & set(io)
    assert modules_in(package) == set(sans_io) | set(io)


@pytest.mark.parametrize("module", params(FR700_CODEC))
def test_fr700_core_module_imports_nothing_io(module: str) -> None:
    assert module_violations(module, ALLOWED) == []


@pytest.mark.parametrize("module", params(SIMULATOR_FR700))
def test_fr700_simulator_module_imports_nothing_io(module: str) -> None:
    # The simulator's model is deterministic and touches no descriptor, as the shared one.
    assert module_violations(module, ALLOWED, SIMULATOR_FORBIDDEN) == []


def test_the_scan_can_fail(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text(
        "import asyncio\nfrom .._bus import Bus\nfrom ._drive import Fr700Drive\n"
        "from ._dialect import Fr700Dialect\nfrom ..bus import parse_flag\n"
    )
    assert len(fr700_violations(bad, ("fr700",))) == 5


def test_importing_the_fr700_core_and_model_loads_no_io_modules() -> None:
    modules = sorted(proven(FR700_CODEC, SIMULATOR_FR700))
    report = probe(modules)
    assert report["before"] == [], "the bare interpreter already loaded them: the check is void"
    assert report["after"] == []
    # They were all imported, and nothing of the package outside the proven modules ran.
    assert set(modules) <= set(report["loaded"]) <= ALLOWED


def test_importing_every_listed_module_loads_no_io_modules() -> None:
    report = probe([*FR700_CODEC, *SIMULATOR_FR700])
    assert report["before"] == []
    assert report["after"] == []
    assert not {"fr700._dialect", "fr700._drive"} & set(report["loaded"])
