"""Safe defaults: a simulator is reachable from this machine only, unless told otherwise.

A drive simulator on the plant network answers anyone who asks, and looks
like a drive. So ``serve_tcp`` and ``sj300 simulate`` bind to loopback by
default; another address is an explicit choice, and the CLI warns about it.
(The read-only bus, the other safety option, is in test_rel_bad_input.py.)
"""

from __future__ import annotations

import inspect
import ipaddress
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

ROOT = Path(__file__).parent.parent.parent


def _is_loopback(host: str) -> bool:
    return ipaddress.ip_address(host).is_loopback


async def test_serve_tcp_binds_to_loopback_by_default() -> None:
    assert inspect.signature(serve_tcp).parameters["host"].default == "127.0.0.1"
    async with await serve_tcp(SimulatedBus([1])) as server:
        assert _is_loopback(server.host)
        assert server.sockets
        for sock in server.sockets:
            assert _is_loopback(sock.getsockname()[0])  # type: ignore[attr-defined]


def _simulate(*args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "sj300_async", "simulate", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _listening_line(proc: subprocess.Popen[str]) -> tuple[str, int]:
    assert proc.stdout is not None
    line = proc.stdout.readline()
    match = re.fullmatch(r"listening on tcp://(.+):(\d+)\n", line)
    assert match, f"unexpected first line {line!r}"
    return match.group(1), int(match.group(2))


def _stop(proc: subprocess.Popen[str]) -> str:
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    assert proc.returncode == 130, err  # Ctrl-C, as every command
    return err


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


@pytest.mark.parametrize("listen", [None, "tcp://:0"], ids=["no --listen", "--listen tcp://:0"])
def test_cli_simulate_listens_on_loopback_by_default(listen: str | None) -> None:
    if listen is None and not _port_free(4001):
        # Something else holds the default port: the simulator must say so in one
        # line and exit 2 (the behaviour under test then is the refusal, not a skip).
        busy = _simulate()
        _, err = busy.communicate(timeout=10)
        assert busy.returncode == 2, err
        assert "Traceback" not in err
        assert len(err.strip().splitlines()) == 1
        return
    proc = _simulate(*(["--listen", listen] if listen else []))
    try:
        host, port = _listening_line(proc)
        assert _is_loopback(host)
        if listen is None:
            assert port == 4001
        err = _stop(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert "reachable from the network" not in err


def test_cli_simulate_warns_when_told_to_listen_beyond_loopback() -> None:
    proc = _simulate("--listen", "tcp://0.0.0.0:0")
    try:
        host, _ = _listening_line(proc)
        assert host == "0.0.0.0"
        err = _stop(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert "reachable from the network" in err
