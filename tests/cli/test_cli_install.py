"""The command a missing gateway extra names: the published package's, or a checkout's."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from sj300_async.cli._install import PACKAGE_DIR, checkout_of, gateway_install_command

#: This repository: the tests run from its checkout.
ROOT = Path(__file__).resolve().parents[2]
PUBLISHED = "pip install 'sj300-async[gateway]'"


def _tree(base: Path, pyproject: str | None) -> Path:
    """A package directory under *base*, beside *pyproject* (None: no pyproject.toml)."""
    package = base / "sj300_async"
    package.mkdir(parents=True)
    if pyproject is not None:
        (base / "pyproject.toml").write_text(pyproject, encoding="utf-8")
    return package


def test_this_repository_is_a_checkout() -> None:
    assert checkout_of(PACKAGE_DIR) == ROOT


@pytest.mark.parametrize(
    "pyproject",
    [
        None,  # site-packages: the published package
        '[project]\nname = "someone-else"\n',
        "[project\nname = ",  # not TOML
        'project = "sj300-async"\n',
    ],
    ids=["no-pyproject", "another-project", "broken", "no-project-table"],
)
def test_outside_a_checkout_the_published_package(tmp_path: Path, pyproject: str | None) -> None:
    package = _tree(tmp_path, pyproject)
    assert checkout_of(package) is None
    command = gateway_install_command(package_dir=package, prefix=str(tmp_path / ".venv"))
    assert command == PUBLISHED


def test_a_checkout_s_venv_gets_make(tmp_path: Path) -> None:
    root = tmp_path / "my checkout"
    package = _tree(root, '[project]\nname = "sj300-async"\n')
    venv = str(root / ".venv")
    here = gateway_install_command(package_dir=package, prefix=venv, cwd=root)
    assert here == "make gateway (this checkout's .venv)"
    elsewhere = gateway_install_command(package_dir=package, prefix=venv, cwd=tmp_path)
    assert elsewhere == f"make -C '{root}' gateway (this checkout's .venv)"


def test_a_checkout_run_by_another_python_gets_its_pip(tmp_path: Path) -> None:
    root = tmp_path / "co"
    package = _tree(root, '[project]\nname = "sj300-async"\n')
    command = gateway_install_command(
        package_dir=package, prefix="/usr", executable="/usr/bin/python3", cwd=root
    )
    assert (
        command == f"/usr/bin/python3 -m pip install -e '{root}[gateway]' (this checkout, editable)"
    )


def test_make_gateway_installs_the_extra_into_the_venv() -> None:
    """The target the message names exists and does what it says (a dry run: -n)."""
    done = subprocess.run(
        ["make", "-n", "-B", "-C", str(ROOT), "gateway"],
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
    )
    assert ".venv/bin/python -m pip install --quiet -e '.[gateway,opcua]'" in done.stdout
