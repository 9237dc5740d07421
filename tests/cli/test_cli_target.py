"""Which bus a command runs on when none is named: refused, or simulated and saying so.

A command that changes drives needs ``--url``, ``SJ300_URL`` or ``--sim``;
without them it exits 2 with one line and sends nothing. A read-only
command runs on the in-memory simulator, with a note on stderr and
``"simulated": true`` in its JSON object.
"""

from __future__ import annotations

import asyncio
import contextvars
import json
from pathlib import Path

import pytest

from sj300_async.cli._common import CHANGES_DRIVES
from sj300_async.cli._output import print_json, simulated_output

from .clirun import TcpSim, sj300

NOTE = "note: no --url given: these are simulated drives (sim://?nodes=1-8)"

#: Every command that changes a drive, with arguments that are otherwise complete.
CHANGING: dict[str, tuple[str, ...]] = {
    "run": ("run", "reverse"),
    "stop": ("stop",),
    "stop --all": ("stop", "--all"),
    "freq": ("freq", "30"),
    "write": ("write", "F002", "5"),
    "reset": ("reset",),
    "params restore": ("params", "restore", "SNAPSHOT"),
}


@pytest.fixture
async def snapshot(tcp_sim: TcpSim, tmp_path: Path) -> Path:
    """A backup of node 1 of the TCP simulator (the file names that bus's URL)."""
    file = tmp_path / "node1.json"
    result = await sj300("params", "backup", str(file), "--url", tcp_sim.url)
    assert result.code == 0, result.err
    return file


def test_the_commands_that_change_drives_are_declared_in_one_place() -> None:
    assert {"run", "stop", "freq", "write", "params restore", "reset"} <= CHANGES_DRIVES


@pytest.mark.parametrize("name", list(CHANGING))
async def test_a_command_that_changes_drives_needs_a_bus(
    name: str, snapshot: Path, tcp_sim: TcpSim
) -> None:
    args = [str(snapshot) if a == "SNAPSHOT" else a for a in CHANGING[name]]
    requests = tcp_sim.bus.stats.requests
    result = await sj300(*args, "--trace")  # a frame sent would show as a trace line
    command = name.removesuffix(" --all")
    result.assert_one_line_error(
        2, f"sj300 {command}: error: {command} changes drives", "--url", "$SJ300_URL", "--sim"
    )
    assert result.out == ""
    # The snapshot names the TCP simulator: restore does not go there on its own.
    assert tcp_sim.bus.stats.requests == requests


async def test_an_empty_sj300_url_names_no_bus() -> None:
    result = await sj300("freq", "30", env_url="")
    result.assert_one_line_error(2, "freq changes drives")


async def test_sim_names_the_simulator_on_either_side_of_the_command() -> None:
    after, before = await asyncio.gather(
        sj300("run", "reverse", "--sim"), sj300("--sim", "run", "reverse", "-n", "3")
    )
    assert (after.code, after.out, after.err) == (0, "node 01: run reverse\n", "")
    assert (before.code, before.out, before.err) == (0, "node 03: run reverse\n", "")


async def test_sj300_url_names_the_bus(tcp_sim: TcpSim) -> None:
    result = await sj300("freq", "12.5", "-n", "2", env_url=tcp_sim.url)
    assert (result.code, result.err) == (0, "")
    assert tcp_sim.bus.drives[2].parameters["F001"] == 1250


async def test_sim_wins_over_sj300_url_and_refuses_url(tcp_sim: TcpSim) -> None:
    requests = tcp_sim.bus.stats.requests
    result = await sj300("stop", "--sim", env_url=tcp_sim.url)
    assert (result.code, result.out, result.err) == (0, "node 01: stop\n", "")
    assert tcp_sim.bus.stats.requests == requests
    both = await sj300("status", "--sim", "--url", tcp_sim.url)
    both.assert_one_line_error(2, "give --url or --sim, not both")


async def test_a_read_on_the_implicit_simulator_says_so() -> None:
    text, as_json = await asyncio.gather(sj300("status"), sj300("status", "-n", "2", "--json"))
    assert text.code == 0, text.err
    assert text.err == f"sj300 status: {NOTE}\n"
    assert text.out.startswith("node 01\n")
    assert as_json.err == f"sj300 status: {NOTE}\n"
    data = as_json.json()
    assert data["node"] == 2
    assert data["simulated"] is True
    assert list(data)[-1] == "simulated"


@pytest.mark.parametrize(
    "args",
    [
        ("read", "F002", "--json"),
        ("trips", "--json"),
        ("scan", "--nodes", "1-2", "--json"),
        ("monitor", "--json", "--count", "1", "--interval", "0.05"),
    ],
    ids=lambda args: args[0],
)
async def test_every_read_only_command_marks_its_json_objects(args: tuple[str, ...]) -> None:
    result = await sj300(*args)
    assert result.code == 0, result.err
    assert result.err.splitlines()[0] == f"sj300 {args[0]}: {NOTE}"  # scan's progress follows
    documents = result.json_lines()
    assert documents
    assert all(isinstance(d, dict) and d["simulated"] is True for d in documents)


async def test_params_backup_and_diff_on_the_implicit_simulator(tmp_path: Path) -> None:
    file = tmp_path / "b.json"
    backup = await sj300("params", "backup", str(file), "--codes", "F002,A004", "--json")
    assert backup.code == 0, backup.err
    assert backup.err == f"sj300 params backup: {NOTE}\n"
    assert backup.json()["simulated"] is True
    diff = await sj300("params", "diff", str(file))
    assert diff.code == 0, diff.err
    assert diff.err == f"sj300 params diff: {NOTE}\n"


async def test_a_named_simulator_is_not_marked() -> None:
    results = await asyncio.gather(
        sj300("status", "--json", "--sim"),
        sj300("status", "--json", "--url", "sim://?nodes=1"),
        sj300("status", "--json", env_url="sim://?nodes=1"),
    )
    for result in results:
        assert (result.code, result.err) == (0, "")
        assert "simulated" not in result.json()


async def test_a_failure_on_the_implicit_simulator_follows_the_note() -> None:
    result = await sj300("status", "-n", "12", "--timeout", "0.05")
    assert result.code == 1
    note, error = result.err.splitlines()
    assert note == f"sj300 status: {NOTE}"
    assert error.startswith("sj300 status: error: node 12 did not answer")


async def test_the_monitor_demo_is_marked_simulated() -> None:
    result = await sj300("monitor", "--count", "1", "--interval", "0.05")
    assert result.code == 0, result.err
    assert result.err == f"sj300 monitor: {NOTE}\n"
    lines = result.out.splitlines()
    assert lines
    assert all(" node 0" in line for line in lines), lines


def test_print_json_marks_objects_only(capsys: pytest.CaptureFixture[str]) -> None:
    def simulated() -> None:
        simulated_output.set(True)
        print_json({"node": 1})
        print_json([{"node": 1}, {"node": 2}])  # a list stays a list, its items untouched

    contextvars.copy_context().run(simulated)
    print_json({"node": 1})  # outside that command's context: not marked
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert lines == [{"node": 1, "simulated": True}, [{"node": 1}, {"node": 2}], {"node": 1}]
