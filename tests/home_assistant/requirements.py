"""Print the PyPI requirements of the Home Assistant integrations the tests load.

Run by the Home Assistant venv's own Python (``make test-ha``), never by the
suite's: it reads the integrations' ``manifest.json`` files from the installed
``homeassistant`` package. The tests start ``hass --skip-pip``, so that a run
installs nothing at start and depends on no network: everything HA would
install for these integrations (and their dependencies, recursively) is
installed beforehand from this list.
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

#: What the tests' configuration.yaml sets up, beside what HA always sets up
#: (its bootstrap's core, logging and default integrations, read from it below).
CONFIGURED = (
    "mqtt",
    "recorder",
    "logbook",
    "history",
    "automation",
    "sensor",
    "number",
    "select",
    "button",
    "binary_sensor",
    "event",
)
#: What onboarding's core_config step sets up on its own, as on every new install (the
#: tests remove their entries again: a weather service is not reachable here).
ONBOARDING = ("google_translate", "met", "radio_browser", "shopping_list")  # fmt: skip


def _always(bootstrap: object) -> set[str]:
    """The integrations HA's bootstrap sets up with any configuration."""
    names = ("CORE_INTEGRATIONS", "LOGGING_AND_HTTP_DEPS_INTEGRATIONS",
             "FRONTEND_INTEGRATIONS", "DEFAULT_INTEGRATIONS")  # fmt: skip
    found: set[str] = set()
    for name in names:
        found.update(getattr(bootstrap, name, ()))
    return found


def requirements(components: Path, domains: set[str]) -> list[str]:
    """Every requirement of *domains* and of what they depend on, in a stable order."""
    seen: set[str] = set()
    wanted: list[str] = []
    todo = sorted(domains)
    while todo:
        domain = todo.pop()
        manifest_path = components / domain / "manifest.json"
        if domain in seen or not manifest_path.exists():
            continue
        seen.add(domain)
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
        wanted.extend(r for r in manifest.get("requirements", ()) if r not in wanted)
        todo.extend(manifest.get("dependencies", ()))
    return sorted(wanted)


def main() -> int:
    bootstrap = importlib.import_module("homeassistant.bootstrap")
    components = Path(str(importlib.import_module("homeassistant.components").__path__[0]))
    for line in requirements(components, _always(bootstrap) | set(CONFIGURED) | set(ONBOARDING)):
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
