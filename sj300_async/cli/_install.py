"""The command that installs the ``gateway`` extra, for the copy of the package that runs.

A user of the published package gets ``pip install 'sj300-async[gateway]'``.
A checkout (the package directory's parent holds this project's
``pyproject.toml``) has no package of that name to install: running from
its ``.venv``, the command is ``make gateway`` (``make -C CHECKOUT gateway``
from another directory); running from any other interpreter, that
interpreter's pip installs the checkout itself, editable, with the extra.
"""

from __future__ import annotations

import shlex
import sys
import tomllib
from pathlib import Path
from typing import Final

__all__ = ["checkout_of", "gateway_install_command"]

#: The project's name in its pyproject.toml.
PROJECT: Final = "sj300-async"
#: This package's directory.
PACKAGE_DIR: Final = Path(__file__).resolve().parents[1]


def checkout_of(package_dir: Path) -> Path | None:
    """The checkout *package_dir* lies in (its parent holds this project's pyproject.toml)."""
    root = package_dir.parent
    try:
        project = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None
    table = project.get("project")
    return root if isinstance(table, dict) and table.get("name") == PROJECT else None


def gateway_install_command(
    *,
    package_dir: Path = PACKAGE_DIR,
    prefix: str | None = None,
    executable: str | None = None,
    cwd: Path | None = None,
    extra: str = "gateway",
) -> str:
    """The one command that installs the *extra* (``gateway``, ``opcua``) where this package runs.

    A checkout's ``make gateway`` installs every extra a northbound needs.

    The keywords default to this interpreter's (``sys.prefix``,
    ``sys.executable``, the working directory); tests give others.
    """
    root = checkout_of(package_dir)
    if root is None:
        return f"pip install '{PROJECT}[{extra}]'"
    venv = Path(sys.prefix if prefix is None else prefix).resolve()
    if venv == (root / ".venv").resolve():
        here = (Path.cwd() if cwd is None else cwd).resolve()
        where = "" if here == root.resolve() else f"-C {shlex.quote(str(root))} "
        return f"make {where}gateway (this checkout's .venv)"
    python = sys.executable if executable is None else executable
    target = shlex.quote(f"{root}[{extra}]")
    return f"{shlex.quote(python)} -m pip install -e {target} (this checkout, editable)"
