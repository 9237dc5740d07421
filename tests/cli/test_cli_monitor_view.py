"""``sj300 monitor`` as a person reads it: 80 columns, human states, trips, offline, cycles, Ctrl-C.

Through the real entry point (a subprocess; a pseudo-terminal for the live
table) against the TCP simulator, whose drives the tests trip and silence
with the simulator's fault hooks; one test renders the table in-process
with rich's console at a fixed width.
"""

from __future__ import annotations

import asyncio
import re
import signal
import sys

import pytest
from rich.console import Console

import sj300_async as sj
from sj300_async.cli._board import Board
from sj300_async.profiles import get_profile

from .clirun import TIMEOUT, TcpSim, cli_env, sj300, sj300_on_terminal

#: A row of the compact table (below 100 columns): node, state, set Hz, out Hz, A, V, link.
_COMPACT_ROW = re.compile(
    r" +(?P<node>\d\d) +(?P<state>\S.*?) +(?P<set>-|\d+\.\d\d) +(?P<out>-|\d+\.\d\d)"
    r" +(-|\d+\.\d) +(-|\d+\.\d) +(?P<link>online|offline) *"
)
#: What a state may read (never the manual's "on stopping" nor "trip / stop").
_HUMAN_STATE = re.compile(
    r"-|stopped|stopping|running|accelerating|decelerating|starting|reversing"
    r"|tripped( E\d\d .+)?"
)
_PLAIN = re.compile(r"\S+ node (?P<node>\d\d) (?P<link>online |offline) (?P<state>.+?) +set ")


def _now() -> float:
    return asyncio.get_running_loop().time()


def _plain(out: str) -> list[re.Match[str]]:
    matches = [_PLAIN.match(line) for line in out.splitlines()]
    assert all(matches), out
    return [m for m in matches if m is not None]


async def test_at_80_columns_nothing_is_cut_in_the_node_and_frequency_columns(
    tcp_sim: TcpSim,
) -> None:
    now = _now()
    tcp_sim.bus.drives[1].trip(1, now=now)  # "tripped E01 over-current at constant speed"
    tcp_sim.bus.drives[3].set_parameter("F001", 4500)
    url_args = ("--url", tcp_sim.url, "--nodes", "1-4", "--interval", "0.05")
    # --count waits for the reads beside the poll (the set frequency): a fixed duration
    # missed it on a loaded machine (the last frame showed "-" for 45.00).
    result = await sj300_on_terminal("monitor", *url_args, "--count", "3", columns=80)
    assert result.code == 0, result.out
    # (A frame's last line and the next frame's first share a line once the cursor
    # movements are stripped: the rows and rules are what is measured.)
    lines = result.out.splitlines()
    rules = [line for line in lines if line.strip() and set(line.strip()) == {"─"}]
    assert rules
    assert all(len(rule) <= 80 for rule in rules)
    headers = [line.split() for line in lines if line.split()[:2] == ["node", "state"]]
    assert headers
    assert all(h == ["node", "state", "set", "Hz", "out", "Hz", "A", "V", "link"] for h in headers)
    rows = [m for m in (_COMPACT_ROW.fullmatch(line) for line in lines) if m is not None]
    assert {m["node"] for m in rows} == {"01", "02", "03", "04"}
    for row in rows:
        assert len(row[0]) <= 80
        assert "…" not in row["node"] + row["set"] + row["out"]
        assert _HUMAN_STATE.fullmatch(row["state"].rstrip("…")) or row["state"].endswith("…")
    final = {m["node"]: m for m in rows[-4:]}
    assert final["03"]["set"] == "45.00"
    # The trip is named; at 80 columns only the state column gives way.
    assert final["01"]["state"].startswith("tripped E01 over-current")
    assert final["02"]["state"] == "stopped"


@pytest.mark.parametrize("width", [80, 99, 100, 120, 160])
async def test_the_table_fits_the_console_width(width: int) -> None:
    async with sj.open_bus("sim://?nodes=1-3", timeout=0.02, retries=0) as bus:
        sim = bus.simulator
        assert sim is not None
        sim.drives[2].trip(36, now=_now())
        sim.faults.silence(3, True)
        poller = sj.Poller(interval_s=0.01, parameters=["F001"])
        poller.add(bus, [1, 2, 3])
        board = Board(bus, get_profile("sj300"), [1, 2, 3], demo=False)
        async with poller:
            async for sample in poller.samples():
                board.update(sample)
                if board.trips.get(2) is not None and sample.node == 3:
                    break
        console = Console(width=width, record=True, force_terminal=False, color_system=None)
        console.print(board.table(width))
    text = console.export_text()
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= width
    header = next(line for line in lines if line.split()[:2] == ["node", "state"])
    assert "set Hz" in header
    assert "out Hz" in header
    assert ("latency ms" in header) is (width >= 160)
    assert ("last error" in header) is (width >= 100)
    rows = {line.split()[0]: line for line in lines if re.match(r" +0[1-3] ", line)}
    assert set(rows) == {"01", "02", "03"}
    assert rows["01"].split()[1:4] == ["stopped", "0.00", "0.00"]
    assert "tripped E36 brake error" in rows["02"] or width < 100
    assert "…" not in rows["01"]
    assert rows["02"].split()[1] == "tripped"
    assert rows["03"].split()[1:4] == ["-", "-", "-"]  # never answered
    assert rows["03"].rstrip().endswith("offline")


async def test_states_read_as_a_person_would_and_a_trip_is_named(tcp_sim: TcpSim) -> None:
    now = _now()
    tcp_sim.bus.drives[2].trip(7, now=now)
    assert (await sj300("run", "forward", "-n", "1", "--url", tcp_sim.url)).code == 0
    args = ("--url", tcp_sim.url, "--nodes", "1-3", "--interval", "0.05")
    result = await sj300("monitor", *args, "--count", "8")
    assert result.code == 0, result.err
    lines = _plain(result.out)
    states = {n: {m["state"] for m in lines if m["node"] == n} for n in ("01", "02", "03")}
    assert states["01"] <= {"starting", "accelerating", "running"}, states
    assert states["03"] == {"stopped"}
    # Tripped from the first sample; named once the trip history is read.
    assert states["02"] <= {"tripped", "tripped E07 over-voltage"}, states
    assert "tripped E07 over-voltage" in states["02"]
    assert all(m["link"] == "online " for m in lines)


async def test_a_node_that_never_answered_is_offline(tcp_sim: TcpSim) -> None:
    # 0.3 s: node 04 answers in time on a loaded machine too (no retries here).
    args = ("--url", tcp_sim.url, "--nodes", "4-5", "--interval", "0.05", "--timeout", "0.3")
    result = await sj300("monitor", *args, "--retries", "0", "--count", "2")
    assert result.code == 0, result.err
    lines = _plain(result.out)
    assert [m["node"] for m in lines] == ["04", "05", "04", "05"]
    assert {m["link"] for m in lines if m["node"] == "04"} == {"online "}
    assert {m["link"] for m in lines if m["node"] == "05"} == {"offline"}
    data = await sj300("monitor", *args, "--retries", "0", "--count", "1", "--json")
    by_node = {s["node"]: s for s in data.json_lines()}
    assert (by_node[4]["online"], by_node[4]["state"]) == (True, "stopped")
    # Never answered: offline from its first poll, though polled in full until
    # offline_after failures.
    assert (by_node[5]["online"], by_node[5]["state"]) == (False, None)
    assert "node 05 did not answer" in by_node[5]["error"]


async def test_count_counts_cycles_not_samples(tcp_sim: TcpSim) -> None:
    args = ("--url", tcp_sim.url, "--nodes", "1-4", "--interval", "0.02", "--json")
    result = await sj300("monitor", *args, "--count", "3")
    assert result.code == 0, result.err
    assert [s["node"] for s in result.json_lines()] == [1, 2, 3, 4] * 3


async def test_a_cycle_does_not_wait_for_a_node_set_aside_as_offline(tcp_sim: TcpSim) -> None:
    # Node 9 is not there: polled in full three times, then only probed every 5 s.
    args = ("--url", tcp_sim.url, "--nodes", "1,9", "--interval", "0.02", "--json")
    result = await sj300("monitor", *args, "--timeout", "0.3", "--retries", "0", "--count", "6")
    assert result.code == 0, result.err
    nodes = [s["node"] for s in result.json_lines()]
    assert nodes.count(1) == 6
    assert nodes[:6] == [1, 9, 1, 9, 1, 9]
    assert nodes.count(9) == 3


async def test_on_a_real_bus_without_nodes_it_scans_first(tcp_sim: TcpSim) -> None:
    args = ("--url", tcp_sim.url, "--interval", "0.02", "--timeout", "0.05", "--json")
    result = await sj300("monitor", *args, "--count", "1", timeout=60)
    assert result.code == 0, result.err
    assert sorted(s["node"] for s in result.json_lines()) == [1, 2, 3, 4]
    assert "nodes answering: 1-4 (4 of 32)" in result.err


async def test_a_scan_finding_nobody_is_one_line_and_exit_1(tcp_sim: TcpSim) -> None:
    for node in range(1, 5):
        tcp_sim.bus.faults.silence(node, True)
    args = ("--url", tcp_sim.url, "--timeout", "0.05", "--count", "1")
    result = await sj300("monitor", *args, timeout=60)
    result.assert_one_line_error(1, "sj300 monitor: error: no node answers", "1-32")


async def test_ctrl_c_exits_130(tcp_sim: TcpSim) -> None:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "monitor",
        "--url",
        tcp_sim.url,
        "--nodes",
        "1-2",
        "--interval",
        "0.05",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=cli_env(),
    )
    try:
        assert proc.stdout is not None
        first = await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)
        assert _PLAIN.match(first.decode()), first
        proc.send_signal(signal.SIGINT)
        _out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert proc.returncode == 130
    assert "Traceback" not in err.decode()


async def test_help_says_ctrl_c_exits_130() -> None:
    result = await sj300("monitor", "--help")
    assert result.code == 0
    assert "Ctrl-C stops it (exit 130)" in " ".join(result.out.split())
