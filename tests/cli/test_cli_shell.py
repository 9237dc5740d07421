"""``sj300 shell`` on a pseudo-terminal, as a user types it.

The real entry point runs in a child attached to a pty (``pty.fork``: the
pty is its controlling terminal, so Ctrl-C typed there is a SIGINT). The
tests type lines and keys and wait, with a deadline, for what the terminal
shows: the prompt, a command's output. Nothing waits a fixed time.
"""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from sj300_async.cli import build_parser
from sj300_async.cli._read import parameter_target
from sj300_async.cli._shell import _Completer, _subcommands
from sj300_async.profiles import get_profile

from .clirun import TIMEOUT, cli_env

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs a POSIX pty")

PROMPT = "sj300> "
URL = "sim://?nodes=1-3"
_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07|\x1b[=>]")
UP = "\x1b[A"
CTRL_C = "\x03"
CTRL_D = "\x04"


class Terminal:
    """``python -m sj300_async ARGS`` on a pseudo-terminal: type, and expect what it shows."""

    def __init__(self, *args: str, env: dict[str, str]) -> None:
        import pty

        argv = [sys.executable, "-m", "sj300_async", *args]
        pid, fd = pty.fork()
        if pid == 0:  # the child: become the command
            try:
                os.execve(sys.executable, argv, env)
            finally:
                os._exit(127)
        self.pid = pid
        self.fd = fd
        self.status: int | None = None
        self._raw = b""
        self._seen = 0  # where the next expect() starts looking
        self._eof = False

    @property
    def text(self) -> str:
        """All the terminal showed, escape sequences and carriage returns removed."""
        return _ANSI.sub("", self._raw.decode(errors="replace")).replace("\r", "")

    def type(self, keys: str) -> None:
        """Type *keys* (a line needs its ``\\r``, as Enter sends)."""
        os.write(self.fd, keys.encode())

    def expect(self, pattern: str, timeout: float = TIMEOUT) -> re.Match[str]:
        """Wait until the terminal shows *pattern* (a regex) past the last match."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        while True:
            text = self.text
            found = regex.search(text, self._seen)
            if found is not None:
                self._seen = found.end()
                return found
            if self._eof or not self._read(deadline):
                raise AssertionError(
                    f"{pattern!r} not shown; the terminal showed after the last match:\n"
                    f"{text[self._seen :]}"
                )

    def line(self, command: str) -> None:
        """Type *command* and Enter at a prompt (waited for first)."""
        self.expect(re.escape(PROMPT))
        self.type(command + "\r")

    def wait_until_reading(self, timeout: float = TIMEOUT) -> None:
        """Wait until the child sleeps in select(), waiting for a key (Linux: /proc; else no-op).

        CPython's readline loses a SIGINT that lands while it handles a key,
        before it is back in select() (it checks signals only when select()
        is interrupted): the Ctrl-C would wait for the next key. A person is
        never that fast; a test is.
        """
        wchan = Path(f"/proc/{self.pid}/wchan")
        deadline = time.monotonic() + timeout
        while True:
            try:
                where = wchan.read_text()
            except OSError:
                return  # no /proc: the race stays possible, if unlikely
            if "select" in where or "poll" in where:
                return
            if time.monotonic() > deadline:
                raise AssertionError(f"the shell does not wait for input (in {where!r})")
            select.select([], [], [], 0.005)

    def wait(self, timeout: float = TIMEOUT) -> int:
        """Read to the end and return the exit status."""
        deadline = time.monotonic() + timeout
        while not self._eof:
            if not self._read(deadline):
                raise AssertionError(f"still running; the terminal showed:\n{self.text}")
        while self.status is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.status = os.waitstatus_to_exitcode(status)
            elif time.monotonic() > deadline:
                raise AssertionError("the terminal closed but the process does not end")
            else:
                select.select([], [], [], 0.01)
        return self.status

    def close(self) -> None:
        """Kill the child if it still runs; close the terminal."""
        if self.status is None:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
            self.status = -signal.SIGKILL
        os.close(self.fd)

    def _read(self, deadline: float) -> bool:
        """Read what is there, waiting until *deadline*; False at the deadline."""
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        readable, _, _ = select.select([self.fd], [], [], left)
        if not readable:
            return False
        try:
            data = os.read(self.fd, 65536)
        except OSError:  # EIO: the child closed its side
            data = b""
        if data:
            self._raw += data
        else:
            self._eof = True
        return True


def _env(history: Path) -> dict[str, str]:
    env = cli_env() | {
        "TERM": "xterm",
        "COLUMNS": "120",
        "LINES": "50",
        "INPUTRC": os.devnull,
        "SJ300_HISTORY": str(history),
        "NO_COLOR": "1",
    }
    return env


@pytest.fixture
def history(tmp_path: Path) -> Path:
    """Where the shell keeps its history (never the user's own file)."""
    return tmp_path / "history"


@pytest.fixture
def shell(history: Path) -> Iterator[Terminal]:
    """``sj300 shell --url sim://?nodes=1-3`` on a terminal."""
    terminal = Terminal("shell", "--url", URL, env=_env(history))
    try:
        yield terminal
    finally:
        terminal.close()


def _status_row(label: str, value: str) -> str:
    return rf"{re.escape(label)} +{value}"


def test_simulated_drives_keep_their_state_across_commands(shell: Terminal) -> None:
    shell.expect(f"sj300 shell on {re.escape(URL)}")
    shell.line("freq 25 -n 1")
    shell.expect("node 01: frequency set to 25.00 Hz")
    shell.line("run forward -n 1")
    shell.expect("node 01: run forward")
    shell.line("status -n 1")
    shell.expect(_status_row("run (B)", "running"))
    shell.line("read F001")
    shell.expect(r"F001 +output frequency setting +25\.00 Hz")
    shell.line("status -n 2")  # the other drives are as they were
    shell.expect(_status_row("run (B)", "stopped"))
    shell.line("exit")
    assert shell.wait() == 0


def test_tab_completes_commands_and_lists_parameter_codes(shell: Terminal) -> None:
    shell.expect(re.escape(PROMPT))
    shell.type("sta\t")  # the only command starting so: status
    shell.expect(r"status $")
    shell.type("-n 2\r")
    shell.expect("node 02")
    shell.expect(re.escape(PROMPT))
    shell.type("read F00\t\t")  # several codes: a second Tab lists them
    shell.expect(r"F001 +F002 +F003 +F004")
    shell.expect(re.escape(PROMPT + "read F00"))  # the line is back, as typed
    shell.type("2\r")
    shell.expect(r"F002 +acceleration time 1 +30\.00 s")
    shell.line("run f\t-n 1")  # a choice completes too
    shell.expect("node 01: run forward")
    shell.line("quit")
    assert shell.wait() == 0


def test_up_arrow_recalls_a_command_and_history_outlives_the_session(
    shell: Terminal, history: Path
) -> None:
    shell.line("read F002 -n 3")
    shell.expect("acceleration time 1")
    shell.expect(re.escape(PROMPT))
    shell.type(UP)
    shell.expect(re.escape("read F002 -n 3"))
    shell.type("\r")
    shell.expect("acceleration time 1")
    shell.line("exit")
    assert shell.wait() == 0
    assert "read F002 -n 3" in history.read_text()

    again = Terminal("shell", "--url", URL, env=_env(history))
    try:
        again.expect(re.escape(PROMPT))
        again.type(UP + UP)  # exit, then the read before it
        again.expect(re.escape("read F002 -n 3"))
        again.type("\r")
        again.expect("acceleration time 1")
        again.line("exit")
        assert again.wait() == 0
    finally:
        again.close()


def test_errors_print_one_line_and_the_session_goes_on(shell: Terminal) -> None:
    shell.line("freq 12.5 -n 2")
    shell.expect("frequency set to 12.50 Hz")
    shell.line("read F001 -n 40")
    shell.expect(r"sj300 read: error: argument -n/--node: a node is 1\.\.32, got '40'")
    shell.line("status -n 7")  # nobody there: a time-out on the bus
    shell.expect(r"sj300 status: error: [^\n]*\n")
    shell.line("bogus")
    shell.expect(r"sj300 shell: error: no command 'bogus'")
    shell.line("status --url tcp://127.0.0.1:1")
    shell.expect(r"sj300 status: error: --url belongs to the session")
    shell.line('read "F001')
    shell.expect(r"sj300 shell: error: No closing quotation")
    shell.line("read F001 -n 2")  # the bus and the drive's state are intact
    shell.expect(r"F001 +output frequency setting +12\.50 Hz")
    assert "Traceback" not in shell.text
    shell.line("exit")
    assert shell.wait() == 0


def test_ctrl_d_at_the_prompt_ends_the_session_with_status_0(shell: Terminal) -> None:
    shell.expect(re.escape(PROMPT))
    shell.type(CTRL_D)
    assert shell.wait() == 0


def test_ctrl_c_clears_the_line_at_the_prompt(shell: Terminal) -> None:
    shell.expect(re.escape(PROMPT))
    shell.type("garbage")
    shell.expect("garbage")
    shell.wait_until_reading()
    shell.type(CTRL_C)
    shell.line("read F002")  # had the line been kept, this would be "garbageread F002"
    shell.expect("acceleration time 1")
    assert "error" not in shell.text
    shell.line("exit")
    assert shell.wait() == 0


def test_ctrl_c_stops_a_monitor_and_returns_to_the_prompt(shell: Terminal) -> None:
    shell.line("run reverse -n 3")
    shell.expect("node 03: run reverse")
    shell.line("monitor --nodes 1-3 --interval 0.1")
    shell.expect(r"\b03\b[^\n]*(running|accel)")  # a row of the live table
    shell.type(CTRL_C)
    shell.line("status -n 3")  # the same bus serves on, the drive still runs
    shell.expect(_status_row("run (B)", "running"))
    shell.expect(_status_row("direction", "reverse"))
    assert "Traceback" not in shell.text
    shell.line("exit")
    assert shell.wait() == 0


def test_help_lists_the_commands_and_a_command_help(shell: Terminal) -> None:
    shell.line("help")
    shell.expect(r"status +a drive's state")
    shell.expect(r"exit +leave")
    shell.line("help read")
    shell.expect(r"usage: sj300 read")
    shell.line("exit")
    assert shell.wait() == 0


def test_commands_on_a_pipe_run_without_a_prompt(history: Path) -> None:
    commands = "freq 40 -n 2\nread F001 -n 2 --json\nbogus\nstatus -n 2 --json\n"
    done = _shell_on_a_pipe("shell", "--url", URL, commands=commands, history=history)
    assert done.returncode == 1, done.stderr  # bogus failed
    assert PROMPT not in done.stdout
    assert '"value": 40.0' in done.stdout
    assert done.stderr.splitlines() == ["sj300 shell: error: no command 'bogus' (help lists them)"]


@pytest.mark.parametrize(
    ("commands", "status"),
    [
        pytest.param("read F001 -n 1\nexit\n", 0, id="all-succeed"),
        pytest.param("read F01\nread F001 -n 1\n", 1, id="usage-error"),  # 2 on its own
        pytest.param("read F001 -n 9\nread F001 -n 1\n", 1, id="nobody-answers"),
        pytest.param('read "F001\nread F001 -n 1\nexit\n', 1, id="refused-by-the-shell"),
        pytest.param("help bogus\nread F001 -n 1\n", 1, id="help-of-no-command"),
    ],
)
def test_a_scripted_session_exits_1_when_a_line_failed(
    commands: str, status: int, history: Path
) -> None:
    done = _shell_on_a_pipe("shell", "--url", URL, commands=commands, history=history)
    assert done.returncode == status, done.stderr
    assert re.search(r"F001 +output frequency setting", done.stdout)  # the lines after ran
    assert "Traceback" not in done.stderr
    assert len(done.stderr.splitlines()) == status  # each failure is one line


def test_an_interactive_session_exits_0_after_a_failed_command(shell: Terminal) -> None:
    shell.line("read F01")
    shell.expect(r"sj300 read: error: argument CODE")
    shell.line("exit")
    assert shell.wait() == 0


def _shell_on_a_pipe(*args: str, commands: str, history: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "sj300_async", *args],
        input=commands,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        env=_env(history),
        check=False,
    )


def test_global_options_of_the_shell_hold_for_its_commands(history: Path) -> None:
    commands = (
        "write F002 12.5 -n 3\n"  # --sim given to the shell: a command changing drives runs
        "read F002 -n 3\n"  # --json given to the shell
        "monitor --count 1 --nodes 3\n"  # the session's drives, not monitor's demo
        "status -n 3 --sim\n"  # the session's bus is a simulator: agrees
        "status -n 3 --retries 0\n"  # the session's bus has other retries: refused
        "--url tcp://127.0.0.1:1 status\n"  # another bus, before the command too
    )
    done = _shell_on_a_pipe("--sim", "--json", "shell", commands=commands, history=history)
    assert done.returncode == 1, done.stderr  # the two refused
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert [line.get("node") for line in lines] == [3, 3, 3, 3]
    assert lines[1]["parameters"][0]["value"] == 12.5
    assert lines[2]["parameters"]["F001"] is not None
    assert "simulated" not in lines[1]
    errors = done.stderr.splitlines()
    assert len(errors) == 2, done.stderr
    assert errors[0].startswith("sj300 status: error: --retries belongs to the session")
    assert errors[1].startswith("sj300 status: error: --url belongs to the session")


@pytest.mark.parametrize("protocol", ["sj300", "fr700"])
def test_every_code_completion_offers_is_one_read_takes(protocol: str) -> None:
    # Issue 27: `read Pr.` offered codes that `read Pr.1` then refused.
    profile = get_profile(protocol)
    parser = build_parser()
    completer = _Completer(parser, _subcommands(parser), list(profile.parameters.codes()))
    prefix = "Pr." if protocol == "fr700" else "F"
    offered = completer.candidates("read ", prefix)
    assert len(offered) >= 4, offered
    for code in offered:
        assert parameter_target(profile, code) == (code, profile.parameters.spec(code)), code


def test_completion_candidates() -> None:
    parser = build_parser()
    commands = _subcommands(parser)
    sj300 = _Completer(parser, commands, ["F001", "F002", "A001"])
    assert sj300.candidates("", "sta") == ["status"]
    assert sj300.candidates("", "e") == ["exit"]
    assert sj300.candidates("help ", "tr") == ["trips"]
    assert sj300.candidates("read ", "f") == ["F001", "F002"]
    assert sj300.candidates("write ", "A") == ["A001"]
    assert sj300.candidates("read F001 ", "--n") == ["--node"]
    assert sj300.candidates("run ", "") == ["forward", "reverse"]
    assert sj300.candidates("params ", "b") == ["backup"]
    assert sj300.candidates("params backup --codes ", "F") == ["F001", "F002"]
    assert sj300.candidates("status ", "F") == []
    assert sj300.candidates("nothing ", "") == []
    fr700 = _Completer(parser, commands, ["Pr.1", "Pr.7", "Pr.79"])
    assert fr700.candidates("read ", "pr.7") == ["Pr.7", "Pr.79"]
