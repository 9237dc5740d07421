"""The protocol core is sans-IO: none of its modules imports asyncio, sockets, clocks or serial.

The core is the neutral wire (:mod:`sj300_async.wire`), the SJ300 codec
(:mod:`sj300_async.sj300` minus its dialect and drive) and the bus's
arithmetic and URL parsing (see :data:`sans_io_scan.CORE_MODULES`). Checks: the
module lists cover those packages (a new module must be classified), a static
scan of every core module's imports (the required one), and a fresh
interpreter that imports the core modules *without* running the ``__init__``
of the packages that re-export the async layers, legitimately.

The SJ300 and FR-700 dialects are no longer sans-IO: each names its drive
class (``Drive`` / ``Fr700Drive``), whose module imports :mod:`sj300_async.bus`
and so asyncio. They are listed with the I/O modules.
"""

from __future__ import annotations

import textwrap

import pytest
from sans_io_scan import (
    BUS_IO,
    BUS_SANS_IO,
    CLASSIFIED_PACKAGES,
    CORE_MODULES,
    IO_PACKAGES,
    ROOT_MODULES,
    SJ300_CODEC,
    SJ300_IO,
    STUBBED_PACKAGES,
    WIRE,
    module_violations,
    modules_in,
    params,
    probe,
    proven,
    subpackages_of,
    violations,
)

#: What a core module may import from the package: the core, minus what is not proved yet.
ALLOWED = proven(CORE_MODULES)


def import_violations(source: str, package: tuple[str, ...] = ("sj300",)) -> list[str]:
    """Every import in *source* (a module of sj300_async.<package>) a core module may not make."""
    return violations(source, package, ALLOWED)


@pytest.mark.parametrize(
    ("package", "sans_io", "io"),
    [("wire", WIRE, ()), ("sj300", SJ300_CODEC, SJ300_IO), ("bus", BUS_SANS_IO, BUS_IO)],
)
def test_the_module_lists_cover_the_package(
    package: str, sans_io: tuple[str, ...], io: tuple[str, ...]
) -> None:
    assert not set(sans_io) & set(io)
    assert modules_in(package) == set(sans_io) | set(io)


def test_every_package_is_classified() -> None:
    # A new package must join CLASSIFIED_PACKAGES (its modules listed) or IO_PACKAGES.
    assert subpackages_of("") == {p for p in CLASSIFIED_PACKAGES if p and "." not in p} | set(
        IO_PACKAGES
    )
    assert {f"simulator.{p}" for p in subpackages_of("simulator")} == {
        p for p in CLASSIFIED_PACKAGES if p.startswith("simulator.")
    }
    assert modules_in("") == set(ROOT_MODULES)


@pytest.mark.parametrize("module", params(CORE_MODULES))
def test_core_module_imports_nothing_io(module: str) -> None:
    assert module_violations(module, ALLOWED) == []


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
        "from ..bus import Bus",
        "from ..bus._bus import Bus",
        "from .. import bus",
        "from ._drive import Drive",
        "from ._dialect import SJ300Dialect",
        "def f():\n    from ._drive import Drive",
        "from ..fr700._drive import Fr700Drive",
        "from ..bus._registry import get_dialect",
        "from ... import other",
        "import importlib",
        "x = __import__('asyncio')",
        "try:\n    import threading\nexcept ImportError:\n    pass",
        # TYPE_CHECKING exempts package imports only where it really is typing's constant
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import asyncio",
        "from typing import TYPE_CHECKING\nif not TYPE_CHECKING:\n    from ._drive import Drive",
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    pass\n"
        "else:\n    from ._drive import Drive",
        "if TYPE_CHECKING:\n    from ._drive import Drive",
        "TYPE_CHECKING = True\nif TYPE_CHECKING:\n    from ._drive import Drive",
        "from typing import TYPE_CHECKING\nTYPE_CHECKING = True\n"
        "if TYPE_CHECKING:\n    from ._drive import Drive",
        "from typing import TYPE_CHECKING\nfrom os import sep as TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from ._drive import Drive",
        "from typing import TYPE_CHECKING\ndef TYPE_CHECKING(): ...\n"
        "if TYPE_CHECKING:\n    from ._drive import Drive",
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    x = __import__('asyncio')",
    ],
)
def test_the_scan_catches_forbidden_imports(source: str) -> None:
    # The scan must be able to fail, or the test above proves nothing.
    assert import_violations(textwrap.dedent(source))


def test_the_scan_allows_core_and_pure_imports() -> None:
    source = (
        "import re\nimport enum\nfrom ._bcc import bcc\nfrom . import _codes\n"
        "from ..wire import BadFrame\nfrom ..wire._events import Discarded\n"
        "from .. import wire\nfrom ..bus._timing import BusTiming\n"
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ._drive import Drive\n"
    )
    assert import_violations(source) == []


def test_the_scan_resolves_a_package_init_against_the_package_itself() -> None:
    # In wire/__init__.py, "from ._enums import ..." is wire._enums.
    assert import_violations("from ._enums import Direction", ("wire",)) == []
    assert import_violations("from ._bus import Bus", ("bus",)) == [
        "imports sj300_async.bus._bus (not sans-IO)"
    ]


def test_the_probe_stubs_exactly_the_packages_that_reexport_io() -> None:
    assert set(STUBBED_PACKAGES) == {"", "sj300", "fr700", "bus", "simulator"}


def test_importing_the_core_loads_no_io_modules() -> None:
    modules = sorted(proven(CORE_MODULES))
    report = probe(modules)
    assert report["before"] == [], "the bare interpreter already loaded them: the check is void"
    assert report["after"] == []
    # Every core module really was imported from the package directory, and nothing else of it.
    assert report["loaded"] == modules


def test_importing_the_wire_package_for_real_loads_no_io_modules() -> None:
    # Only the root __init__ (the user's API) is stood in: the wire's own __init__ runs.
    report = probe(WIRE, stubs=("",), site_packages=True)
    assert report["before"] == []
    assert report["after"] == []
    assert report["loaded"] == sorted(WIRE)


def test_importing_every_listed_module_loads_no_io_modules() -> None:
    report = probe(CORE_MODULES)
    assert report["before"] == []
    assert report["after"] == []
    assert report["loaded"] == sorted(CORE_MODULES)
