"""Fixtures of the reliability suite (helpers live in the rel_*.py modules)."""

from __future__ import annotations

from pathlib import Path

import pytest

from .rel_sizes import LONG, SHORT, Sizes

_HERE = Path(__file__).parent
#: The long form runs for minutes; the suite's 120 s per-test limit is for the short form.
_LONG_TIMEOUT_S = 3600


@pytest.fixture(scope="session")
def sizes(soak: bool) -> Sizes:
    """The run sizes: SHORT in the default suite, LONG with ``--soak``."""
    return LONG if soak else SHORT


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not config.getoption("--soak"):
        return
    for item in items:
        if _HERE in Path(item.fspath).parents:
            item.add_marker(pytest.mark.timeout(_LONG_TIMEOUT_S))
