"""``sj300 gateway --check-config FILE`` (systemd's ExecReload runs it before SIGHUP) on
weird files: whatever the file, one line and exit status 2, never a traceback, in bounded
time. And the reload's own reading of such files (:meth:`Gateway.reload_file`).

The bugs found here (each a test below) are fixed: the tests hold the fixes.
"""

from __future__ import annotations

import asyncio
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from sj300_async.gateway import Gateway, load_config

pytestmark = pytest.mark.timeout(120)

#: ``sj300`` as its console script runs it.
CLI = [sys.executable, "-c", "import sys; from sj300_async.cli import main; sys.exit(main())"]
#: A check is quick: one that takes longer hangs.
CHECK_S = 30.0

GOOD = (
    '[[lines]]\nname = "a"\nurl = "sim://?nodes=1"\nnodes = "1"\ninterval_s = 0.05\n'
    "trips_interval_s = 0\n"
)


def _check(
    path: Path | str, *, memory: int | None = None, timeout: float = CHECK_S
) -> subprocess.CompletedProcess[str]:
    def limit() -> None:
        if memory is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    return subprocess.run(
        [*CLI, "gateway", "--check-config", str(path)],
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=limit,
        check=False,
    )


def _one_line_refusal(done: subprocess.CompletedProcess[str]) -> None:
    assert "Traceback" not in done.stderr, done.stderr[-2000:]
    assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert done.stdout == ""


@pytest.fixture(scope="module", autouse=True)
def _cli_runs() -> None:
    """The command line runs (else this file tests nothing)."""
    done = subprocess.run(
        [*CLI, "--help"],
        capture_output=True,
        timeout=CHECK_S,
        check=False,
    )
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize(
    "make",
    ["directory", "missing", "not utf-8", "empty", "nul bytes", "long name"],
)
def test_weird_files_are_one_line_and_status_2(tmp_path: Path, make: str) -> None:
    path = tmp_path / "gw.toml"
    if make == "directory":
        path.mkdir()
    elif make == "not utf-8":
        path.write_bytes(b"\xff\xfe[[lines]]\n")
    elif make == "empty":
        path.write_bytes(b"")
    elif make == "nul bytes":
        path.write_bytes(b"[[lines]]\x00\x00\nname = 1\n")
    elif make == "long name":
        path = tmp_path / ("x" * 300)
    _one_line_refusal(_check(path))


def test_a_good_file_passes(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    path.write_text(GOOD)
    done = _check(path)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("nesting", ["array", "inline table"])
def test_a_deeply_nested_file_is_one_line(tmp_path: Path, nesting: str) -> None:
    path = tmp_path / "gw.toml"
    if nesting == "array":
        path.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    else:
        path.write_text("x = " + "{y = " * 3000 + "1" + "}" * 3000 + "\n")
    _one_line_refusal(_check(path))


def test_a_huge_integer_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    path.write_text("[gateway]\nstale_after_s = " + "9" * 5000 + "\n" + GOOD)
    _one_line_refusal(_check(path))


def test_an_endless_device_is_one_line() -> None:
    _one_line_refusal(_check("/dev/zero", memory=768 * 1024 * 1024))


def test_a_fifo_is_refused_in_bounded_time(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    os.mkfifo(path)
    try:
        done = _check(path, timeout=10)
    except subprocess.TimeoutExpired:
        pytest.fail("--check-config on a FIFO still ran after 10 s")
    _one_line_refusal(done)


async def test_a_fifo_does_not_lock_out_later_reloads(tmp_path: Path) -> None:
    """A FIFO named as the file is refused at once (never opened: its read would wait for
    a writer, holding the reload lock), and the next reload is taken."""
    path = tmp_path / "gw.toml"
    path.write_text(GOOD)
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    async with Gateway(load_config(path), tune_collector=False) as gateway:
        async with asyncio.timeout(10):
            refused = await gateway.reload_file(fifo)
            assert refused.refusal == f"{fifo}: not a regular file"
            outcome = await gateway.reload_file(path)  # the good file, after it
        assert not outcome.refused
