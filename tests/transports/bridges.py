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

__all__ = ["free_port", "socat_ser2net", "wait_for_path", "wait_for_port"]


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
async def socat_ser2net() -> AsyncIterator[tuple[str, int]]:
    """socat pty pair; ser2net serves end B on a TCP port: yields (end A's path, port)."""
    for tool in ("socat", "ser2net"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool} is not installed (.ci/run installs it)")
    with tempfile.TemporaryDirectory() as tmp:
        a, b = Path(tmp) / "sim", Path(tmp) / "bridge"
        socat = subprocess.Popen(
            ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
            stderr=subprocess.DEVNULL,
        )
        ser2net = None
        try:
            await wait_for_path(a)
            await wait_for_path(b)
            port = free_port()
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
            await wait_for_port(port)
            yield os.path.realpath(a), port
        finally:
            for proc in (ser2net, socat):
                if proc is not None:
                    proc.terminate()
                    try:
                        proc.wait(timeout=5)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()
