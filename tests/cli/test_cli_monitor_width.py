"""``sj300 monitor``: columns that keep their width over a run (issue 27, item 8).

The plain lines and the live table keep their columns while drives trip
(with the longest trip meaning their protocol's profile has), go offline
and come back: on a bus of either protocol, and in the fleet view. The
table is rendered in-process with rich's console at fixed widths; one test
reads a running monitor's plain lines on a pipe.

Nothing sleeps for a state: the pollers' samples are taken until the board
knows it, the running monitor is read line by line.
"""

from __future__ import annotations

import asyncio
import re
import signal
import time
from typing import Any

import pytest
from rich.console import Console

import sj300_async as sj
from sj300_async.cli._board import Board
from sj300_async.cli._fit import STATE_WIDTH, clip
from sj300_async.cli._fleet import fleet_table, plain_line
from sj300_async.gateway.mqtt import Fleet, FleetUrl, StateMessage, Topics
from sj300_async.profiles import Trip, get_profile

from .clirun import TIMEOUT, TcpSim, running, sj300


def _state(gateway: str, node: int, *, online: bool = True) -> StateMessage:
    return StateMessage(
        gateway, "hall", node, "sj300", time.time(), online, 10.0, 1.0, 200.0, "forward",
        True, False, state="running",
    )  # fmt: skip


async def _stop(proc: asyncio.subprocess.Process) -> None:
    proc.send_signal(signal.SIGTERM)
    _, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 0, err


def _longest_trip(protocol: str) -> Trip:
    """The trip whose state text is the longest the protocol's profile can give."""
    return max(get_profile(protocol).trip_codes(), key=lambda trip: len(str(trip)))


def _render(board: Board, width: int) -> list[str]:
    console = Console(width=width, record=True, force_terminal=False, color_system=None)
    console.print(board.table(width))
    return console.export_text().splitlines()


@pytest.mark.parametrize("protocol", ["sj300", "fr700"])
async def test_the_columns_keep_their_width_while_drives_trip_and_go_offline(
    protocol: str,
) -> None:
    profile = get_profile(protocol)
    first = profile.node_range[0] or 1  # SJ300 from 1, FR-700 from 0 (1 here: alike)
    stopped, tripping, silent = first, first + 1, first + 2
    nodes = [stopped, tripping, silent]
    trip = _longest_trip(protocol)
    url = f"sim://?nodes={stopped}-{silent}"
    async with sj.open_bus(url, protocol=protocol, timeout=0.02, retries=0) as bus:
        sim = bus.simulator
        assert sim is not None
        setpoint = profile.setpoint_parameter
        poller = sj.Poller(interval_s=0.01, parameters=() if setpoint is None else (setpoint,))
        poller.add(bus, nodes)
        board = Board(bus, profile, nodes, demo=False)
        lines: list[str] = []
        frames: dict[int, list[list[str]]] = {80: [], 100: [], 160: []}

        def frame() -> None:
            for width, shown in frames.items():
                shown.append(_render(board, width))

        async def until(done: Any) -> None:
            async for sample in poller.samples():
                board.update(sample)
                lines.append(board.plain_line(sample))
                if done():
                    return

        async with poller:
            await until(lambda: len(lines) >= 3)  # all answering, stopped
            frame()
            sim.faults.silence(silent, True)
            sim.drives[tripping].trip(trip.number, now=asyncio.get_running_loop().time())
            await until(
                lambda: (
                    board.trips.get(tripping) is not None and not poller.health(bus, silent).online
                )
            )
            frame()
            sim.faults.silence(silent, False)
            await until(lambda: poller.health(bus, silent).online)
            frame()
        board.trips.close()

    # The plain lines: every column at the same place, the trip cut with … (an error follows
    # the columns, as long as it is).
    columns = [line.split("  error: ")[0] for line in lines]
    assert len({len(line) for line in columns}) == 1, columns
    assert len({line.index(" set ") for line in columns}) == 1
    state_text = f"tripped {trip}"
    assert len(state_text) > STATE_WIDTH  # the longest trip is cut
    assert any(clip(state_text, STATE_WIDTH) in line for line in lines)
    assert any("offline" in line and "error: " in line for line in lines)
    # The table: at each width, every frame as wide, its columns where they were.
    for width, shown in frames.items():
        headers = [next(ln for ln in f if ln.split()[:2] == ["node", "state"]) for f in shown]
        assert len({h.rstrip() for h in headers}) == 1, headers
        sizes = {len(ln) for f in shown for ln in f if re.match(r" +\d\d ", ln)}
        assert sizes == {len(headers[0])}, (width, sizes)
        assert len(headers[0]) <= width
    tripped_row = next(ln for ln in frames[160][1] if ln.split()[:1] == [f"{tripping:02d}"])
    assert "tripped " + trip.code in tripped_row
    assert "…" in tripped_row


async def test_a_bus_monitors_plain_lines_on_a_pipe_keep_their_columns(tcp_sim: TcpSim) -> None:
    loop = asyncio.get_running_loop()
    trip = _longest_trip("sj300")
    tcp_sim.bus.drives[2].trip(trip.number, now=loop.time())
    assert (await sj300("run", "forward", "-n", "1", "--url", tcp_sim.url)).code == 0
    args = ("--url", tcp_sim.url, "--nodes", "1-2,5", "--interval", "0.05", "--timeout", "0.3")
    cut = clip(f"tripped {trip}", STATE_WIDTH)
    lines: list[str] = []
    async with running("monitor", *args, "--retries", "0") as proc:
        assert proc.stdout is not None
        async with asyncio.timeout(TIMEOUT):
            while not (any(cut in ln for ln in lines) and any(" 05 offline" in ln for ln in lines)):
                line = await proc.stdout.readline()
                assert line, "the monitor ended early"
                lines.append(line.decode().rstrip("\n"))
        await _stop(proc)
    columns = [line.split("  error: ")[0] for line in lines]
    assert len({len(line) for line in columns}) == 1, columns


def _fleet_messages() -> list[StateMessage]:
    fr700 = _longest_trip("fr700")
    return [
        _state("gw-a", 1),
        StateMessage(
            "gw-a",
            "hall",
            2,
            "fr700",
            time.time() - 7200,
            True,
            0.0,
            0.0,
            0.0,
            direction="stop",
            running=False,
            tripped=True,
            trip=fr700.code,
            state="tripped",
            trip_meaning=fr700.meaning,
        ),
        _state("gw-b", 3, online=False),
        StateMessage("gw-b", "hall", 4, "sj300", time.time(), True),  # nothing read yet
    ]


def test_the_fleet_views_columns_keep_their_width() -> None:
    fleet = Fleet(FleetUrl("mqtt", "h", 1883))
    lines: list[str] = []
    frames: dict[int, list[list[str]]] = {80: [], 160: []}
    for message in _fleet_messages():
        topic = Topics(message.gateway).state(message.line, message.node)
        assert fleet.receive(topic, message.to_json()) == message
        lines.append(plain_line(fleet, message))
        for width, shown in frames.items():
            console = Console(width=width, record=True, force_terminal=False, color_system=None)
            console.print(fleet_table(fleet, width))
            shown.append(console.export_text().splitlines())
    fleet.receive(Topics("gw-b").availability, b"offline")  # gw-b's drives: offline (stale)
    lines += [plain_line(fleet, m) for m in fleet.drives]
    assert len({len(line) for line in lines}) == 1, lines
    assert any("…" in line and "E." in line for line in lines)
    assert any("offline (stale)" in line for line in lines)
    for width, shown in frames.items():
        headers = [next(ln for ln in f if ln.split()[:2] == ["gateway", "line"]) for f in shown]
        assert len({h.rstrip() for h in headers}) == 1, headers
        sizes = {len(ln) for f in shown for ln in f if ln.lstrip().startswith("gw-")}
        assert sizes == {len(headers[0])}, (width, sizes)
        assert len(headers[0]) <= width
