"""The transport contract fixture: the same simulated drives behind every transport.

``line`` yields an ``open()`` factory; ``async with line.open() as bus`` gives
a bus connected through the transport under test to a simulator whose
drives the test can inspect (``line.sim``). Transports:

- loopback: ``sim://`` (the in-memory transport and simulator endpoint)
- tcp:      raw TCP to the simulator's TCP server
- pty:      the library's serial transport (pyserial) on a real pseudo-terminal
            served by the simulator (a Linux pty refuses parity: 8N1)
- ser2net:  a socat pty pair, the simulator on one end, ser2net exposing the
            other end on loopback TCP, the library's TCP transport in front
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

import sj300_async as sj
from sj300_async.simulator import open_pty_server, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

NODES = (1, 2, 3, 4)


@dataclass
class Line:
    kind: str
    sim: SimulatedBus
    url: str
    open: Callable[..., contextlib.AbstractAsyncContextManager[sj.Bus]]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _wait_for_port(port: int, timeout: float = 5.0) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        try:
            _, writer = await asyncio.open_connection("127.0.0.1", port)
        except OSError:
            if loop.time() > deadline:
                raise
            await asyncio.sleep(0.02)
        else:
            writer.close()
            await writer.wait_closed()
            return


async def _wait_for_path(path: Path, timeout: float = 5.0) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not path.exists():
        if loop.time() > deadline:
            raise TimeoutError(f"{path} did not appear")
        await asyncio.sleep(0.02)


@contextlib.asynccontextmanager
async def _ser2net_bridge(sim: SimulatedBus) -> AsyncIterator[str]:
    """socat pty pair; simulator on end A; ser2net serves end B on a TCP port."""
    for tool in ("socat", "ser2net"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool} is not installed (.ci/run installs it)")
    from sj300_async.simulator import serve_serial_device

    with tempfile.TemporaryDirectory() as tmp:
        a, b = Path(tmp) / "sim", Path(tmp) / "bridge"
        socat = subprocess.Popen(
            ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
            stderr=subprocess.DEVNULL,
        )
        ser2net = None
        try:
            await _wait_for_path(a)
            await _wait_for_path(b)
            port = _free_port()
            config = Path(tmp) / "ser2net.yaml"
            config.write_text(
                "%YAML 1.1\n---\n"
                "connection: &sim\n"
                f"  accepter: tcp,127.0.0.1,{port}\n"
                f"  connector: serialdev,{os.path.realpath(b)},19200n81,local\n"
                "  options:\n"
                "    kickolduser: true\n"
            )
            ser2net = subprocess.Popen(
                ["ser2net", "-n", "-d", "-c", str(config)],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            async with await serve_serial_device(sim, os.path.realpath(a)):
                await _wait_for_port(port)
                yield f"tcp://127.0.0.1:{port}?baudrate=19200"
        finally:
            for proc in (ser2net, socat):
                if proc is not None:
                    proc.terminate()
                    try:
                        proc.wait(timeout=5)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()


@pytest.fixture(params=["loopback", "tcp", "pty", "ser2net"])
async def line(request: pytest.FixtureRequest) -> AsyncIterator[Line]:
    kind = request.param
    async with contextlib.AsyncExitStack() as stack:
        sim = SimulatedBus(nodes=NODES)
        if kind == "loopback":
            url = "sim://"
        elif kind == "tcp":
            server = await stack.enter_async_context(await serve_tcp(sim))
            url = f"tcp://127.0.0.1:{server.port}"
        elif kind == "pty":
            pty = await stack.enter_async_context(await open_pty_server(sim))
            url = f"serial://{pty.path}?baudrate=19200"
        else:
            url = await stack.enter_async_context(_ser2net_bridge(sim))

        def open_line(**kwargs: object) -> contextlib.AbstractAsyncContextManager[sj.Bus]:
            if kind == "loopback":
                kwargs["simulator"] = sim
            else:
                kwargs.setdefault("timeout", 0.5)
            return sj.open_bus(url, **kwargs)  # type: ignore[arg-type]

        yield Line(kind, sim, url, open_line)
