"""``sj300 gateway --demo``: the workbench on simulated drives that move, in one command."""

from __future__ import annotations

import asyncio
import json

import aiohttp
from cli.clirun import TIMEOUT, sj300

from .test_gateway_cli import gateway_process, read_servers, stop


async def test_the_demo_serves_eight_drives_that_move() -> None:
    async with gateway_process("--demo", "--http", "127.0.0.1:0") as proc:
        port = (await read_servers(proc, "metrics"))["metrics"]
        base = f"http://127.0.0.1:{port}/api/v1"
        running: set[int] = set()
        async with aiohttp.ClientSession() as session:
            async with session.get(f"{base}/drives") as response:
                drives = await response.json()
            assert [d["node"] for d in drives] == list(range(1, 9))
            # The demo starts the drives: the event stream shows them running.
            async with asyncio.timeout(TIMEOUT), session.get(f"{base}/events") as stream:
                event = ""
                async for raw in stream.content:
                    line = raw.decode().strip()
                    if line.startswith("event: "):
                        event = line.removeprefix("event: ")
                    elif line.startswith("data: ") and event == "drive":
                        drive = json.loads(line.removeprefix("data: "))
                        if drive["running"] and (drive["output_frequency_hz"] or 0) > 0:
                            running.add(drive["node"])
                        if len(running) >= 3:
                            break
            async with session.get(f"{base}/gateway") as response:
                assert (await response.json())["writes"] is False  # the demo grants none
        result = await stop(proc)
    assert result.code == 0, result
    assert "Traceback" not in result.err


async def test_the_demo_brings_its_own_line() -> None:
    result = await sj300("gateway", "--demo", "--url", "sim://?nodes=1", "--http", ":0")
    result.assert_one_line_error(2)
    assert "--demo serves its own simulated line" in result.err
