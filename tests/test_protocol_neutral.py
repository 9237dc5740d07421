"""The gateway and the command line know no protocol by name: they ask its profile.

Two static checks over ``sj300_async/gateway`` and ``sj300_async/cli``:

- they import nothing of a protocol package (``sj300_async.sj300``,
  ``.fr700`` and the simulator's ``.sj300``, ``.fr700``), so no
  ``isinstance`` against one protocol's types is possible there;
- no branch on a protocol's name: a registered protocol's name as a string
  literal compared with something, as a dictionary key, in a tuple, list or
  set literal, or as a ``choices=`` argument.

The product's own name ``sj300`` (the command ``sj300``, the MQTT topic
prefix ``sj300/``) is not a protocol's, and may appear elsewhere. Each
check is itself tested on deliberately bad code.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path
from typing import Final

import pytest

from sj300_async.bus import protocol_names

ROOT: Final = Path(__file__).resolve().parents[1]
SCANNED: Final = ("sj300_async/gateway", "sj300_async/cli")
PROTOCOL_PACKAGES: Final = (
    "sj300_async.sj300",
    "sj300_async.fr700",
    "sj300_async.simulator.sj300",
    "sj300_async.simulator.fr700",
)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not is_package:
        base.pop()
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def protocol_imports(path: Path, text: str) -> Iterator[str]:
    """Each import of a protocol package in *text* (the module at *path*)."""
    module = _module_name(path)
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node, module, is_package)
            names = [base, *(f"{base}.{alias.name}" for alias in node.names)]
        else:
            continue
        for name in names:
            if any(name == p or name.startswith(p + ".") for p in PROTOCOL_PACKAGES):
                yield f"{node.lineno}: {name}"
                break


def protocol_branches(text: str, protocols: frozenset[str]) -> Iterator[str]:
    """Each place *text* branches on, or keys a table by, a protocol's name."""

    def named(node: ast.AST) -> bool:
        return isinstance(node, ast.Constant) and node.value in protocols

    for node in ast.walk(ast.parse(text)):
        found: list[ast.AST] = []
        if isinstance(node, ast.Compare):
            found = [n for n in (node.left, *node.comparators) if named(n)]
        elif isinstance(node, ast.Dict):
            found = [key for key in node.keys if key is not None and named(key)]
        elif isinstance(node, ast.Tuple | ast.List | ast.Set):
            found = [element for element in node.elts if named(element)]
        elif isinstance(node, ast.keyword) and node.arg == "choices":
            found = [n for n in ast.walk(node.value) if named(n)]
        elif isinstance(node, ast.MatchValue) and named(node.value):
            found = [node.value]
        for hit in found:
            assert isinstance(hit, ast.Constant)
            yield f"{hit.lineno}: {hit.value!r}"


def _sources() -> Iterator[tuple[Path, str]]:
    for tree in SCANNED:
        for path in sorted((ROOT / tree).rglob("*.py")):
            yield path, path.read_text(encoding="utf-8")


def test_the_gateway_and_the_cli_import_no_protocol_package() -> None:
    found = [
        f"{path.relative_to(ROOT)}:{hit}"
        for path, text in _sources()
        for hit in protocol_imports(path, text)
    ]
    assert found == []


def test_the_gateway_and_the_cli_never_branch_on_a_protocol_name() -> None:
    protocols = frozenset(protocol_names())
    assert {"sj300", "fr700"} <= protocols
    found = [
        f"{path.relative_to(ROOT)}:{hit}"
        for path, text in _sources()
        for hit in protocol_branches(text, protocols)
    ]
    assert found == []


@pytest.mark.parametrize(
    "code",
    [
        'if protocol == "fr700":\n    pass\n',
        'ok = line.protocol != "sj300"\n',
        'ok = name in ("sj300", "fr700")\n',
        'BASES = {"sj300": 1, "fr700": 2}\n',
        'p.add_argument("--protocol", choices=("sj300", "fr700"))\n',
        'p.add_argument("--protocol", choices=["fr700"])\n',
        'match protocol:\n    case "fr700":\n        pass\n',
    ],
)
def test_a_branch_on_a_protocol_name_is_found(code: str) -> None:
    assert list(protocol_branches(code, frozenset({"sj300", "fr700"})))


@pytest.mark.parametrize(
    "code",
    [
        'parser = ArgumentParser(prog="sj300")\n',
        'DEFAULT_PREFIX = "sj300"\n',
        'node = node_id("sj300", gateway)\n',
        "if profile.capabilities.broadcast_stop:\n    pass\n",
    ],
)
def test_the_product_name_and_capabilities_are_no_branch(code: str) -> None:
    assert list(protocol_branches(code, frozenset({"sj300", "fr700"}))) == []


@pytest.mark.parametrize(
    ("relative", "code"),
    [
        ("sj300_async/cli/x.py", "from ..sj300 import InverterStatus\n"),
        ("sj300_async/cli/x.py", "from ..fr700._drive import Fr700Drive\n"),
        ("sj300_async/gateway/mqtt/x.py", "from ...sj300 import MonitorData\n"),
        ("sj300_async/cli/x.py", "import sj300_async.simulator.fr700\n"),
        ("sj300_async/cli/x.py", "from ..simulator import fr700\n"),
        ("sj300_async/cli/x.py", "def f():\n    from .. import sj300\n"),
    ],
)
def test_a_protocol_import_is_found(relative: str, code: str) -> None:
    assert list(protocol_imports(ROOT / relative, code))


def test_neutral_imports_are_not_protocol_imports() -> None:
    code = "from ..profiles import get_profile\nfrom ..simulator import serve_tcp\n"
    assert list(protocol_imports(ROOT / "sj300_async/cli/x.py", code)) == []
