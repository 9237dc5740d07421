"""Run the real ``sj300`` entry point as a user does: a subprocess, on a pipe or a terminal."""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import json
import os
import re
import signal
import socket
import struct
import sys
import termios
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

from waiting import wait_for

from sj300_async.simulator.sj300 import SimulatedBus

#: Generous per command: a cold interpreter start on a loaded CI machine.
TIMEOUT = 20.0

_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07")


@dataclass(frozen=True)
class TcpSim:
    """Simulated drives behind a TCP bridge (the ``tcp_sim`` fixture), and the bridge's URL."""

    bus: SimulatedBus
    url: str


@dataclass(frozen=True)
class Result:
    """What a finished command left behind."""

    code: int
    out: str
    err: str

    def json(self) -> Any:
        """stdout parsed as one JSON document."""
        return json.loads(self.out)

    def json_lines(self) -> list[Any]:
        """stdout parsed as JSON lines."""
        return [json.loads(line) for line in self.out.splitlines()]

    def assert_one_line_error(self, code: int, *fragments: str) -> None:
        """Exit status *code*, nothing on stdout, one ``sj300 ...: error:`` line on stderr."""
        assert self.code == code, (self.code, self.out, self.err)
        assert "Traceback" not in self.err, self.err
        lines = self.err.splitlines()
        assert len(lines) == 1, self.err
        assert re.match(r"sj300( [a-z ]+)?: error: ", lines[0]), lines[0]
        for fragment in fragments:
            assert fragment in lines[0], (fragment, lines[0])


def closed_port() -> int:
    """A local TCP port nobody listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


def cli_env(url: str | None = None) -> dict[str, str]:
    """The environment of a command: ours without SJ300_URL, or with it set to *url*."""
    env = {k: v for k, v in os.environ.items() if k != "SJ300_URL"}
    if url is not None:
        env["SJ300_URL"] = url
    return env


async def sj300(*args: str, env_url: str | None = None, timeout: float = TIMEOUT) -> Result:
    """Run ``python -m sj300_async ARGS`` with stdout and stderr on pipes."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        *args,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=cli_env(env_url),
    )
    try:
        out, err = await asyncio.wait_for(proc.communicate(), timeout)
    finally:
        await _reap(proc)
    assert proc.returncode is not None
    return Result(proc.returncode, out.decode(), err.decode())


@contextlib.asynccontextmanager
async def running(
    *args: str, extra_env: dict[str, str] | None = None
) -> AsyncIterator[asyncio.subprocess.Process]:
    """``python -m sj300_async ARGS`` left running: stdin empty, stdout and stderr on
    pipes, *extra_env* added to the environment; killed if it still runs at the end."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        *args,
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=cli_env() | (extra_env or {}),
    )
    try:
        yield proc
    finally:
        await _reap(proc)


async def finished(proc: asyncio.subprocess.Process, stdin: bytes | None = None) -> Result:
    """What *proc* left when it ended (given *stdin*), within :data:`TIMEOUT`; killed if not."""
    try:
        out, err = await asyncio.wait_for(proc.communicate(stdin), TIMEOUT)
    finally:
        await _reap(proc)
    assert proc.returncode is not None
    return Result(proc.returncode, out.decode(), err.decode())


async def _reap(proc: asyncio.subprocess.Process) -> None:
    """Kill *proc* if it still runs, and wait for it: no child outlives its test."""
    if proc.returncode is None:
        proc.kill()
        await proc.wait()


async def sj300_on_terminal(*args: str, timeout: float = TIMEOUT, columns: int = 160) -> Result:
    """Run ``python -m sj300_async ARGS`` with stdout and stderr on one pseudo-terminal.

    ``out`` holds everything the terminal showed, escape sequences removed; ``err`` is empty.
    """
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 50, columns, 0, 0))
    env = cli_env() | {"TERM": "xterm-256color", "COLUMNS": str(columns), "LINES": "50"}
    env.pop("NO_COLOR", None)
    try:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "sj300_async", *args, stdout=slave, stderr=slave, env=env
        )
    finally:
        os.close(slave)
    loop = asyncio.get_running_loop()
    chunks: list[bytes] = []
    done = asyncio.Event()

    def readable() -> None:
        try:
            data = os.read(master, 65536)
        except OSError:  # EIO: the last writer closed the terminal
            data = b""
        if data:
            chunks.append(data)
        else:
            loop.remove_reader(master)
            done.set()

    os.set_blocking(master, False)
    loop.add_reader(master, readable)
    try:
        async with asyncio.timeout(timeout):
            await done.wait()
            await proc.wait()
    finally:
        with contextlib.suppress(ValueError, OSError):
            loop.remove_reader(master)
        os.close(master)
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert proc.returncode is not None
    text = _ANSI.sub("", b"".join(chunks).decode(errors="replace")).replace("\r", "")
    return Result(proc.returncode, text, "")


async def interrupted_restore(
    *args: str, restoring: Callable[[], bool], stall: Callable[[], None]
) -> tuple[int, int]:
    """``sj300 params restore ARGS`` stopped with Ctrl-C while it writes: (written, total).

    Once *restoring* says a write landed, *stall* silences the drive (the next
    write waits for its answer: still writing) and SIGINT goes. Checks the
    exit status 130, nothing on stdout and the one line on stderr.
    """
    async with running("params", "restore", *args) as proc:
        await wait_for(restoring, "a parameter restored")
        stall()
        proc.send_signal(signal.SIGINT)
        out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 130
    assert out == b""
    lines = err.decode().splitlines()
    assert len(lines) == 1, lines
    said = re.fullmatch(
        r"sj300 params restore: interrupted after (\d+) of (\d+) parameters written; "
        r"the drive holds a mix of the file's values and its own",
        lines[0],
    )
    assert said, lines
    return int(said[1]), int(said[2])
