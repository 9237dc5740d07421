"""Suite-wide options: the long (``--soak``) form of the reliability runs, and their figures.

The reliability tests (tests/reliability) run in every ``pytest`` at a short
size; ``--soak`` (``make soak``) runs them at the sizes docs/RELIABILITY.md
publishes. Each of them records its figures in the ``soak_figures`` fixture;
they are printed at the end of the run and, with ``--soak-report PATH``,
written there as JSON.
"""

from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

_FIGURES = pytest.StashKey[dict[str, Any]]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("sj300 reliability")
    group.addoption(
        "--soak",
        action="store_true",
        default=False,
        help="run the reliability suite at its long (published) sizes; minutes, not seconds",
    )
    group.addoption(
        "--soak-report",
        metavar="PATH",
        default=None,
        help="write the reliability figures of this run to PATH as JSON",
    )
    group.addoption(
        "--soak-seed",
        type=int,
        default=None,
        help="seed of the reliability runs (default: SJ300_SOAK_SEED, else 300)",
    )


def pytest_configure(config: pytest.Config) -> None:
    config.stash[_FIGURES] = {}


@pytest.fixture(scope="session")
def soak(pytestconfig: pytest.Config) -> bool:
    """True when the long form was asked for (``--soak``)."""
    return bool(pytestconfig.getoption("--soak"))


@pytest.fixture(scope="session")
def soak_seed(pytestconfig: pytest.Config) -> int:
    """The seed every reliability run derives its randomness from (printed with the figures)."""
    seed = pytestconfig.getoption("--soak-seed")
    if seed is None:
        seed = int(os.environ.get("SJ300_SOAK_SEED", "300"))
    return int(seed)


@pytest.fixture(scope="session")
def soak_figures(pytestconfig: pytest.Config) -> dict[str, Any]:
    """Where reliability tests record their figures: ``soak_figures[name] = {...}``."""
    return pytestconfig.stash[_FIGURES]


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    figures = config.stash.get(_FIGURES, {})
    if not figures:
        return
    report = {
        "form": "long (--soak)" if config.getoption("--soak") else "short (default suite)",
        "date": time.strftime("%Y-%m-%d %H:%M:%S %z"),
        "commit": _commit(config.rootpath),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "ci": os.environ.get("SJ300_CI") == "1",
        # ru_maxrss is in KiB on Linux: the peak of the whole pytest process.
        "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "runs": figures,
    }
    text = json.dumps(report, indent=2, sort_keys=False, default=str)
    terminalreporter.section("sj300 reliability figures")
    path = config.getoption("--soak-report")
    if config.getoption("--soak") or config.getoption("verbose") > 0:
        terminalreporter.write_line(text)
    else:  # the default suite: the headlines only
        for name, run in figures.items():
            whole = json.dumps(run, default=str)
            shown = {k: v for k, v in run.items() if k in _HEADLINES}
            terminalreporter.write_line(
                f"{name}: {whole if len(whole) <= 240 else json.dumps(shown)}"
            )
        if not path:
            terminalreporter.write_line("(-v or --soak-report PATH for every figure)")
    if path:
        Path(path).write_text(text + "\n")
        terminalreporter.write_line(f"written to {path}")


def _commit(root: Path) -> str | None:
    """The git commit under test (with ``+`` when the tree has changes), if known."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True
        )
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
        )
    except OSError:
        return None
    if head.returncode != 0:
        return os.environ.get("SJ300_COMMIT")
    return head.stdout.strip() + ("+" if dirty.stdout.strip() else "")


_HEADLINES = frozenset(
    (
        "transactions",
        "cancellations",
        "reconnect_cycles",
        "total_inputs",
        "wrong_values",
        "untyped_errors",
        "swallowed_cancellations",
        "leaks",
        "elapsed_s",
    )
)
