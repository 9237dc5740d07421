"""``sj300 gateway --opcua URL`` as a user runs it: a subprocess, a client, SIGTERM."""

from __future__ import annotations

import asyncio
import hashlib
import re
import signal
import sys
from pathlib import Path

from asyncua import ua
from cli.clirun import TIMEOUT, Result, cli_env, sj300

from sj300_async.cli._install import gateway_install_command

from .conftest import NAMESPACE, Pair, connected

_ANNOUNCE = re.compile(
    r"opcua on (opc\.tcp://127\.0\.0\.1:\d+) \(Basic256Sha256_SignAndEncrypt, "
    r"Basic256Sha256_Sign\); generated (\S+) \(SHA-1 ([0-9a-f]{40})\)"
)


async def test_the_flag_serves_read_only_drives_with_a_generated_certificate(
    tmp_path: Path, client_pair: Pair
) -> None:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sj300_async", "gateway", "--url", "sim://?nodes=1-2",
        "--nodes", "1-2", "--interval", "0.1", "--id", "gw1",
        "--opcua", "opc.tcp://127.0.0.1:0",
        stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE, env=cli_env(), cwd=tmp_path,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        async with asyncio.timeout(TIMEOUT):
            line = (await proc.stdout.readline()).decode().strip()
        announced = _ANNOUNCE.fullmatch(line)
        assert announced, line
        url, certificate, thumbprint = announced.groups()
        # Beside the working directory, as the flags-only case says.
        assert (tmp_path / certificate).resolve() == (tmp_path / "opcua" / "cert.der").resolve()
        async with connected(url, pair=client_pair) as client:
            ns = await client.get_namespace_index(NAMESPACE)
            assert await client.get_node(ua.NodeId("line1/Drive1/Line", ns)).read_value() == (
                "line1"
            )
            async with asyncio.timeout(TIMEOUT):
                while not await client.get_node(ua.NodeId("line1/Drive2/Online", ns)).read_value():
                    await asyncio.sleep(0.05)
            drive = client.get_node(ua.NodeId("line1/Drive1", ns))
            names = {(await c.read_browse_name()).Name for c in await drive.get_children()}
            assert "Stop" not in names  # read-only: no method at all
        proc.send_signal(signal.SIGTERM)
        async with asyncio.timeout(TIMEOUT):
            _, err = await proc.communicate()
        assert proc.returncode == 0, err.decode()
        der = (tmp_path / certificate).read_bytes()
        assert hashlib.sha1(der).hexdigest() == thumbprint  # what a client shows to trust
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_a_bad_endpoint_is_one_line() -> None:
    result = await sj300(
        "gateway", "--url", "sim://?nodes=1", "--nodes", "1", "--opcua", "http://x:1"
    )
    result.assert_one_line_error(2, "--opcua: expected opc.tcp://HOST:PORT, got 'http://x:1'")
    assert result.out == ""


async def test_without_asyncua_the_opcua_extra_is_named() -> None:
    args = ["gateway", "--url", "sim://?nodes=1", "--nodes", "1", "--opcua", "opc.tcp://h:1"]
    code = (
        "import sys; sys.modules['asyncua'] = None; from sj300_async.cli import main; "
        f"sys.exit(main({args!r}))"
    )
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-c", code, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode is not None
    result = Result(proc.returncode, out.decode(), err.decode())
    result.assert_one_line_error(2, "needs the opcua extra (asyncua is missing): ")
    assert result.err.endswith(f": {gateway_install_command(extra='opcua')}\n"), result.err
