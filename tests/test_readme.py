"""README.md says what the Makefile and the npm packages file install (they cannot drift apart)."""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _system_packages() -> list[str]:
    """The Debian packages of the Makefile's SYSTEM_PACKAGES (``package:command`` entries)."""
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8").replace("\\\n", " ")
    found = re.search(r"^SYSTEM_PACKAGES := (.+)$", makefile, re.M)
    assert found is not None
    return [entry.split(":")[0] for entry in found[1].split()]


def test_the_readme_lists_every_system_package_the_tests_need() -> None:
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    found = re.search(r"the Debian packages its real-part tests use \(([^:)]+)", readme)
    assert found is not None, "README.md no longer lists the Debian packages"
    assert found[1].split(", ") == _system_packages()


def test_the_readme_lists_every_npm_package_the_tests_need() -> None:
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    found = re.search(r"the npm packages its OPC UA and Sparkplug tests use \(([^:)]+)", readme)
    assert found is not None, "README.md no longer lists the npm packages"
    wanted = []
    for folder in ("opcua", "sparkplug"):
        package = json.loads((ROOT / f"tests/{folder}/node/package.json").read_text("utf-8"))
        wanted += list(package["dependencies"])
    assert found[1].split(", ") == wanted
