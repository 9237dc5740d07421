"""``sj300 params`` over the whole function-code table, through the real entry point.

Backups hold every catalogued code with its name, unit, value and raw value,
plus the node, the protocol and the time; restore checks the file's node and
protocol against the target; a missing directory is one line, exit 2; and a
full round trip runs against ``sj300 simulate`` as a separate process.
"""

from __future__ import annotations

import asyncio
import json
import re
import signal
import sys
from collections.abc import AsyncIterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from sj300_async import __version__
from sj300_async.sj300 import PARAMETERS

from .clirun import TIMEOUT, TcpSim, sj300, sj300_on_terminal
from .conftest import FAST_BAUD

#: The in-memory simulator, named: a command without a URL notes that its drives are simulated.
SIM = "sim://?nodes=1-8"

#: A few codes of every group (catalogue order), 2nd / 3rd motor copies and card codes among them.
CHANGES = {
    "F202": "12.5",
    "A342": "3.5",
    "A045": "90",
    "B083": "8.0",
    "B113": "380.0",
    "C044": "7.5",
    "H206": "120",
    "H024": "0.25",
    "P011": "4096",
    "P044": "2.5",
}


def entries(file: Path) -> list[dict[str, Any]]:
    """The ``parameters`` list of a version 2 backup."""
    data = json.loads(file.read_text())
    parameters: list[dict[str, Any]] = data["parameters"]
    return parameters


@pytest.fixture
async def simulate() -> AsyncIterator[str]:
    """``sj300 simulate`` on a free port (drives 1-3): yields its URL, SIGINT at the end."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "simulate",
        "--listen",
        "tcp://127.0.0.1:0",
        "--nodes",
        "1-3",
        "--baud",  # answers as fast as 115200 baud allows (the URL says so): see conftest.py
        str(FAST_BAUD),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)).decode()
        match = re.fullmatch(r"listening on (tcp://127\.0\.0\.1:\d+)\n", line)
        assert match, line
        yield f"{match[1]}?baudrate={FAST_BAUD}"
        proc.send_signal(signal.SIGINT)
        await asyncio.wait_for(proc.communicate(), TIMEOUT)
        assert proc.returncode == 130  # Ctrl-C
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_backup_holds_every_catalogued_code_with_its_unit(
    tcp_sim: TcpSim, tmp_path: Path
) -> None:
    file = tmp_path / "node3.json"
    before = datetime.now(UTC).replace(microsecond=0)
    result = await sj300("params", "backup", str(file), "-n", "3", "--url", tcp_sim.url)
    after = datetime.now(UTC)
    assert result.code == 0, result.err
    assert result.out == f"node 03: {len(PARAMETERS)} parameters saved to {file}\n"

    data = json.loads(file.read_text())
    assert (data["format"], data["version"], data["protocol"]) == ("sj300-params", 2, "sj300")
    assert (data["node"], data["url"]) == (3, tcp_sim.url)
    assert data["library_version"] == __version__
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", data["taken_at"])
    taken_at = datetime.fromisoformat(data["taken_at"])
    assert taken_at.utcoffset() == timedelta(0)
    assert before <= taken_at <= after

    drive = tcp_sim.bus.drives[3].parameters
    assert [p["code"] for p in data["parameters"]] == list(PARAMETERS)
    for entry in data["parameters"]:
        info = PARAMETERS[entry["code"]]
        assert entry == {
            "code": info.code,
            "name": info.name,
            "unit": info.unit,
            "value": info.from_raw(drive[info.code]),
            "raw": drive[info.code],
        }
    by_code = {p["code"]: p for p in data["parameters"]}
    assert (by_code["F002"]["value"], by_code["F002"]["unit"]) == (30.0, "s")
    assert (by_code["A204"]["value"], by_code["A204"]["raw"]) == (50.0, 500)
    assert by_code["H024"]["unit"] == "kg m2"


async def test_backup_shows_progress_on_a_terminal(tmp_path: Path) -> None:
    file = tmp_path / "b.json"
    result = await sj300_on_terminal("params", "backup", str(file), "--url", SIM)
    assert result.code == 0, result.out
    assert f"{len(PARAMETERS)}/{len(PARAMETERS)}" in result.out  # the bar reached the end
    assert result.out.endswith(f"node 01: {len(PARAMETERS)} parameters saved to {file}\n")


async def test_a_code_the_drive_refuses_is_absent_with_the_reason(tmp_path: Path) -> None:
    file = tmp_path / "some.json"
    result = await sj300("params", "backup", str(file), "--codes", "P099,B113", "--url", SIM)
    assert result.code == 0, result.err
    assert result.out.startswith("node 01: 1 parameters saved to ")
    assert result.out.rstrip().endswith("absent: P099")
    b113, p099 = entries(file)
    assert (b113["code"], b113["raw"], b113["unit"]) == ("B113", 0, "V")
    assert "absent" not in b113
    assert p099["code"] == "P099"
    assert (p099["raw"], p099["value"]) == (None, None)
    assert p099["absent"] == "NAK 16 (abnormal parameter code or value)"


async def test_restore_onto_another_node_needs_force(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "node1.json"
    url = ("--url", tcp_sim.url)
    tcp_sim.bus.drives[1].set_parameter("F202", 1234)
    tcp_sim.bus.drives[1].set_parameter("P044", 250)
    assert (await sj300("params", "backup", str(file), *url)).code == 0
    other = tcp_sim.bus.drives[2]
    untouched = dict(other.parameters)

    refused = await sj300("params", "restore", str(file), "-n", "2", *url)
    refused.assert_one_line_error(
        2, "sj300 params restore: error: ", "taken from node 01, not node 02", "--force"
    )
    assert dict(other.parameters) == untouched  # nothing was written

    forced = await sj300("params", "restore", str(file), "-n", "2", "--force", "--json", *url)
    assert forced.code == 0, forced.err
    assert forced.json()["mismatches"] == []
    assert (other.parameters["F202"], other.parameters["P044"]) == (1234, 250)
    assert other.parameters["C072"] == 2  # the node address is never restored

    same_node = await sj300("params", "restore", str(file), "-n", "1", *url)
    assert same_node.code == 0, same_node.err


async def test_a_file_of_another_protocol_is_never_restored(
    tcp_sim: TcpSim, tmp_path: Path
) -> None:
    file = tmp_path / "fr700.json"
    snapshot = {
        "format": "sj300-params",
        "version": 2,
        "protocol": "fr700",
        "node": 1,
        "taken_at": "2025-01-31T12:00:00Z",
        "parameters": [{"code": "7", "name": "acceleration time", "unit": "s", "raw": 50}],
    }
    file.write_text(json.dumps(snapshot))
    untouched = dict(tcp_sim.bus.drives[1].parameters)
    url = ("--url", tcp_sim.url)
    results = await asyncio.gather(
        sj300("params", "restore", str(file), *url),
        sj300("params", "restore", str(file), "--force", *url),
        sj300("params", "diff", str(file), *url),
    )
    for result, action in zip(results, ("restore", "restore", "diff"), strict=True):
        result.assert_one_line_error(
            2, f"sj300 params {action}: error: {file}: a backup of fr700 drives"
        )
    assert dict(tcp_sim.bus.drives[1].parameters) == untouched


async def test_a_missing_directory_is_one_line_and_exit_2(tcp_sim: TcpSim, tmp_path: Path) -> None:
    missing = tmp_path / "missing"
    not_a_directory = tmp_path / "file"
    not_a_directory.write_text("")
    url = ("--url", tcp_sim.url)
    backup, under_a_file, diff = await asyncio.gather(
        sj300("params", "backup", str(missing / "b.json"), *url),
        sj300("params", "backup", str(not_a_directory / "b.json"), *url),
        sj300("params", "diff", str(missing / "b.json"), *url),
    )
    backup.assert_one_line_error(
        2, f"sj300 params backup: error: {missing}: No such file or directory"
    )
    under_a_file.assert_one_line_error(2, f"{not_a_directory}: Not a directory")
    diff.assert_one_line_error(2, f"sj300 params diff: error: {missing / 'b.json'}: No such file")
    assert not missing.exists()


async def test_a_version_1_file_is_still_read(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "v1.json"
    snapshot = {
        "format": "sj300-params",
        "version": 1,
        "node": 4,
        "url": tcp_sim.url,
        "created": "2024-05-01T08:00:00+00:00",
        "parameters": {"F002": 3000, "B113": 0},
        "absent": ["P099"],
    }
    file.write_text(json.dumps(snapshot))
    result = await sj300("params", "diff", str(file), "--url", tcp_sim.url)
    assert (result.code, result.out) == (0, f"node 04 matches {file} (3 parameters)\n")


async def test_round_trip_against_sj300_simulate(simulate: str, tmp_path: Path) -> None:
    url = ("--url", simulate)
    original, restored = tmp_path / "original.json", tmp_path / "restored.json"
    assert (await sj300("params", "backup", str(original), "-n", "2", *url)).code == 0

    for code, value in CHANGES.items():
        changed = await sj300("write", code, value, "-n", "2", *url)
        assert changed.code == 0, (code, changed.err)
    different = await sj300("params", "diff", str(original), "--json", *url)
    assert different.code == 1
    assert [d["code"] for d in different.json()["differences"]] == list(CHANGES)
    h024 = next(d for d in different.json()["differences"] if d["code"] == "H024")
    assert (h024["drive_value"], h024["drive_raw"], h024["unit"]) == (0.25, 250, "kg m2")

    result = await sj300("params", "restore", str(original), *url)
    assert result.code == 0, result.err
    written = len(PARAMETERS) - 5  # C071..C075: the node address and the line settings
    assert result.out.startswith(f"node 02: {written} of {written} parameters restored")

    assert (await sj300("params", "backup", str(restored), "-n", "2", *url)).code == 0
    assert entries(restored) == entries(original)
    assert (await sj300("params", "diff", str(original), *url)).code == 0
