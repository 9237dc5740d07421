"""``sj300 gateway`` under a descriptor limit of 128, with more idle sockets than that against it.

The issue (26): about 345 idle sockets against a limit of 256 took the whole
gateway down (Modbus, /healthz and the line's reconnect failed with EMFILE)
and asyncio logged 146,085 tracebacks in 30 s. With the listener's cap
(``max_connections``, 64 by default, below the limit), the newcomers are
accepted and closed at once, the lines keep polling, /metrics is served
throughout, and the Modbus port serves again as soon as the sockets close.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import resource
import signal
import socket
import sys
import textwrap
from collections.abc import AsyncIterator
from pathlib import Path

from cli.clirun import TIMEOUT, cli_env

from .test_gateway_cli import http_get, read_servers

#: The gateway's descriptor limit, and the idle sockets opened against its Modbus port.
NOFILE = 128
IDLE_SOCKETS = 200
#: The default cap of the Modbus listener.
CAP = 64
#: How soon the Modbus port must serve again once the idle sockets are closed.
RECOVER_WITHIN_S = 1.0
READ = bytes.fromhex("0001 0000 0006 01 03 0000 0002")  # unit 1: online, sample age


def _lower_nofile() -> None:  # runs in the child, before exec
    resource.setrlimit(resource.RLIMIT_NOFILE, (NOFILE, NOFILE))


@contextlib.asynccontextmanager
async def _gateway(config: Path) -> AsyncIterator[asyncio.subprocess.Process]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "gateway",
        "--config",
        str(config),
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=cli_env(),
        preexec_fn=_lower_nofile,
    )
    try:
        yield proc
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


def _metric(body: str, name: str, labels: str = "") -> float:
    found = re.search(rf"^{re.escape(name + labels)} (\S+)$", body, re.M)
    assert found, f"{name}{labels} not in /metrics"
    return float(found[1])


async def _scrape(port: int) -> str:
    status, body = await http_get(port, "/metrics")
    assert status == 200
    return body


async def _modbus_read(port: int) -> bytes | None:
    """The answer to READ on a new connection, None when the connection is refused or closed."""
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
    except OSError:
        return None
    try:
        writer.write(READ)
        await writer.drain()
        return await reader.readexactly(13)
    except (OSError, asyncio.IncompleteReadError):
        return None
    finally:
        writer.close()


async def test_a_gateway_over_its_descriptor_limit_keeps_polling_and_recovers(
    tmp_path: Path,
) -> None:
    assert resource.getrlimit(resource.RLIMIT_NOFILE)[0] > IDLE_SOCKETS + 100  # this process
    config = tmp_path / "gateway.toml"
    config.write_text(
        textwrap.dedent(
            """\
            [modbus]
            listen = "127.0.0.1:0"
            # every socket comes from 127.0.0.1: the whole cap open to one address
            max_connections_per_address = 64
            [metrics]
            listen = "127.0.0.1:0"
            [[lines]]
            name = "hall"
            url = "sim://?nodes=1-2"
            nodes = "1-2"
            interval_s = 0.05
            """
        )
    )
    loop = asyncio.get_running_loop()
    idle: list[socket.socket] = []
    async with _gateway(config) as proc:
        ports = await read_servers(proc, "modbus", "metrics")
        try:
            for _ in range(IDLE_SOCKETS):  # more than the gateway's descriptors
                sock = socket.socket()
                sock.setblocking(False)
                idle.append(sock)
                await loop.sock_connect(sock, ("127.0.0.1", ports["modbus"]))
            async with asyncio.timeout(TIMEOUT):
                while True:  # every newcomer past the cap accepted and closed
                    body = await _scrape(ports["metrics"])
                    if _metric(body, "sj300_modbus_connections_refused_total") >= (
                        IDLE_SOCKETS - CAP
                    ):
                        break
            assert _metric(body, "sj300_modbus_connections") == CAP
            # The line keeps polling: its request count goes on rising.
            before = _metric(body, "sj300_line_requests_total", '{line="hall"}')
            async with asyncio.timeout(TIMEOUT):
                while _metric(await _scrape(ports["metrics"]), "sj300_line_requests_total",
                              '{line="hall"}') < before + 10:  # fmt: skip
                    pass
            assert (await http_get(ports["metrics"], "/healthz")) == (200, "ok\n")
        finally:
            for sock in idle:
                sock.close()
        closed_at = loop.time()
        while (answer := await _modbus_read(ports["modbus"])) is None:
            assert loop.time() - closed_at < RECOVER_WITHIN_S, "Modbus not served again"
        recovered_s = loop.time() - closed_at
        assert answer[:11] == bytes.fromhex("0001 0000 0007 01 03 04 0001")  # online
        assert recovered_s < RECOVER_WITHIN_S
        proc.send_signal(signal.SIGTERM)
        async with asyncio.timeout(TIMEOUT):
            _out, err = await proc.communicate()
    log = err.decode()
    assert proc.returncode == 0, log
    assert "Traceback" not in log
    assert len(log.splitlines()) < 100, log
    assert "Too many open files" not in log, log
