"""A serial port that refuses the line settings: one line with the hint, never a traceback.

Linux pseudo-terminals refuse parity (``tcsetattr`` fails with EINVAL, which
pyserial lets through as ``termios.error``, not an OSError): a real pty
stands for the USB adapters that do the same.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest

from sj300_async.transports import serial_connector
from sj300_async.transports._serial import SerialSettingsError
from sj300_async.wire import LineSettings

from .clirun import TIMEOUT, cli_env, sj300

termios = pytest.importorskip("termios")

HINT = "a pseudo-terminal or some USB adapters do not support parity or 7 data bits"


def _pty_refuses_parity() -> bool:
    master, slave = os.openpty()
    try:
        attributes = termios.tcgetattr(slave)
        attributes[2] |= termios.PARENB
        termios.tcsetattr(slave, termios.TCSANOW, attributes)
    except termios.error:
        return True
    finally:
        os.close(slave)
        os.close(master)
    return False


pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or not _pty_refuses_parity(),
    reason="needs pseudo-terminals that refuse parity (Linux)",
)


@pytest.fixture
def pty_path() -> Iterator[str]:
    """The path of a fresh pseudo-terminal (both ends held open by the test)."""
    master, slave = os.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(slave)
        os.close(master)


@pytest.fixture
async def simulated_pty() -> AsyncIterator[str]:
    """``sj300 simulate --pty`` in a subprocess: the path of its pseudo-terminal."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "simulate",
        "--pty",
        "--nodes",
        "1-2",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL,
        env=cli_env(),
    )
    try:
        assert proc.stdout is not None
        line = await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)
        assert line.startswith(b"listening on /dev/"), line
        yield line.decode().removeprefix("listening on ").strip()
    finally:
        if proc.returncode is None:
            proc.terminate()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(proc.wait(), TIMEOUT)
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_parity_on_a_pty_is_one_line_with_the_hint(pty_path: str) -> None:
    after, before = await asyncio.gather(
        sj300("status", "--url", pty_path, "--parity", "E"),
        sj300("--parity", "E", "--url", pty_path, "status"),
    )
    for result in (after, before):
        result.assert_one_line_error(
            1,
            f"sj300 status: error: serial port {pty_path} refuses 19200 8E1: ",
            "Invalid argument (errno 22)",
            HINT,
            "docs/guide/troubleshooting.md",
        )


async def test_the_simulators_pty_answers_8n1_and_refuses_7_data_bits(simulated_pty: str) -> None:
    fine = await sj300("status", "-n", "2", "--url", simulated_pty, "--json")
    assert fine.code == 0, fine.err
    assert fine.json()["node"] == 2
    refused = await sj300("status", "--url", simulated_pty, "--bytesize", "7")
    refused.assert_one_line_error(1, f"serial port {simulated_pty} refuses 19200 7N1", HINT)


async def test_the_refused_port_is_closed_again(pty_path: str) -> None:
    fds = Path("/proc/self/fd")
    before = len(list(fds.iterdir()))
    connect = serial_connector(pty_path, LineSettings.parse(19200, 8, "O", 1))
    for _ in range(3):  # a reconnecting bus tries again and again
        with pytest.raises(SerialSettingsError, match="refuses 19200 8O1") as refused:
            await connect(asyncio.Protocol)
        assert isinstance(refused.value.__cause__, termios.error)
    assert len(list(fds.iterdir())) == before


def test_a_termios_error_from_anywhere_is_one_line_with_the_hint() -> None:
    from sj300_async.cli import _Expected, _message

    error = termios.error(22, "Invalid argument")
    assert isinstance(error, _Expected)
    assert (
        _message(error)
        == f"Invalid argument (errno 22): {HINT} (see docs/guide/troubleshooting.md)"
    )
