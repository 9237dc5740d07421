"""Test-only plumbing for the transport tests: free ports, and the socat + ser2net bridge."""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import AsyncIterator
from pathlib import Path

__all__ = ["free_port", "ser2net", "socat_ser2net", "wait_for_path", "wait_for_port"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def wait_for_port(port: int, timeout: float = 5.0) -> None:
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


async def wait_for_path(path: Path, timeout: float = 5.0) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not path.exists():
        if loop.time() > deadline:
            raise TimeoutError(f"{path} did not appear")
        await asyncio.sleep(0.02)


@contextlib.asynccontextmanager
async def socat_ser2net(*, rfc2217: bool = False) -> AsyncIterator[tuple[str, int]]:
    """socat pty pair; ser2net serves end B on a TCP port: yields (end A's path, port).

    *rfc2217*: ser2net's accepter speaks telnet with RFC 2217 (``telnet(rfc2217)``)
    instead of passing raw bytes.
    """
    _require("socat")
    with tempfile.TemporaryDirectory() as tmp:
        a, b = Path(tmp) / "sim", Path(tmp) / "bridge"
        socat = subprocess.Popen(
            ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
            stderr=subprocess.DEVNULL,
        )
        try:
            await wait_for_path(a)
            await wait_for_path(b)
            async with ser2net(os.path.realpath(b), rfc2217=rfc2217) as port:
                yield os.path.realpath(a), port
        finally:
            _stop(socat)


@contextlib.asynccontextmanager
async def ser2net(device: str, *, rfc2217: bool = False) -> AsyncIterator[int]:
    """ser2net serving the terminal *device* on a free loopback port: yields the port.

    *rfc2217*: a ``telnet(rfc2217)`` accepter (the client sets the line), else raw TCP.
    """
    _require("ser2net")
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        accepter = f"telnet(rfc2217),tcp,127.0.0.1,{port}" if rfc2217 else f"tcp,127.0.0.1,{port}"
        config = Path(tmp) / "ser2net.yaml"
        config.write_text(
            "%YAML 1.1\n---\n"
            "connection: &sim\n"
            f"  accepter: {accepter}\n"
            f"  connector: serialdev,{device},19200n81,local\n"
            "  options:\n"
            "    kickolduser: true\n"
        )
        proc = subprocess.Popen(
            ["ser2net", "-n", "-d", "-c", str(config)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            await wait_for_port(port)
            yield port
        finally:
            _stop(proc)


def _require(tool: str) -> None:
    if shutil.which(tool) is None:
        raise RuntimeError(f"{tool} is not installed (.ci/run installs it)")


def _stop(proc: subprocess.Popen[bytes]) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
