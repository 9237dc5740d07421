"""``sj300 trips --record DIR`` (issue 45): the trip black box without a gateway.

The command watches a simulated SJ300 line served over TCP by the test, which
trips a drive by the simulator's fault hook once the command has polled for a
while; the record lands in DIR as the gateway's would (a JSON and a pcapng), the
command prints it and ends after ``--count``.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

from waiting import wait_for

from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .clirun import finished, running, sj300


async def test_a_trip_is_recorded_into_the_directory(tmp_path: Path) -> None:
    sim = SimulatedBus(range(1, 3))
    server = await serve_tcp(sim)
    trips = tmp_path / "trips"
    async with server, running(
        "trips", "--record", str(trips), "--url", f"tcp://127.0.0.1:{server.port}",
        "--nodes", "1-2", "--interval", "0.05", "--before", "1", "--after", "0.5",
        "--count", "1", "--json",
    ) as proc:  # fmt: skip
        # A second of polls of both drives first: the trip has its seconds before it.
        await wait_for(lambda: sim.stats.requests >= 120, "the command's polls", timeout=30)
        assert sim.drives[2].trip(7, now=asyncio.get_running_loop().time())
        result = await finished(proc)
    assert result.code == 0, result.err
    (printed,) = [json.loads(line) for line in result.out.splitlines()]
    assert (printed["line"], printed["node"], printed["code"]) == ("line1", 2, "E07")
    record = json.loads((trips / f"{printed['id']}.json").read_text())
    assert (record["id"], record["trip"]["code"]) == (printed["id"], "E07")
    times = record["samples"]["time"]
    assert times[0] <= record["time"] - 0.8  # the second before it, at the poll's rate
    assert (trips / f"{printed['id']}.pcapng").read_bytes()[:4] == b"\x0a\x0d\x0d\x0a"


async def test_bad_recording_options_are_one_line_errors(tmp_path: Path) -> None:
    for options, fragment in (
        (("--count", "0"), "--count"),
        (("--before", "-1"), "--before"),
        (("--nodes", "x"), "nodes"),
    ):
        result = await sj300("trips", "--record", str(tmp_path), "--sim", *options)
        result.assert_one_line_error(2, fragment)
