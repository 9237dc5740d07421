"""Every drive command through the real entry point, once per protocol: SJ300 and FR-700.

Each test is written once and runs against each protocol's simulator served
over real TCP (a fresh one per test), through ``python -m sj300_async``.
What differs between the protocols is data, in :data:`PROTOCOLS`: the URL's
query, the noun and range of the drives' addresses, a parameter, a trip,
what the protocol lacks. Each command's human output names the protocol's
noun (``node 02``, ``station 02``) and never the other's, its ``--json``
form parses, and what a protocol lacks is refused in one line, exit 2,
before anything is sent. After a command that moves a drive the test waits
for the simulated drive's state (a deadline, never a guessed sleep).

``params backup|diff|restore`` run here on two codes; their whole walk has
a file per protocol (tests/cli/test_cli_params.py,
tests/cli/test_cli_params_fr700.py), as ``sniff`` and ``simulate`` have
theirs (tests/capture/test_sniff_tap.py, tests/simulator/test_sim_cli.py,
tests/fr700/test_fr700_sim_cli.py).
"""

from __future__ import annotations

import asyncio
import json
import re
import sys
from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Protocol

import pytest
from waiting import wait_for

from sj300_async import Direction
from sj300_async.cli import main
from sj300_async.fr700.codec import Fr700StatusBits
from sj300_async.simulator import LinePacing, PlausibleLine, RunState, serve_tcp
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.simulator.sj300 import SimulatedBus

from .clirun import Result, cli_env, finished, sj300

#: The line speed the simulator answers at and each URL declares (as conftest's tcp_sim).
BAUD: Final = 115200
#: The address in each protocol's range with no drive: the one a scan finds silent.
ABSENT: Final = 5
#: The set frequency the run tests command, in Hz.
RUN_HZ: Final = 30.0
#: The ramp times the run tests write, in seconds: the drive reaches RUN_HZ in a blink.
RAMP_S: Final = 0.2


class SimDrive(Protocol):
    """What the tests ask of a simulated drive, whichever protocol it speaks."""

    @property
    def tripped(self) -> bool: ...

    @property
    def parameters(self) -> Mapping[Any, int]: ...

    def state(self, now: float) -> RunState: ...

    def output_hz(self, now: float) -> float: ...

    def trip(self, code: int | None = None, *, now: float) -> bool: ...


@dataclass(frozen=True)
class Param:
    """A parameter of one protocol, its factory value as the simulator holds it."""

    code: str  #: as the user types it
    key: str | int  #: the simulated drive's key in ``parameters``
    name: str
    unit: str
    decimals: int  #: as the CLI prints it; also raw counts per unit (10 ** decimals)
    value: float

    def shown(self, value: float) -> str:
        return f"{value:.{self.decimals}f} {self.unit}"

    def raw(self, value: float) -> int:
        return round(value * 10.0**self.decimals)


@dataclass(frozen=True)
class Facts:
    """What one protocol's drives are, as the tests need it."""

    name: str  #: the protocol, and the test id
    model: str  #: how a refusal names its drives
    query: str  #: the URL's query (besides the baud rate)
    noun: str  #: what an address is called
    addresses: range  #: the protocol's range of addresses
    accel: Param  #: acceleration time: read and written
    decel: str  #: deceleration time's code (the run test writes it too)
    maximum: Param  #: maximum frequency: read
    foreign: str  #: the other protocol's parameter code: refused
    trip_byte: int  #: what ``drive.trip`` is given
    trip_code: str  #: how the CLI names that trip
    trip_meaning: str
    broadcast_stop: bool  #: ``stop --all`` works
    #: A simulated drive's stored (EEPROM) value of a parameter; None: ``write --store`` refused.
    stored: Callable[[Any, Any], int] | None
    simulator: Callable[[Iterable[int]], SimulatedBus | Fr700SimulatedBus]
    direction: Callable[[Any, float], Direction]  #: a simulated drive's direction at *now*
    set_hz: Callable[[Any], float]  #: a simulated drive's set frequency

    @property
    def other_noun(self) -> str:
        return "station" if self.noun == "node" else "node"


def _fr700_direction(drive: Any, now: float) -> Direction:
    bits: Fr700StatusBits = drive.status_bits(now)
    if Fr700StatusBits.FORWARD in bits:
        return Direction.FORWARD
    if Fr700StatusBits.REVERSE in bits:
        return Direction.REVERSE
    return Direction.STOP


def _sj300_direction(drive: Any, now: float) -> Direction:
    direction: Direction = drive.monitor(now).direction
    return direction


SJ300: Final = Facts(
    name="sj300",
    model="SJ300",
    query="",
    noun="node",
    addresses=range(1, 33),
    accel=Param("F002", "F002", "acceleration time 1", "s", 2, 30.0),
    decel="F003",
    maximum=Param("A004", "A004", "maximum frequency", "Hz", 1, 50.0),
    foreign="Pr.7",
    trip_byte=7,
    trip_code="E07",
    trip_meaning="over-voltage",
    broadcast_stop=True,
    stored=lambda drive, key: drive.stored_parameters[key],
    simulator=SimulatedBus,
    direction=_sj300_direction,
    set_hz=lambda drive: drive.parameters["F001"] / 100,
)
FR700: Final = Facts(
    name="fr700",
    model="FR-700",
    query="&protocol=fr700",
    noun="station",
    addresses=range(32),
    accel=Param("Pr.7", 7, "acceleration time", "s", 1, 5.0),
    decel="Pr.8",
    maximum=Param("Pr.1", 1, "maximum frequency", "Hz", 2, 120.0),
    foreign="F002",
    trip_byte=0x10,
    trip_code="E.OC1",
    trip_meaning="overcurrent trip during acceleration",
    broadcast_stop=False,
    stored=None,
    simulator=Fr700SimulatedBus,
    direction=_fr700_direction,
    set_hz=lambda drive: drive.set_frequency_hz,
)
PROTOCOLS: Final = (SJ300, FR700)


@dataclass(frozen=True)
class Line:
    """A protocol's simulated drives behind a TCP bridge, and how to reach them."""

    facts: Facts
    drives: Mapping[int, SimDrive]
    sim: SimulatedBus | Fr700SimulatedBus
    url: str

    @property
    def first(self) -> int:
        return self.facts.addresses[0]

    @property
    def last(self) -> int:
        return self.facts.addresses[-1]

    def tag(self, address: int) -> str:
        """How the CLI names a drive: ``node 02``, ``station 00``."""
        return f"{self.facts.noun} {address:02d}"

    async def run(self, *args: str) -> Result:
        """``sj300 ARGS --url`` this line."""
        return await sj300(*args, "--url", self.url)

    async def human(self, *args: str) -> Result:
        """``sj300 ARGS`` that must succeed, its output naming this protocol's noun only."""
        result = await self.run(*args)
        assert result.code == 0, (args, result.err)
        assert "Traceback" not in result.err, result.err
        wrong = re.compile(rf"\b{self.facts.other_noun}s?\b")
        assert not wrong.search(result.out + result.err), (args, result.out, result.err)
        return result

    async def json(self, *args: str) -> Any:
        """``sj300 ARGS --json``, parsed."""
        result = await self.run(*args, "--json")
        assert result.code == 0, (args, result.err)
        return result.json()

    def now(self) -> float:
        return asyncio.get_running_loop().time()

    async def wait_state(
        self, address: int, state: RunState, direction: Direction, hz: float | None = None
    ) -> None:
        """Wait until the drive at *address* is in *state*, turning *direction* (at *hz*)."""
        drive = self.drives[address]

        def there() -> bool:
            now = self.now()
            return (
                drive.state(now) is state
                and self.facts.direction(drive, now) is direction
                and (hz is None or drive.output_hz(now) == pytest.approx(hz))
            )

        await wait_for(there, f"{self.tag(address)} {state.value} {direction.name} {hz} Hz")

    def nothing_sent(self) -> bool:
        """True when the simulated line has seen no byte at all."""
        stats = self.sim.stats
        parser = stats.parser
        seen = (stats.requests, parser.frames, parser.bad_frames, parser.discarded_bytes)
        return seen == (0, 0, 0, 0)


@pytest.fixture(params=PROTOCOLS, ids=[p.name for p in PROTOCOLS])
async def line(request: pytest.FixtureRequest) -> AsyncIterator[Line]:
    """A drive at every address of the protocol's range but :data:`ABSENT`, over TCP."""
    facts: Facts = request.param
    sim = facts.simulator(a for a in facts.addresses if a != ABSENT)
    pacing = PlausibleLine(LinePacing(BAUD, 8, "N", 1))
    server = await serve_tcp(sim, "127.0.0.1", 0, line=pacing)
    url = f"tcp://127.0.0.1:{server.port}?baudrate={BAUD}{facts.query}"
    try:
        yield Line(facts, sim.drives, sim, url)
    finally:
        server.close()
        await server.wait_closed()


async def test_scan_covers_the_protocols_range(line: Line) -> None:
    text, data = await asyncio.gather(line.human("scan"), line.json("scan"))
    answering = [a for a in line.facts.addresses if a != ABSENT]
    first, last = line.first, line.last
    assert text.out == (
        f"{line.facts.noun}s answering: {first}-{ABSENT - 1},{ABSENT + 1}-{last} (31 of 32)\n"
    )
    assert f"{line.tag(first)}: answers" in text.err.splitlines()
    assert f"{line.tag(ABSENT)}: no answer" in text.err.splitlines()
    assert data == {"scanned": list(line.facts.addresses), "answering": answering}


async def test_status_takes_every_address_of_the_range_and_refuses_the_others(
    line: Line,
) -> None:
    # FR-700 station 0 is valid; SJ300 node 0 (first - 1) is not.
    first, last = line.first, line.last
    text, data, below, above = await asyncio.gather(
        line.human("status", "-n", str(first)),
        line.json("status", "-n", str(last)),
        line.run("status", "-n", str(first - 1)),
        line.run("status", "-n", str(last + 1)),
    )
    rows = text.out.splitlines()
    assert rows[0] == line.tag(first)
    assert re.fullmatch(r"state +stopped", rows[1]), rows
    assert re.search(r"^set frequency +0\.00 Hz$", text.out, re.M), text.out
    assert (data["node"], data["state"], data["trip"]) == (last, "stopped", None)
    assert data["direction"] == "stop"
    assert data["set_frequency_hz"] == 0.0
    assert data["monitor"]["output_frequency_hz"] == 0.0
    noun = line.facts.noun
    for refused, number in ((below, first - 1), (above, last + 1)):
        refused.assert_one_line_error(
            2,
            f"sj300 status: error: argument -n/--node: a {noun} is {first}..{last}, got '{number}'",
        )


async def test_read_and_write_a_parameter(line: Line) -> None:
    accel, maximum = line.facts.accel, line.facts.maximum
    text, data, foreign = await asyncio.gather(
        line.human("read", accel.code, maximum.code),
        line.json("read", accel.code, maximum.code, "-n", "2"),
        line.run("read", line.facts.foreign),
    )
    rows = [row.split() for row in text.out.splitlines()]
    assert rows[0] == ["code", "name", "value"]
    assert rows[1] == [accel.code, *accel.name.split(), *accel.shown(accel.value).split()]
    assert rows[2] == [maximum.code, *maximum.name.split(), *maximum.shown(maximum.value).split()]
    assert data == {
        "node": 2,
        "parameters": [
            {
                "code": p.code,
                "name": p.name,
                "value": p.value,
                "unit": p.unit,
                "raw": p.raw(p.value),
            }
            for p in (accel, maximum)
        ],
    }
    foreign.assert_one_line_error(2, "sj300 read: error: argument CODE:", line.facts.foreign)

    wrote, wrote_json = await asyncio.gather(
        line.human("write", accel.code, str(RAMP_S)),
        line.json("write", accel.code, str(RAMP_S * 10), "-n", "2"),
    )
    assert wrote.out == (
        f"{line.tag(1)} {accel.code} {accel.name}: {accel.shown(accel.value)} -> "
        f"{accel.shown(RAMP_S)}\n"
    )
    assert wrote_json["node"] == 2
    assert (wrote_json["code"], wrote_json["unit"], wrote_json["stored"]) == (
        accel.code,
        "s",
        False,
    )
    assert (wrote_json["old_raw"], wrote_json["raw"]) == (accel.raw(accel.value), accel.raw(2.0))
    assert line.drives[1].parameters[accel.key] == accel.raw(RAMP_S)
    assert line.drives[2].parameters[accel.key] == accel.raw(2.0)


async def test_write_store_stores_or_is_refused(line: Line) -> None:
    accel = line.facts.accel
    result = await line.run("write", accel.code, "12", "--store")
    if line.facts.stored is not None:
        assert result.code == 0, result.err
        assert result.out.endswith(f"-> {accel.shown(12)} (stored)\n"), result.out
        assert line.facts.stored(line.drives[1], accel.key) == accel.raw(12)
    else:
        result.assert_one_line_error(
            2,
            f"sj300 write: error: write needs storing settings apart, which "
            f"{line.facts.model} drives (protocol {line.facts.name}) do not have here",
        )
        assert line.nothing_sent()


async def test_freq_run_forward_reverse_and_stop(line: Line) -> None:
    facts = line.facts
    # Short ramps first (the drive reaches its frequency at once), with the frequencies.
    ramps = (line.run("write", code, str(RAMP_S)) for code in (facts.accel.code, facts.decel))
    *wrote, freq, freq_json = await asyncio.gather(
        *ramps, line.human("freq", str(RUN_HZ)), line.json("freq", "12.5", "-n", "2")
    )
    assert [r.code for r in wrote] == [0, 0], [r.err for r in wrote]
    assert freq.out == f"{line.tag(1)}: frequency set to {RUN_HZ:.2f} Hz\n"
    assert freq_json == {"node": 2, "frequency_hz": 12.5}
    assert facts.set_hz(line.drives[1]) == RUN_HZ
    assert facts.set_hz(line.drives[2]) == 12.5

    forward = await line.human("run", "forward")
    assert forward.out == f"{line.tag(1)}: run forward\n"
    await line.wait_state(1, RunState.CONSTANT_SPEED, Direction.FORWARD, RUN_HZ)
    status, status_json = await asyncio.gather(line.human("status"), line.json("status"))
    assert re.search(r"^state +running$", status.out, re.M), status.out
    assert re.search(r"^direction +forward$", status.out, re.M), status.out
    assert re.search(rf"^set frequency +{RUN_HZ:.2f} Hz$", status.out, re.M), status.out
    assert status_json["state"] == "running"
    assert status_json["direction"] == "forward"  # both protocols, as the text row
    assert status_json["set_frequency_hz"] == RUN_HZ
    assert status_json["monitor"]["output_frequency_hz"] == RUN_HZ

    reverse = await line.json("run", "reverse")
    assert reverse == {"node": 1, "direction": "REVERSE"}
    await line.wait_state(1, RunState.CONSTANT_SPEED, Direction.REVERSE, RUN_HZ)

    stop, stop_json = await asyncio.gather(line.human("stop"), line.json("stop", "-n", "2"))
    assert stop.out == f"{line.tag(1)}: stop\n"
    assert stop_json == {"node": 2, "broadcast": False}
    await line.wait_state(1, RunState.STOPPED, Direction.STOP)
    assert line.drives[2].state(line.now()) is RunState.STOPPED  # never ran


async def test_stop_all_broadcasts_or_is_refused(line: Line) -> None:
    if not line.facts.broadcast_stop:
        refused = await line.run("stop", "--all")
        refused.assert_one_line_error(
            2,
            f"sj300 stop: error: stop needs a broadcast stop, which {line.facts.model} drives "
            f"(protocol {line.facts.name}) do not have here",
        )
        assert line.nothing_sent()
        return
    runs = await asyncio.gather(*(line.human("run", "forward", "-n", n) for n in ("1", "2")))
    assert [r.out for r in runs] == [
        f"{line.tag(1)}: run forward\n",
        f"{line.tag(2)}: run forward\n",
    ]
    text, data = await asyncio.gather(line.human("stop", "--all"), line.json("stop", "--all"))
    assert text.out == "all drives: stop (broadcast)\n"
    assert data == {"node": None, "broadcast": True}
    # The factory ramp is long: stopping is decelerating (at 0 Hz set frequency: stopped).
    stopping = (RunState.DECELERATING, RunState.STOPPED)
    await wait_for(
        lambda: all(line.drives[a].state(line.now()) in stopping for a in (1, 2)),
        "drives 1 and 2 stopping",
    )


async def test_trips_status_run_and_reset_of_a_tripped_drive(line: Line) -> None:
    facts = line.facts
    for address in (2, 3):
        assert line.drives[address].trip(facts.trip_byte, now=line.now())
    trip = f"{facts.trip_code} {facts.trip_meaning}"

    empty, trips, trips_json, status, status_json, run, monitor, codes = await asyncio.gather(
        line.human("trips", "-n", "4"),
        line.human("trips", "-n", "2"),
        line.json("trips", "-n", "2"),
        line.human("status", "-n", "2"),
        line.json("status", "-n", "2"),
        line.run("run", "forward", "-n", "2"),
        line.human("monitor", "--count", "1", "--nodes", "2"),
        line.human("trips", "--codes"),
    )
    assert empty.out.startswith(f"{line.tag(4)}: 0 trip(s)"), empty.out
    rows = trips.out.splitlines()
    assert rows[0].startswith(f"{line.tag(2)}: 1 trip(s)"), trips.out
    assert rows[1].split()[:3] == ["#", "trip", "meaning"]
    assert rows[2].split()[:2] == ["1", facts.trip_code]
    assert facts.trip_meaning in rows[2]
    (record,) = trips_json["records"]
    assert (record["error_code"], record["meaning"]) == (facts.trip_code, facts.trip_meaning)
    assert re.search(r"^state +tripped$", status.out, re.M), status.out
    assert re.search(rf"^trip +{re.escape(trip)}$", status.out, re.M), status.out
    assert status_json["state"] == "tripped"
    assert (status_json["trip"]["code"], status_json["trip"]["meaning"]) == (
        facts.trip_code,
        facts.trip_meaning,
    )
    run.assert_one_line_error(
        1, f"sj300 run: error: {line.tag(2)} is tripped: {trip}; clear it with sj300 reset"
    )
    assert line.drives[2].state(line.now()) is RunState.TRIPPED
    assert f"{line.tag(2)} online  tripped" in monitor.out, monitor.out
    assert any(row.split()[:1] == [facts.trip_code] for row in codes.out.splitlines())

    reset, reset_json = await asyncio.gather(
        line.human("reset", "-n", "2"), line.json("reset", "-n", "3")
    )
    assert reset.out == f"{line.tag(2)}: reset, {trip} cleared\n"
    assert reset_json["node"] == 3
    assert reset_json["was_tripped"] is True
    assert (reset_json["trip"]["code"], reset_json["trip"]["meaning"]) == (
        facts.trip_code,
        facts.trip_meaning,
    )
    assert not line.drives[2].tripped
    assert not line.drives[3].tripped
    again, again_json, history = await asyncio.gather(
        line.human("reset", "-n", "2"), line.json("reset", "-n", "3"), line.json("trips", "-n", "2")
    )
    assert again.out == f"{line.tag(2)} is not tripped: nothing to reset\n"
    assert again_json == {"node": 3, "was_tripped": False, "trip": None}
    # The history keeps the trip once it is cleared.
    assert [r["error_code"] for r in history["records"]] == [facts.trip_code]


async def test_params_backup_diff_and_restore(line: Line, tmp_path: Path) -> None:
    # Two codes (--codes): the whole walk has a test per protocol (test_cli_params*.py).
    accel, maximum = line.facts.accel, line.facts.maximum
    file = tmp_path / "backup.json"
    saved = await line.human(
        "params", "backup", str(file), "-n", "2", "--codes", f"{accel.code},{maximum.code}"
    )
    assert saved.out.startswith(f"{line.tag(2)}: 2 parameters saved to {file}"), saved.out
    data = json.loads(file.read_text())
    assert (data["protocol"], data["node"]) == (line.facts.name, 2)
    assert {p["code"]: p["raw"] for p in data["parameters"]} == {  # in the protocol's order
        accel.code: accel.raw(accel.value),
        maximum.code: maximum.raw(maximum.value),
    }
    same = await line.human("params", "diff", str(file))
    assert same.out == f"{line.tag(2)} matches {file} (2 parameters)\n"
    await line.human("write", accel.code, "1", "-n", "2")
    differs = await line.run("params", "diff", str(file))
    assert differs.code == 1, differs.err
    assert differs.out.splitlines()[0] == f"{line.tag(2)} differs from {file}"
    assert re.search(
        rf"^{re.escape(accel.code)} .* {accel.shown(accel.value)} +{accel.shown(1)}$",
        differs.out,
        re.M,
    ), differs.out
    restored = await line.human("params", "restore", str(file))
    assert restored.out.startswith(f"{line.tag(2)}: 2 of 2 parameters restored and verified"), (
        restored.out
    )
    assert line.drives[2].parameters[accel.key] == accel.raw(accel.value)
    assert (await line.run("params", "diff", str(file))).code == 0


async def test_monitor_count(line: Line) -> None:
    nodes = f"{line.first},{line.first + 1}"
    text, samples = await asyncio.gather(
        line.human("monitor", "--count", "1", "--nodes", nodes),
        line.run("monitor", "--count", "1", "--nodes", nodes, "--json"),
    )
    rows = text.out.splitlines()
    assert len(rows) == 2, text.out
    for row, address in zip(
        sorted(rows, key=lambda r: r.split()[2]), (line.first, line.first + 1), strict=True
    ):
        assert re.search(rf"\b{line.tag(address)} online +stopped\b", row), row
    assert samples.code == 0, samples.err
    records = samples.json_lines()
    assert sorted(r["node"] for r in records) == [line.first, line.first + 1]
    assert all(r["online"] and r["error"] is None for r in records)


async def test_monitor_shows_the_set_frequency_from_the_first_sample(line: Line) -> None:
    # SJ300's is a parameter the poll reads (F001); FR-700's a read of its own (H6D).
    assert (await line.run("freq", "12.5", "-n", "2")).code == 0
    data = await line.json("monitor", "--count", "1", "--nodes", "2")
    assert data["set_frequency_hz"] == 12.5
    text = await line.human("monitor", "--count", "1", "--nodes", "2")
    assert re.search(r"\b12\.50\b", text.out), text.out


async def test_monitor_names_the_trip_from_the_first_sample(line: Line) -> None:
    assert line.drives[2].trip(line.facts.trip_byte, now=line.now())
    text, data = await asyncio.gather(
        line.human("monitor", "--count", "1", "--nodes", "2"),
        line.json("monitor", "--count", "1", "--nodes", "2"),
    )
    assert (data["trip"], data["trip_meaning"]) == (line.facts.trip_code, line.facts.trip_meaning)
    assert f"{line.tag(2)} online  tripped {line.facts.trip_code} " in text.out, text.out


async def shell_on_a_pipe(url: str, commands: str) -> Result:
    """``sj300 shell --url URL`` with *commands* on its stdin (a pipe: no prompt)."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "shell",
        "--url",
        url,
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=cli_env(),
    )
    return await finished(proc, commands.encode())


async def test_shell_runs_the_commands_on_one_bus(line: Line) -> None:
    facts, first = line.facts, line.first
    commands = [
        f"status -n {first}",
        f"read {facts.accel.code} -n 3 --json",
        "freq 20 -n 3",
        "run forward -n 3",
        f"status -n {first - 1}",  # outside the range: refused, the session goes on
        "trips -n 3 --json",
    ]
    done = await shell_on_a_pipe(line.url, "".join(f"{c}\n" for c in commands))
    assert done.code == 1, done.err  # the refused line
    assert done.err.splitlines() == [
        f"sj300 status: error: argument -n/--node: a {facts.noun} is "
        f"{first}..{line.last}, got '{first - 1}' (see --help)"
    ]
    out = done.out.splitlines()
    assert out[0] == line.tag(first)
    assert f"{line.tag(3)}: frequency set to 20.00 Hz" in out
    assert f"{line.tag(3)}: run forward" in out
    documents = [row for row in out if row.startswith("{")]
    human = [row for row in out if not row.startswith("{")]
    assert not any(re.search(rf"\b{facts.other_noun}\b", row) for row in human), human
    read, trips = (Result(0, document, "").json() for document in documents)
    assert read["parameters"][0]["code"] == facts.accel.code
    assert (trips["node"], trips["records"]) == (3, [])
    assert facts.set_hz(line.drives[3]) == 20.0
    drive = line.drives[3]  # accelerating, or already at 20 Hz on a slow machine
    await wait_for(
        lambda: (
            drive.state(line.now()).outputting
            and facts.direction(drive, line.now()) is Direction.FORWARD
        ),
        f"{line.tag(3)} running forward",
    )


async def test_refusals_send_nothing(line: Line) -> None:
    """A number outside the range, or another protocol's code: one line, exit 2, no frame."""
    first, last, noun = line.first, line.last, line.facts.noun
    results = await asyncio.gather(
        line.run("freq", "10", "-n", str(first - 1)),
        line.run("run", "forward", "-n", str(last + 1)),
        line.run("write", line.facts.foreign, "1"),
    )
    for result in results[:2]:
        result.assert_one_line_error(2, f"a {noun} is {first}..{last}")
    results[2].assert_one_line_error(2, "sj300 write: error: argument CODE:", line.facts.foreign)
    assert line.nothing_sent()


@pytest.mark.parametrize("command", ["read", "write"])
def test_help_names_each_protocols_frames(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The help said ``(command 06)`` for an FR-700 too: each protocol's is named now."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    description = " ".join(capsys.readouterr().out.split("\n\n")[1].split())
    assert "SJ300: command" in description, description
    assert "FR-700: the parameter's" in description, description
