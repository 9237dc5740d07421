"""The library, sim:// and tcp:// buses and ``sj300 --help`` without POSIX-only modules.

Windows has no pty, tty, termios, fcntl, grp, pwd or resource, and pyserial
imports termios on POSIX when it is imported. Everything that needs them is
imported where it is used (the pty and serial-device servers, the serial
transport), so the rest works where they do not exist. Each test runs in a
subprocess whose first ``sys.meta_path`` finder refuses those modules, as
importing them on Windows would.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from sj300_async.cli import build_parser

#: Modules that exist on POSIX only (``posix`` itself cannot go: ``os`` is built on it).
BLOCKED = ("pty", "tty", "termios", "fcntl", "grp", "pwd", "resource", "syslog")

_BLOCKER = """\
import sys
from importlib.abc import MetaPathFinder

BLOCKED = frozenset({blocked!r})


class _Blocker(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked)", name=name)
        return None


for _name in list(sys.modules):
    if _name.partition(".")[0] in BLOCKED:
        del sys.modules[_name]
sys.meta_path.insert(0, _Blocker())

_code = sys.argv[1]
sys.argv = ["sj300", *sys.argv[2:]]
exec(compile(_code, "<blocked>", "exec"), {{"__name__": "__main__"}})
"""


@pytest.fixture
def blocked_python(tmp_path: Path) -> Path:
    """A script that blocks :data:`BLOCKED`, then runs its first argument as code."""
    script = tmp_path / "without_posix.py"
    script.write_text(_BLOCKER.format(blocked=sorted(BLOCKED)))
    return script


def _run(script: Path, code: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(script), textwrap.dedent(code), *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


def _ok(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_the_blocker_blocks(blocked_python: Path) -> None:
    code = """
        import importlib
        import sys

        for name in sys.argv[1:]:
            try:
                importlib.import_module(name)
            except ModuleNotFoundError:
                print("blocked", name)
            else:
                print("imported", name)
    """
    out = _ok(_run(blocked_python, code, *BLOCKED)).split("\n")
    assert [line for line in out if line] == [f"blocked {name}" for name in BLOCKED]


def test_import_leaves_posix_modules_alone(blocked_python: Path) -> None:
    code = """
        import sys

        import sj300_async
        import sj300_async.bus
        import sj300_async.cli
        import sj300_async.simulator
        import sj300_async.simulator.fr700
        import sj300_async.simulator.sj300
        import sj300_async.transports
        from sj300_async.transports import serial_connector
        from sj300_async.simulator import precise_event_loop, serve_tcp

        # pyserial is imported when a serial bus connects, not before.
        assert "serial" not in sys.modules, "pyserial imported at import time"
        assert "serial_asyncio_fast" not in sys.modules
        # The POSIX-only servers are found on first use, and only then fail.
        try:
            sj300_async.simulator.open_pty_server
        except ModuleNotFoundError as exc:
            print("pty server:", exc.name)
        print("ok")
    """
    out = _ok(_run(blocked_python, code))
    assert "pty server: tty" in out
    assert out.endswith("ok\n")


def test_sim_bus_reads_status(blocked_python: Path) -> None:
    code = """
        import asyncio

        import sj300_async as sj


        async def main() -> None:
            async with sj.open_bus("sim://?nodes=1-2") as bus:
                status = await bus.drive(2).read_status()
                print(status.b.name)


        asyncio.run(main())
    """
    assert _ok(_run(blocked_python, code)) == "STOPPED\n"


def test_tcp_bus_reads_status(blocked_python: Path) -> None:
    code = """
        import asyncio

        import sj300_async as sj
        from sj300_async.simulator import serve_tcp
        from sj300_async.simulator.sj300 import SimulatedBus


        async def main() -> None:
            async with await serve_tcp(SimulatedBus(nodes=[1, 3])) as server:
                async with sj.open_bus(f"tcp://127.0.0.1:{server.port}") as bus:
                    status = await bus.drive(3).read_status()
                    print(status.b.name, server.connections)


        asyncio.run(main())
    """
    assert _ok(_run(blocked_python, code)) == "STOPPED 1\n"


def _subcommands(
    parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()
) -> Iterator[tuple[str, ...]]:
    yield prefix
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _subcommands(sub, (*prefix, name))


_COMMANDS = sorted(set(_subcommands(build_parser())))


def test_every_subcommand_is_covered() -> None:
    assert () in _COMMANDS
    assert ("simulate",) in _COMMANDS
    assert len(_COMMANDS) > 10


@pytest.mark.parametrize("command", _COMMANDS, ids=lambda c: " ".join(c) or "sj300")
def test_cli_help(blocked_python: Path, command: tuple[str, ...]) -> None:
    code = """
        from sj300_async.cli import main

        raise SystemExit(main())
    """
    result = _run(blocked_python, code, *command, "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"usage: sj300 {' '.join(command)}".rstrip())


def test_python_dash_m_help(blocked_python: Path) -> None:
    code = """
        import runpy
        import sys

        sys.argv = ["sj300", "--help"]
        runpy.run_module("sj300_async", run_name="__main__")
    """
    result = _run(blocked_python, code)
    assert result.returncode == 0, result.stderr
    assert "simulate" in result.stdout
