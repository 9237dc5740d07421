"""``sj300 params backup / diff / restore`` round trips against a TCP simulator (state persists)."""

from __future__ import annotations

import asyncio
import json
import re
from pathlib import Path

from waiting import wait_for

from sj300_async.sj300 import PARAMETERS

from .clirun import TcpSim, finished, interrupted_restore, running, sj300


async def test_backup_writes_the_documented_format(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "node2.json"
    result = await sj300("params", "backup", str(file), "-n", "2", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    assert result.out == f"node 02: {len(PARAMETERS)} parameters saved to {file}\n"
    data = json.loads(file.read_text())
    assert data["format"] == "sj300-params"
    assert (data["version"], data["protocol"]) == (2, "sj300")
    assert data["node"] == 2
    assert data["url"] == tcp_sim.url
    assert not any("absent" in p for p in data["parameters"])
    raw = {p["code"]: p["raw"] for p in data["parameters"]}
    assert raw == dict(tcp_sim.bus.drives[2].parameters)  # raw integers
    assert list(raw) == list(PARAMETERS)  # catalogue order


async def test_backup_records_absent_codes(tmp_path: Path) -> None:
    file = tmp_path / "some.json"
    result = await sj300(
        "params", "backup", str(file), "--codes", "F002,f999,A004", "--json", "--sim"
    )
    assert result.code == 0, result.err
    assert result.json() == {"node": 1, "file": str(file), "parameters": 2, "absent": ["F999"]}
    data = json.loads(file.read_text())
    assert {p["code"]: p["raw"] for p in data["parameters"]} == {
        "F002": 3000,
        "A004": 500,
        "F999": None,
    }
    assert [p["code"] for p in data["parameters"] if "absent" in p] == ["F999"]


async def test_backup_diff_restore_round_trip(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "backup.json"
    url = ("--url", tcp_sim.url)
    assert (await sj300("params", "backup", str(file), *url)).code == 0
    original = dict(tcp_sim.bus.drives[1].parameters)

    same = await sj300("params", "diff", str(file), *url)
    assert (same.code, same.out) == (0, f"node 01 matches {file} ({len(PARAMETERS)} parameters)\n")

    drive = tcp_sim.bus.drives[1]
    drive.set_parameter("F002", 1250)
    drive.set_parameter("A038", 250)  # not C078: a 40 ms wait makes reading 335 codes slow
    different, as_json = await asyncio.gather(
        sj300("params", "diff", str(file), *url), sj300("params", "diff", str(file), "--json", *url)
    )
    assert different.code == 1  # like diff(1)
    lines = different.out.splitlines()
    assert lines[0] == f"node 01 differs from {file}"
    assert [line.split()[0] for line in lines[2:]] == ["F002", "A038"]
    assert lines[2].split()[-4:] == ["30.00", "s", "12.50", "s"]
    assert as_json.code == 1
    data = as_json.json()
    assert data["equal"] is False
    assert data["differences"][0] == {
        "code": "F002",
        "name": "acceleration time 1",
        "unit": "s",
        "file_raw": 3000,
        "drive_raw": 1250,
        "file_value": 30.0,
        "drive_value": 12.5,
    }

    restored = await sj300("params", "restore", str(file), *url)
    assert restored.code == 0, restored.err
    written = len(PARAMETERS) - 5
    assert restored.out == (
        f"node 01: {written} of {written} parameters restored and verified; "
        "skipped C071, C072, C073, C074, C075\n"
    )
    assert dict(drive.parameters) == original
    assert (await sj300("params", "diff", str(file), *url)).code == 0


async def test_restore_retries_values_that_depend_on_others(
    tcp_sim: TcpSim, tmp_path: Path
) -> None:
    drive = tcp_sim.bus.drives[3]
    drive.set_parameter("A004", 600)
    drive.set_parameter("A003", 600)
    file = tmp_path / "sixty.json"
    assert (await sj300("params", "backup", str(file), "-n", "3", "--url", tcp_sim.url)).code == 0
    drive.set_parameter("A003", 500)
    drive.set_parameter("A004", 500)
    # A003 = 60 Hz comes first in the file and is refused while A004 is 50 Hz; the retry works.
    result = await sj300("params", "restore", str(file), "--json", "--store", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    data = result.json()
    assert data["node"] == 3  # the file's node by default
    assert data["mismatches"] == []
    assert data["stored"] is True
    assert data["skipped"] == ["C071", "C072", "C073", "C074", "C075"]
    assert (drive.parameters["A003"], drive.parameters["A004"]) == (600, 600)
    assert drive.stored_parameters["A003"] == 600


async def test_restore_to_another_node_keeps_its_address(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "one.json"
    tcp_sim.bus.drives[1].set_parameter("F003", 4200)
    assert (await sj300("params", "backup", str(file), "--url", tcp_sim.url)).code == 0
    result = await sj300(
        "params", "restore", str(file), "-n", "4", "--force", "--include-comm", "--json",
        "--url", tcp_sim.url,
    )  # fmt: skip
    assert result.code == 0, result.err
    assert result.json()["skipped"] == ["C072"]
    assert "C071" in result.json()["written"]
    assert tcp_sim.bus.drives[4].parameters["F003"] == 4200
    assert tcp_sim.bus.drives[4].parameters["C072"] == 4


async def test_restore_reports_mismatches_and_exits_1(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "edited.json"
    snapshot = {
        "format": "sj300-params",
        "version": 1,
        "node": 2,
        "url": tcp_sim.url,
        "parameters": {"F002": 1500, "F999": 10, "C078": 5000},
    }
    file.write_text(json.dumps(snapshot))
    result = await sj300("params", "restore", str(file), "--url", tcp_sim.url)
    assert result.code == 1
    assert result.err == f"sj300 params restore: error: 2 parameter(s) do not match {file}\n"
    lines = result.out.splitlines()
    assert lines[0] == "not restored"
    assert [line.split()[0] for line in lines[2:4]] == ["F999", "C078"]
    assert "(absent)" in lines[2]
    assert lines[4] == "node 02: 1 of 3 parameters restored and verified"
    assert tcp_sim.bus.drives[2].parameters["F002"] == 1500

    data = (await sj300("params", "restore", str(file), "--json", "--url", tcp_sim.url)).json()
    assert data["written"] == ["F002"]
    f999, c078 = data["mismatches"]
    assert (f999["code"], f999["expected"], f999["actual"]) == ("F999", 10, None)
    assert "NAK 16" in f999["error"]
    assert (c078["code"], c078["expected"], c078["actual"]) == ("C078", 5000, 0)


async def test_bad_snapshot_files_exit_2(tmp_path: Path) -> None:
    cases = {
        "not-json.json": ("{", "not JSON"),
        "other.json": ('{"format": "other"}', 'no "format": "sj300-params"'),
        "v3.json": ('{"format": "sj300-params", "version": 3}', "version 3 is not 1 or 2"),
        "node.json": (
            '{"format": "sj300-params", "version": 1, "node": 40, "parameters": {}}',
            "node 40",
        ),
        "raw.json": (
            '{"format": "sj300-params", "version": 1, "node": 1, "parameters": {"F002": 1.5}}',
            "F002: 1.5 is not a raw value",
        ),
        "code.json": (
            '{"format": "sj300-params", "version": 1, "node": 1, "parameters": {"Z1": 1}}',
            "not a parameter code",
        ),
    }
    checks = []
    for name, (text, message) in cases.items():
        file = tmp_path / name
        file.write_text(text)
        action = "diff" if name.startswith(("n", "r")) else "restore"
        checks.append((sj300("params", action, str(file)), action, file, message))
    results = await asyncio.gather(*(command for command, *_ in checks))
    for result, (_, action, file, message) in zip(results, checks, strict=True):
        result.assert_one_line_error(2, f"sj300 params {action}: error: {file}", message)


async def test_diff_trouble_exits_2(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "b.json"
    assert (await sj300("params", "backup", str(file), "--codes", "F002")).code == 0
    result = await sj300("params", "diff", str(file), "-n", "9", "--url", tcp_sim.url)
    result.assert_one_line_error(2, "node 09 did not answer")


async def test_backup_to_a_missing_directory_exits_2(tmp_path: Path) -> None:
    result = await sj300("params", "backup", str(tmp_path / "missing" / "b.json"))
    result.assert_one_line_error(2, "No such file or directory")


async def test_ctrl_c_during_a_restore_says_how_far_it_got(tcp_sim: TcpSim, tmp_path: Path) -> None:
    file = tmp_path / "backup.json"
    assert (await sj300("params", "backup", str(file), "--url", tcp_sim.url)).code == 0
    drive = tcp_sim.bus.drives[1]
    drive.set_parameter("F002", 1250)  # among the first the restore writes
    written, total = await interrupted_restore(
        str(file),
        "--url",
        tcp_sim.url,
        restoring=lambda: drive.parameters["F002"] == 3000,
        stall=lambda: tcp_sim.bus.faults.silence(1),
    )
    assert total == len(PARAMETERS) - 5  # the communication settings are skipped
    assert 1 <= written < total


async def test_a_restore_the_drive_stops_answering_says_how_far_it_got(
    tcp_sim: TcpSim, tmp_path: Path
) -> None:
    file = tmp_path / "backup.json"
    assert (await sj300("params", "backup", str(file), "--url", tcp_sim.url)).code == 0
    drive = tcp_sim.bus.drives[1]
    drive.set_parameter("F002", 1250)  # among the first the restore writes
    async with running("params", "restore", str(file), "--url", tcp_sim.url) as proc:
        await wait_for(lambda: drive.parameters["F002"] == 3000, "F002 restored")
        tcp_sim.bus.faults.silence(1)
        result = await finished(proc)
    result.assert_one_line_error(1, "node 01 did not answer", "; stopped after ")
    said = re.search(
        r"stopped after (\d+) of (\d+) parameters written; the drive holds a mix", result.err
    )
    assert said, result.err
    assert 1 <= int(said[1]) < int(said[2]) == len(PARAMETERS) - 5
