"""``sj300 gateway`` under systemd's ``Type=notify``: READY once it serves, the watchdog fed
from the loop, STOPPING on the way out.

The test plays systemd: it binds the datagram socket ``$NOTIFY_SOCKET`` names and reads
what the real command sends. The loop monitor's ping is checked on a loop the test stalls.
"""

from __future__ import annotations

import asyncio
import itertools
import os
import re
import signal
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli.clirun import TIMEOUT, running

from sj300_async.gateway import ServiceManager
from sj300_async.gateway._looplag import PROBE_S, LoopMonitor


@pytest.fixture
def notify_socket(tmp_path: Path) -> Iterator[socket.socket]:
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind(str(tmp_path / "notify"))
        sock.setblocking(False)
        yield sock


async def _next(sock: socket.socket) -> dict[str, str]:
    """The next datagram, as its KEY=VALUE fields."""
    loop = asyncio.get_running_loop()
    async with asyncio.timeout(TIMEOUT):
        data = await loop.sock_recv(sock, 4096)
    return dict(line.split("=", 1) for line in data.decode().splitlines())


async def test_ready_once_serving_then_pings_then_stopping(
    notify_socket: socket.socket, tmp_path: Path
) -> None:
    env = {"NOTIFY_SOCKET": str(tmp_path / "notify"), "WATCHDOG_USEC": "2000000"}
    args = ("gateway", "--url", "sim://?nodes=1-2", "--nodes", "1-2", "--modbus", "127.0.0.1:0")
    async with running(*args, extra_env=env) as proc:
        ready = await _next(notify_socket)
        assert ready["READY"] == "1"
        # Said once every northbound listens: the port it names takes a connection now.
        found = re.search(r"modbus on 127\.0\.0\.1:(\d+)", ready["STATUS"])
        assert found is not None, ready
        assert ready["STATUS"].startswith("1 line(s), 2 drive(s); modbus on 127.0.0.1:")
        _, writer = await asyncio.open_connection("127.0.0.1", int(found[1]))
        writer.close()
        # WatchdogSec 2 s: a ping each second, from the loop.
        pings = []
        for _ in range(3):
            assert await _next(notify_socket) == {"WATCHDOG": "1"}
            pings.append(time.monotonic())
        gaps = [later - earlier for earlier, later in itertools.pairwise(pings)]
        assert all(0.5 < gap < 1.9 for gap in gaps), gaps
        proc.send_signal(signal.SIGTERM)
        while (fields := await _next(notify_socket)) == {"WATCHDOG": "1"}:
            pass
        assert fields == {"STOPPING": "1", "STATUS": "stopping"}
        async with asyncio.timeout(TIMEOUT):
            assert await proc.wait() == 0


async def test_without_notify_socket_nothing_is_sent(
    notify_socket: socket.socket, tmp_path: Path
) -> None:
    """The same command with no NOTIFY_SOCKET: serves, and the socket hears nothing."""
    args = ("gateway", "--url", "sim://?nodes=1", "--nodes", "1", "--modbus", "127.0.0.1:0")
    async with running(*args) as proc:
        assert proc.stdout is not None
        async with asyncio.timeout(TIMEOUT):
            line = await proc.stdout.readline()
        assert line.startswith(b"modbus on 127.0.0.1:")
        proc.send_signal(signal.SIGTERM)
        async with asyncio.timeout(TIMEOUT):
            assert await proc.wait() == 0
    with pytest.raises(BlockingIOError):
        notify_socket.recv(4096)


def test_the_environment_read() -> None:
    pid = str(os.getpid())
    assert ServiceManager.from_environment({}) is None
    assert ServiceManager.from_environment({"NOTIFY_SOCKET": "relative"}) is None
    plain = ServiceManager.from_environment({"NOTIFY_SOCKET": "/run/x"})
    assert plain is not None
    assert (plain.watchdog_s, plain.ping_every_s) == (None, None)
    mine = ServiceManager.from_environment(
        {"NOTIFY_SOCKET": "@abstract", "WATCHDOG_USEC": "30000000", "WATCHDOG_PID": pid}
    )
    assert mine is not None
    assert (mine.watchdog_s, mine.ping_every_s) == (30.0, 15.0)
    # A watchdog meant for another process (a parent that exec'd us) is not ours.
    other = ServiceManager.from_environment(
        {"NOTIFY_SOCKET": "/run/x", "WATCHDOG_USEC": "30000000", "WATCHDOG_PID": "1"}
    )
    assert other is not None
    assert other.watchdog_s is None
    short = ServiceManager.from_environment({"NOTIFY_SOCKET": "/x", "WATCHDOG_USEC": "500000"})
    assert short is not None
    assert short.ping_every_s == 1.0


def test_an_abstract_socket_is_reached() -> None:
    name = f"sj300-test-{os.getpid()}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind("\0" + name)
        manager = ServiceManager(f"@{name}")
        assert manager.ready("serving\nthings")
        assert sock.recv(4096) == b"READY=1\nSTATUS=serving things"


def test_a_socket_that_is_gone_is_counted_not_raised(tmp_path: Path) -> None:
    manager = ServiceManager(str(tmp_path / "nobody"))
    assert not manager.alive()
    assert (manager.sent, manager.failed) == (0, 1)


async def test_a_stalled_loop_sends_no_ping_until_it_runs_again() -> None:
    """The ping rides the lag probe: while the loop is stuck none is sent, and the first
    turn after it sends one (late, as systemd must see it)."""
    pings: list[float] = []
    monitor = LoopMonitor()
    monitor.start()
    try:
        monitor.keep_alive(lambda: pings.append(time.monotonic()), 0.2)
        deadline = time.monotonic() + 5.0
        while len(pings) < 2 and time.monotonic() < deadline:
            await asyncio.sleep(PROBE_S)
        assert len(pings) >= 2
        stall_began = time.monotonic()
        time.sleep(1.0)  # the stall under test: the loop cannot run anything
        count = len(pings)
        while len(pings) == count and time.monotonic() < deadline:
            await asyncio.sleep(PROBE_S)
        assert len(pings) == count + 1
        assert pings[-1] - stall_began >= 1.0  # nothing during the stall
        assert monitor.since(0).max_s >= 0.9  # and the lag measure saw the same stall
    finally:
        monitor.stop()
