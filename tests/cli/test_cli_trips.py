"""Trips through the real entry point: ``sj300 reset``, ``run`` refusing a tripped drive, meanings.

The drives are the TCP simulator's (``tcp_sim``): a trip is injected with the
simulator's fault hook (``drive.trip``), as a fault inside the drive would,
and what reached each drive is recorded by wrapping its ``handle``.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable

import pytest

from sj300_async.simulator import serve_tcp
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.simulator.sj300 import SimulatedDrive
from sj300_async.sj300 import Command, Request, TripCode
from sj300_async.sj300._events import Reply

from .clirun import TcpSim, sj300


def _now() -> float:
    return asyncio.get_running_loop().time()


def record_commands(
    monkeypatch: pytest.MonkeyPatch,
    drive: SimulatedDrive,
    after: Callable[[Request, float], None] | None = None,
) -> list[Command]:
    """Every command *drive* is sent from now on, in order (*after* runs after each one)."""
    commands: list[Command] = []
    handle = drive.handle

    def recording(request: Request, now: float) -> Reply | None:
        commands.append(request.command)
        reply = handle(request, now)
        if after is not None:
            after(request, now)
        return reply

    monkeypatch.setattr(drive, "handle", recording)
    return commands


async def test_reset_clears_a_trip_the_simulator_injected(
    tcp_sim: TcpSim, monkeypatch: pytest.MonkeyPatch
) -> None:
    drive = tcp_sim.bus.drives[2]
    assert drive.trip(7, now=_now())
    commands = record_commands(monkeypatch, drive)
    result = await sj300("reset", "-n", "2", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    assert result.err == ""
    assert result.out == "node 02: reset, E07 over-voltage cleared\n"
    assert not drive.tripped
    # RS on, then every command-02 input off; the status read before and after.
    assert commands.count(Command.SET_TERMINALS) == 2
    assert commands[0] is Command.READ_STATUS
    assert commands[-1] is Command.READ_STATUS
    assert Command.RUN not in commands


async def test_status_of_a_tripped_drive_names_its_trip(tcp_sim: TcpSim) -> None:
    assert tcp_sim.bus.drives[2].trip(7, now=_now())
    result = await sj300("status", "-n", "2", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    assert result.out.splitlines()[1:4] == [
        "state                 tripped",
        "trip                  E07 over-voltage",
        "state (A)             trip (08)",
    ]


async def test_reset_json_names_the_trip(tcp_sim: TcpSim) -> None:
    assert tcp_sim.bus.drives[3].trip(TripCode.THERMAL, now=_now())
    result = await sj300("reset", "-n", "3", "--json", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    assert result.json() == {
        "node": 3,
        "was_tripped": True,
        "trip": {"code": "E21", "number": 21, "name": "THERMAL", "meaning": "thermal trip"},
    }
    assert not tcp_sim.bus.drives[3].tripped


async def test_reset_of_a_drive_not_tripped_says_so_and_changes_nothing(
    tcp_sim: TcpSim, monkeypatch: pytest.MonkeyPatch
) -> None:
    commands = record_commands(monkeypatch, tcp_sim.bus.drives[1])
    result = await sj300("reset", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    assert result.out == "node 01 is not tripped: nothing to reset\n"
    assert commands == [Command.READ_STATUS]
    as_json = await sj300("reset", "--json", "--url", tcp_sim.url)
    assert as_json.json() == {"node": 1, "was_tripped": False, "trip": None}


async def test_a_trip_that_comes_back_is_one_line_and_exit_1(
    tcp_sim: TcpSim, monkeypatch: pytest.MonkeyPatch
) -> None:
    drive = tcp_sim.bus.drives[4]
    assert drive.trip(14, now=_now())

    def trip_again(request: Request, now: float) -> None:  # a fault that persists
        if request.command is Command.SET_TERMINALS:
            drive.trip(14, now=now)

    record_commands(monkeypatch, drive, after=trip_again)
    result = await sj300("reset", "-n", "4", "--wait", "0.3", "--url", tcp_sim.url)
    result.assert_one_line_error(1, "node 04 is still tripped after the reset: E14 ground fault")
    assert drive.tripped


async def test_run_refuses_a_tripped_drive_and_sends_no_run_command(
    tcp_sim: TcpSim, monkeypatch: pytest.MonkeyPatch
) -> None:
    drive = tcp_sim.bus.drives[2]
    assert drive.trip(7, now=_now())
    commands = record_commands(monkeypatch, drive)
    for direction in ("forward", "reverse"):
        result = await sj300("run", direction, "-n", "2", "--url", tcp_sim.url)
        result.assert_one_line_error(
            1, "sj300 run: error: node 02 is tripped: E07 over-voltage; clear it with sj300 reset"
        )
    assert Command.RUN not in commands
    assert Command.READ_STATUS in commands
    # Once reset, it runs.
    assert (await sj300("reset", "-n", "2", "--url", tcp_sim.url)).code == 0
    ran = await sj300("run", "forward", "-n", "2", "--url", tcp_sim.url)
    assert ran.code == 0, ran.err
    assert Command.RUN in commands


async def test_trips_shows_each_trip_with_its_meaning(tcp_sim: TcpSim) -> None:
    drive = tcp_sim.bus.drives[2]
    drive.trip(7, now=_now())
    drive.reset(_now())
    drive.trip(36, now=_now())
    drive.reset(_now())
    drive.trip(99, now=_now())  # no meaning published: kept as its number
    result = await sj300("trips", "-n", "2", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    lines = result.out.splitlines()
    assert lines[1].split()[:3] == ["#", "trip", "meaning"]
    assert lines[2].split()[:4] == ["1", "E99", "unknown", "trip"]
    assert lines[3].split()[:4] == ["2", "E36", "brake", "error"]
    assert lines[4].split()[:3] == ["3", "E07", "over-voltage"]
    data = (await sj300("trips", "-n", "2", "--json", "--url", tcp_sim.url)).json()
    picked = [(r["error_code"], r["trip_factor"], r["name"], r["meaning"]) for r in data["records"]]
    assert picked == [
        ("E99", 99, "UNKNOWN_99", "unknown trip"),
        ("E36", 36, "BRAKE", "brake error"),
        ("E07", 7, "OVER_VOLTAGE", "over-voltage"),
    ]


async def test_trips_codes_lists_every_code_with_its_meaning() -> None:
    result = await sj300("trips", "--codes")
    assert result.code == 0, result.err
    lines = result.out.splitlines()
    assert lines[0].split() == ["code", "meaning", "name"]
    rows = {line.split()[0]: line for line in lines[1:]}
    assert list(rows) == [code.error_code for code in TripCode]
    assert "over-current while accelerating" in rows["E03"]
    assert "momentary power failure" in rows["E16"]
    assert "option card error" in rows["E65"]
    data = (await sj300("trips", "--codes", "--json")).json()
    assert {c["code"]: c["meaning"] for c in data["codes"]} == {
        code.error_code: code.description for code in TripCode
    }
    assert data["codes"][6] == {
        "code": "E07",
        "number": 7,
        "name": "OVER_VOLTAGE",
        "meaning": "over-voltage",
    }


@pytest.fixture
async def fr700_tcp() -> AsyncIterator[tuple[Fr700SimulatedBus, str]]:
    """Two FR-700 drives behind a TCP bridge; an inverter reset deafens a drive for 0.5 s."""
    sim = Fr700SimulatedBus([0, 1], reset_s=0.5)
    server = await serve_tcp(sim, "127.0.0.1", 0)
    try:
        yield sim, f"tcp://127.0.0.1:{server.port}"
    finally:
        server.close()
        await server.wait_closed()


async def test_fr700_trips_lists_the_fault_history_newest_first(
    fr700_tcp: tuple[Fr700SimulatedBus, str],
) -> None:
    sim, url = fr700_tcp
    args = ("--protocol", "fr700", "--url", url)
    empty = await sj300("trips", "-n", "0", *args)
    assert empty.out == "station 00: 0 trip(s) recorded\n", empty.err
    drive = sim.drives[1]
    assert drive.trip(0x30, now=_now())
    drive.power_cycle(_now())  # the history survives it; the trip does not
    assert drive.trip(0xA0, now=_now())
    result = await sj300("trips", "-n", "1", *args)
    assert result.code == 0, result.err
    assert result.out.splitlines() == [
        "station 01: 2 trip(s) recorded, newest first",
        "#  trip   meaning",
        "1  E.OPT  option fault",
        "2  E.THT  inverter overload trip (electronic thermal relay)",
    ]
    data = (await sj300("trips", "-n", "1", "--json", *args)).json()
    assert data["total_count"] is None  # an FR-700 counts no trips
    assert [r["error_code"] for r in data["records"]] == ["E.OPT", "E.THT"]


async def test_fr700_reset_waits_for_the_restart_and_names_the_fault(
    fr700_tcp: tuple[Fr700SimulatedBus, str],
) -> None:
    sim, url = fr700_tcp
    assert sim.drives[1].trip(0x10, now=_now())
    args = ("--protocol", "fr700", "--url", url, "--timeout", "0.1")
    result = await sj300("reset", "-n", "1", *args)
    assert result.code == 0, result.err
    # The fault as its display shows it, and its meaning (the reference's table); a station.
    assert result.out == "station 01: reset, E.OC1 overcurrent trip during acceleration cleared\n"
    assert not sim.drives[1].tripped
    assert sim.stats.resets == 1
    again = await sj300("reset", "-n", "1", "--json", *args)
    assert again.json() == {"node": 1, "was_tripped": False, "trip": None}
    assert sim.stats.resets == 1  # nothing sent to a drive that is not tripped
