"""Suite-wide options: the long (``--soak``) form of the reliability runs, and their figures.

The reliability tests (tests/reliability) run in every ``pytest`` at a short
size; ``--soak`` (``make soak``) runs them at the sizes docs/RELIABILITY.md
publishes. Each of them records its figures in the ``soak_figures`` fixture;
they are printed at the end of the run and, with ``--soak-report PATH``,
written there as JSON.

``make test`` runs the suite in worker processes (pytest-xdist, ``-n``):
each worker sends its figures and its peak memory to the controller when it
finishes (``workeroutput``), which prints them all as a serial run does.
"""

from __future__ import annotations

import json
import os
import platform
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest

_FIGURES = pytest.StashKey[dict[str, Any]]()
#: The workers' peak resident memory, MiB (pytest-xdist runs only).
_WORKER_RSS = pytest.StashKey[list[float]]()
#: The key of a worker's figures and peak memory in its ``workeroutput``.
_WORKER_KEY = "sj300_soak_figures"


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
        "--attacks",
        action="store_true",
        default=False,
        help="run each attack of tests/adversarial by itself too (make attacks); "
        "without it only the combined attack runs",
    )
    group.addoption(
        "--soak-seed",
        type=int,
        default=None,
        help="seed of the reliability runs (default: SJ300_SOAK_SEED, else 300)",
    )
    group.addoption(
        "--home-assistant",
        metavar="HASS",
        default=None,
        help="run tests/home_assistant against this Home Assistant (its hass; make test-ha)",
    )


def pytest_configure(config: pytest.Config) -> None:
    config.stash[_FIGURES] = {}
    config.stash[_WORKER_RSS] = []
    # The tests that press Ctrl-C (SIGINT to a child: the CLI, the examples) need
    # their children to hear it. A suite started in the background by a script
    # (`make test &`, nohup) has SIGINT ignored, and an ignored signal stays ignored
    # across exec: every such child then ran to its end and exited 0 (two clean
    # runs failed 14 tests so). Python's own handler here resets it for them.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    # The OPC UA server keeps the standard nodeset in a cache directory (the user's by
    # default): the tests, and the gateways they start as children, keep theirs in one of
    # this run's own (each xdist worker its own), never in the user's.
    os.environ.pop("CACHE_DIRECTORY", None)
    os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp(prefix="sj300-tests-cache-")


def pytest_unconfigure(config: pytest.Config) -> None:
    shutil.rmtree(os.environ.get("XDG_CACHE_HOME", ""), ignore_errors=True)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Without ``--attacks``, the attacks run alone are deselected (not skipped), and
    without ``--home-assistant`` the tests against a real Home Assistant (``make test-ha``:
    its install is 800 MB; the default suite checks the same payloads against a schema of
    HA's discovery keys, tests/ha_discovery_schema.py).

    Each of them starts a plant of its own for 15-30 s; the default suite runs
    them all at once in one test (tests/adversarial), and ``make attacks``, which
    .ci/run calls after ``make test``, runs each alone with its own assertions.
    """
    wanted = {"attack_alone": config.getoption("--attacks"),
              "home_assistant": config.getoption("--home-assistant") is not None}  # fmt: skip
    for marker, asked in wanted.items():
        if asked:
            continue
        alone = [item for item in items if item.get_closest_marker(marker) is not None]
        if alone:
            config.hook.pytest_deselected(items=alone)
            items[:] = [item for item in items if item.get_closest_marker(marker) is None]


def _peak_rss_mib() -> float:
    # ru_maxrss is in KiB on Linux: the peak of this whole process.
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


def pytest_sessionfinish(session: pytest.Session) -> None:
    output = getattr(session.config, "workeroutput", None)
    if output is not None:  # a pytest-xdist worker: hand the figures to the controller
        figures = session.config.stash.get(_FIGURES, {})
        output[_WORKER_KEY] = json.dumps({"runs": figures, "rss": _peak_rss_mib()}, default=str)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: Any, error: object) -> None:
    """pytest-xdist: a worker finished; keep its figures for the summary."""
    sent = getattr(node, "workeroutput", {}).get(_WORKER_KEY)
    if sent is None:
        return
    received = json.loads(sent)
    node.config.stash[_FIGURES].update(received["runs"])
    node.config.stash[_WORKER_RSS].append(received["rss"])


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
    workers_rss: list[float] = config.stash.get(_WORKER_RSS, [])
    report = {
        "form": "long (--soak)" if config.getoption("--soak") else "short (default suite)",
        "date": time.strftime("%Y-%m-%d %H:%M:%S %z"),
        "commit": _commit(config.rootpath),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "pytest_workers": len(workers_rss) or 1,
        "ci": os.environ.get("SJ300_CI") == "1",
        # The peak of the pytest process that ran the tests (the largest worker's).
        "peak_rss_mib": max(workers_rss, default=_peak_rss_mib()),
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
        "rss_peak_growth_pct",
        "fds_after_settle",
        "elapsed_s",
    )
)
