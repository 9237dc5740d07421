"""``sj300 params`` on FR-700 drives, through the real entry point, against a TCP simulator.

A backup walks every number the computer link addresses (Pr.0..Pr.999,
through the link-parameter extension), records what the drive lacks (NAK B)
as absent, names the catalogued parameters and keeps the others raw; diff
shows values in their units; restore leaves the station number, the line
settings and the calibration alone, writes Pr.77 last and tries again what
a write lock refused; a file never crosses protocols; Ctrl-C says how far
a restore got.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

import sj300_async as sj
from sj300_async.fr700 import FR700_PARAMETERS, Fr700OperationMode
from sj300_async.simulator import LinePacing, PlausibleLine, serve_tcp
from sj300_async.simulator.fr700 import Fr700SimulatedBus

from .clirun import interrupted_restore, sj300
from .conftest import FAST_BAUD

#: What a restore never writes, or only with --include-comm, among the simulated parameters.
SKIPPED = [
    f"Pr.{n}" for n in (117, 118, 119, 120, 121, 122, 123, 124, 337, 341, 902, 903, 904, 905)
]
ABSENT = "NAK B (instruction code error)"


@dataclass(frozen=True)
class Fr700Sim:
    """Simulated FR-700 stations 0..2 behind a TCP bridge, and the bridge's URL."""

    bus: Fr700SimulatedBus
    url: str


@pytest.fixture
async def fr700_sim() -> AsyncIterator[Fr700Sim]:
    bus = Fr700SimulatedBus(range(3))
    line = PlausibleLine(LinePacing(FAST_BAUD, 8, "N", 1))
    server = await serve_tcp(bus, "127.0.0.1", 0, line=line)
    try:
        yield Fr700Sim(bus, f"tcp://127.0.0.1:{server.port}?protocol=fr700&baudrate={FAST_BAUD}")
    finally:
        server.close()
        await server.wait_closed()


def codes(numbers: Iterable[int]) -> str:
    """``--codes`` for parameter *numbers*."""
    return ",".join(f"Pr.{n}" for n in numbers)


async def test_a_backup_walks_every_number_and_writes_the_documented_format(
    fr700_sim: Fr700Sim, tmp_path: Path
) -> None:
    file = tmp_path / "station1.json"
    drive = fr700_sim.bus.drives[1]
    result = await sj300("params", "backup", str(file), "-n", "1", "--url", fr700_sim.url)
    assert result.code == 0, result.err
    present = len(drive.parameters)
    assert result.out == (
        f"station 01: {present} parameters saved to {file}; "
        f"{1000 - present} codes absent (the drive has no such parameter)\n"
    )
    assert fr700_sim.bus.stats.requests == 1000 + 10  # one read a number, one HFF a bank
    data = json.loads(file.read_text())
    assert (data["format"], data["version"], data["protocol"]) == ("sj300-params", 2, "fr700")
    assert (data["node"], data["url"]) == (1, fr700_sim.url)
    entries = {p["code"]: p for p in data["parameters"]}
    assert list(entries) == [f"Pr.{n}" for n in range(1000)]  # every number, in order
    raw = {code: p["raw"] for code, p in entries.items() if p["raw"] is not None}
    assert raw == {f"Pr.{n}": value for n, value in drive.parameters.items()}
    assert entries["Pr.7"] == {
        "code": "Pr.7",
        "name": "acceleration time",
        "unit": "s",
        "value": 5.0,
        "raw": 50,
    }
    assert entries["Pr.117"]["raw"] == 1  # the station number
    # what the drive has beyond the catalogue: the raw integer, nothing guessed
    assert entries["Pr.13"] == {
        "code": "Pr.13",
        "name": None,
        "unit": None,
        "value": None,
        "raw": 50,
    }
    assert entries["Pr.14"] == {
        "code": "Pr.14",
        "name": None,
        "unit": None,
        "value": None,
        "raw": None,
        "absent": ABSENT,
    }
    absent = [code for code, p in entries.items() if "absent" in p]
    assert len(absent) == 1000 - present
    assert all(entries[code]["absent"] == ABSENT for code in absent)


async def test_codes_takes_any_number_the_link_addresses(
    fr700_sim: Fr700Sim, tmp_path: Path
) -> None:
    file = tmp_path / "some.json"
    url = ("--url", fr700_sim.url)
    result = await sj300(
        "params", "backup", str(file), "--codes", "pr.7, Pr 13,Pr.14", "--json", *url
    )
    assert result.code == 0, result.err
    assert result.json() == {"node": 1, "file": str(file), "parameters": 2, "absent": ["Pr.14"]}
    data = json.loads(file.read_text())
    assert [(p["code"], p["raw"]) for p in data["parameters"]] == [
        ("Pr.7", 50),
        ("Pr.13", 50),
        ("Pr.14", None),
    ]
    bad = tmp_path / "bad.json"
    beyond, not_one = await asyncio.gather(
        sj300("params", "backup", str(bad), "--codes", "Pr.7,Pr.1000", *url),
        sj300("params", "backup", str(bad), "--codes", "F002", *url),
    )
    beyond.assert_one_line_error(2, "argument --codes: parameter numbers are 0..999, got 1000")
    not_one.assert_one_line_error(2, "argument --codes: ")
    assert not bad.exists()


async def test_diff_shows_values_in_their_units_and_exits_0_or_1(
    fr700_sim: Fr700Sim, tmp_path: Path
) -> None:
    file = tmp_path / "station2.json"
    url = ("--url", fr700_sim.url)
    backup = await sj300(
        "params", "backup", str(file), "-n", "2", "--codes", "Pr.1,Pr.7,Pr.13,Pr.14", *url
    )
    assert backup.code == 0, backup.err

    same = await sj300("params", "diff", str(file), *url)
    assert (same.code, same.out) == (0, f"station 02 matches {file} (4 parameters)\n")

    drive = fr700_sim.bus.drives[2]
    drive.set_parameter(7, 125)  # 12.5 s
    drive.set_parameter(13, 70)  # uncatalogued: raw
    different, as_json = await asyncio.gather(
        sj300("params", "diff", str(file), *url), sj300("params", "diff", str(file), "--json", *url)
    )
    assert different.code == 1, different.err
    lines = different.out.splitlines()
    assert lines[0] == f"station 02 differs from {file}"
    assert lines[1].split() == ["code", "name", "file", "drive"]
    assert lines[2].split() == ["Pr.7", "acceleration", "time", "5.0", "s", "12.5", "s"]
    assert lines[3].split() == [
        "Pr.13",
        "(not",
        "in",
        "the",
        "catalogue)",
        "50",
        "(raw)",
        "70",
        "(raw)",
    ]
    assert len(lines) == 4
    assert as_json.code == 1
    assert as_json.json()["differences"] == [
        {
            "code": "Pr.7",
            "name": "acceleration time",
            "unit": "s",
            "file_raw": 50,
            "drive_raw": 125,
            "file_value": 5.0,
            "drive_value": 12.5,
        },
        {
            "code": "Pr.13",
            "name": None,
            "unit": None,
            "file_raw": 50,
            "drive_raw": 70,
            "file_value": None,
            "drive_value": None,
        },
    ]


async def test_restore_round_trip_leaves_the_address_line_and_calibration_alone(
    fr700_sim: Fr700Sim, tmp_path: Path
) -> None:
    file = tmp_path / "backup.json"
    url = ("--url", fr700_sim.url)
    assert (await sj300("params", "backup", str(file), "-n", "1", *url)).code == 0
    drive = fr700_sim.bus.drives[1]
    original = dict(drive.parameters)
    changes = {1: 6000, 3: 5000, 7: 300, 13: 100, 118: 96, 341: 0, 903: 5000}
    for number, raw in changes.items():
        drive.set_parameter(number, raw)

    restored = await sj300("params", "restore", str(file), *url)
    assert restored.code == 0, restored.err
    written = len(original) - len(SKIPPED)
    assert restored.out == (
        f"station 01: {written} of {written} parameters restored and verified; "
        f"skipped {', '.join(SKIPPED)}\n"
    )
    now = dict(drive.parameters)
    assert {n: now[n] for n in (1, 3, 7, 13)} == {n: original[n] for n in (1, 3, 7, 13)}
    assert {n: now[n] for n in (118, 341, 903)} == {118: 96, 341: 0, 903: 5000}  # left alone

    # to another station, with the line settings: still never its station number or calibration
    other = fr700_sim.bus.drives[2]
    other.set_parameter(902, 123)
    forced = await sj300(
        "params", "restore", str(file), "-n", "2", "--force", "--include-comm", "--json", *url
    )
    assert forced.code == 0, forced.err
    data = forced.json()
    assert data["skipped"] == ["Pr.117", "Pr.902", "Pr.903", "Pr.904", "Pr.905"]
    assert {"Pr.118", "Pr.341"} <= set(data["written"])
    assert data["mismatches"] == []
    assert (other.parameters[117], other.parameters[902]) == (2, 123)
    assert {n: other.parameters[n] for n in original if n not in (117, 902)} == {
        n: raw for n, raw in original.items() if n not in (117, 902)
    }


async def test_pr77_is_written_last_and_a_locked_drive_is_unlocked_first(
    fr700_sim: Fr700Sim, tmp_path: Path
) -> None:
    url = ("--url", fr700_sim.url)
    drive = fr700_sim.bus.drives[0]
    numbers = codes([7, 77, 79, 340])  # Pr.79 and Pr.340 come after Pr.77

    # A backup of a write-locked drive (Pr.77 = 1) restored onto an unlocked one.
    locked = tmp_path / "locked.json"
    for number, raw in {7: 80, 79: 2, 340: 0, 77: 1}.items():
        drive.set_parameter(number, raw)
    backup = await sj300("params", "backup", str(locked), "-n", "0", "--codes", numbers, *url)
    assert backup.code == 0, backup.err
    for number, raw in {77: 0, 7: 50, 79: 0, 340: 1}.items():
        drive.set_parameter(number, raw)
    restored = await sj300("params", "restore", str(locked), "--json", *url)
    assert restored.code == 0, restored.err
    # The mode and command-source settings after the rest, the write lock last.
    assert restored.json()["written"] == ["Pr.7", "Pr.340", "Pr.79", "Pr.77"]
    assert {n: drive.parameters[n] for n in (7, 77, 79, 340)} == {7: 80, 77: 1, 79: 2, 340: 0}

    # The drive is locked now: every write before Pr.77 = 0 is refused, then tried again.
    unlocked = tmp_path / "unlocked.json"
    data = json.loads(locked.read_text())
    assert [p["code"] for p in data["parameters"]] == ["Pr.7", "Pr.77", "Pr.79", "Pr.340"]
    data["parameters"][0]["raw"] = 50
    data["parameters"][1]["raw"] = 0
    unlocked.write_text(json.dumps(data))
    again = await sj300("params", "restore", str(unlocked), *url)
    assert again.code == 0, again.err
    assert again.out == "station 00: 4 of 4 parameters restored and verified\n"
    assert {n: drive.parameters[n] for n in (7, 77)} == {7: 50, 77: 0}


async def test_writes_refused_for_the_operation_mode_are_listed_with_the_hint(
    fr700_sim: Fr700Sim, tmp_path: Path
) -> None:
    file = tmp_path / "b.json"
    url = ("--url", fr700_sim.url)
    backup = await sj300("params", "backup", str(file), "-n", "2", "--codes", "Pr.7,Pr.8", *url)
    assert backup.code == 0, backup.err
    fr700_sim.bus.drives[2].set_parameter(7, 10)
    async with sj.open_bus(fr700_sim.url, protocol="fr700") as bus:
        await bus.drive(2).set_operation_mode(Fr700OperationMode.EXTERNAL)
    result = await sj300("params", "restore", str(file), *url)
    assert result.code == 1
    lines = result.out.splitlines()
    assert lines[0] == "not restored"
    assert lines[2].split()[:3] == ["Pr.7", "5.0", "s"]
    assert "station 02 answered NAK A (mode error)" in lines[2]
    assert lines[3] == "station 02: 1 of 2 parameters restored and verified"  # Pr.8 was equal
    assert result.err == (
        f"sj300 params restore: error: 1 parameter(s) do not match {file}: the drive must be in "
        "network (computer link) operation mode (Pr.79, or HFB H0000), and stopped for some "
        "writes; Pr.77 = 1 refuses every write but Pr.77\n"
    )


async def test_store_is_refused_before_anything_is_opened(tmp_path: Path) -> None:
    result = await sj300(
        "params", "restore", str(tmp_path / "missing.json"), "--store",
        "--url", "sim://?protocol=fr700",
    )  # fmt: skip
    result.assert_one_line_error(
        2, "params restore --store needs storing settings apart, which FR-700 drives"
    )


async def test_a_file_never_crosses_protocols(fr700_sim: Fr700Sim, tmp_path: Path) -> None:
    fr700_file, sj300_file = tmp_path / "fr700.json", tmp_path / "sj300.json"
    made = await asyncio.gather(
        sj300("params", "backup", str(fr700_file), "--codes", "Pr.7", "--url", fr700_sim.url),
        sj300("params", "backup", str(sj300_file), "--codes", "F002", "--sim"),
    )
    assert [m.code for m in made] == [0, 0], [m.err for m in made]
    untouched = dict(fr700_sim.bus.drives[1].parameters)
    on_fr700 = ("--url", fr700_sim.url)
    on_sj300 = ("--sim",)
    results = await asyncio.gather(
        sj300("params", "restore", str(sj300_file), *on_fr700),
        sj300("params", "restore", str(sj300_file), "--force", *on_fr700),
        sj300("params", "diff", str(sj300_file), *on_fr700),
        sj300("params", "restore", str(fr700_file), *on_sj300),
        sj300("params", "diff", str(fr700_file), *on_sj300),
    )
    for result, (action, model, other) in zip(
        results,
        [("restore", "FR-700", "sj300")] * 2
        + [("diff", "FR-700", "sj300"), ("restore", "SJ300", "fr700"), ("diff", "SJ300", "fr700")],
        strict=True,
    ):
        file = sj300_file if other == "sj300" else fr700_file
        result.assert_one_line_error(
            2,
            f"sj300 params {action}: error: {file}: a backup of {other} drives",
            f"never restored onto or compared with an {model} drive",
        )
    assert dict(fr700_sim.bus.drives[1].parameters) == untouched


async def test_ctrl_c_during_a_restore_says_how_far_it_got(
    fr700_sim: Fr700Sim, tmp_path: Path
) -> None:
    file = tmp_path / "backup.json"
    url = ("--url", fr700_sim.url)
    drive = fr700_sim.bus.drives[1]
    writable = [n for n in drive.parameters if f"Pr.{n}" not in SKIPPED]
    backup = await sj300("params", "backup", str(file), "-n", "1", "--codes", codes(writable), *url)
    assert backup.code == 0, backup.err
    drive.set_parameter(1, 6000)  # the second the restore writes, once Pr.0's ACK came
    written, total = await interrupted_restore(
        str(file),
        *url,
        restoring=lambda: drive.parameters[1] == 12000,
        stall=lambda: fr700_sim.bus.faults.silence(1),
    )
    assert total == len(writable)
    assert 13 in writable  # uncatalogued parameters are written too
    assert 13 not in FR700_PARAMETERS
    assert 1 <= written < total


# -- read / write of a number the catalogue does not describe ------------------------------


async def test_read_and_write_take_a_number_the_catalogue_does_not_describe(
    fr700_sim: Fr700Sim,
) -> None:
    # Pr.13 is simulated but not catalogued: a backup keeps it raw, so do read and write.
    assert 13 not in FR700_PARAMETERS
    url = ("--url", fr700_sim.url)
    read = await sj300("read", "Pr.13", "Pr.7", "-n", "1", *url)
    assert read.code == 0, read.err
    rows = [line.split() for line in read.out.splitlines()[1:]]
    assert rows[0][0] == "Pr.13"
    assert " ".join(rows[0][1:]) == "(not in the catalogue) 50 (raw)"
    assert " ".join(rows[1]) == "Pr.7 acceleration time 5.0 s"
    as_json = await sj300("read", "pr 13", "-n", "1", "--json", *url)
    assert as_json.json()["parameters"] == [
        {"code": "Pr.13", "name": None, "value": None, "unit": None, "raw": 50}
    ]
    refused = await sj300("write", "Pr.13", "5", "-n", "1", *url)
    refused.assert_one_line_error(2, "Pr.13 is not in the FR-700 parameter catalogue", "--raw")
    written = await sj300("write", "Pr.13", "70", "--raw", "-n", "1", *url)
    assert written.out == "station 01 Pr.13 (not in the catalogue): 50 -> 70\n", written.err
    assert fr700_sim.bus.drives[1].parameters[13] == 70
    outside = await sj300("read", "Pr.1000", "-n", "1", *url)
    outside.assert_one_line_error(2, "parameter numbers are 0..999, got 1000")


# -- the monitor's set-frequency read beside the poll ------------------------------------


async def test_a_station_that_never_answers_its_set_frequency_read_costs_one_attempt(
    fr700_sim: Fr700Sim, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A review's station 1 answered its polls but never H6D: each read, with the bus's
    # retries and again 2 s later, took the line from the polls (13 records in 30 s
    # where 60 were due). One attempt now, and the next after SETPOINT_AFTER_FAILURE_S.
    simulated = fr700_sim.bus.drives[1]
    asked: list[float] = []
    handle = simulated.handle

    def deaf_to_h6d(request: Any, now: float) -> Any:
        if request.instruction == 0x6D:
            asked.append(now)
            return None  # not answered
        return handle(request, now)

    monkeypatch.setattr(simulated, "handle", deaf_to_h6d)
    result = await sj300(
        "monitor", "--url", fr700_sim.url, "--nodes", "0-2", "--json", "--count", "6",
        "--interval", "0.05", "--timeout", "0.1", "--retries", "2",
    )  # fmt: skip
    assert result.code == 0, result.err
    records = result.json_lines()
    assert [r["node"] for r in records].count(1) == 6
    assert [r["set_frequency_hz"] for r in records if r["node"] == 1] == [None] * 6
    assert all(r["set_frequency_hz"] == 0.0 for r in records if r["node"] != 1)
    assert len(asked) == 1, asked  # one attempt, no retry, no second read within 30 s
