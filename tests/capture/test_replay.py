"""replay://: a capture answers as the line did (issue 17's replay must-show).

A workload runs against the simulator through the TCP transport, with faults
injected at known points, while a capture is written; the same workload is
then run against ``replay://`` of that capture, with no simulator and no
faults, and must give the same typed results, call for call.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from cli.clirun import sj300

import sj300_async as sj
from sj300_async.simulator import SimulatorServer, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.transports._replay import ReplayMismatchError
from sj300_async.wire._pcapng import CapturedPacket, PacketDirection, read_pcapng

Outcome = tuple[str, Any]
Call = Callable[[sj.Bus[sj.Drive, sj.Broadcast]], Awaitable[object]]


def _outcome(value: object) -> Outcome:
    """A result or a typed error in comparable form: the type, and what it says."""
    if isinstance(value, sj.NakError):
        return ("NakError", (value.node, value.code))
    if isinstance(value, sj.ReplyTimeoutError):
        return ("ReplyTimeoutError", value.attempts)
    if isinstance(value, sj.SJ300Error):
        return (type(value).__name__, None)
    return ("value", value)


def _status(node: int) -> Call:
    return lambda bus: bus.drive(node).read_status()


def _monitor(node: int) -> Call:
    return lambda bus: bus.drive(node).read_monitor()


def _workload(sim: SimulatedBus | None) -> list[tuple[str, Call]]:
    """The calls, with the faults injected before some of them on the live run."""

    def fault(inject: Callable[[SimulatedBus], None], call: Call) -> Call:
        async def faulted(bus: sj.Bus[sj.Drive, sj.Broadcast]) -> object:
            if sim is not None:
                inject(sim)
            return await call(bus)

        return faulted

    return [
        ("status", lambda bus: bus.drive(1).read_status()),
        ("monitor", lambda bus: bus.drive(2).read_monitor()),
        ("read F002", lambda bus: bus.drive(3).read_parameter("F002")),
        ("write A020", lambda bus: bus.drive(1).write_parameter_raw("A020", 1234)),
        ("read back A020", lambda bus: bus.drive(1).read_parameter_raw("A020")),
        ("NAK", lambda bus: bus.drive(2).read_parameter_raw("A999")),
        ("dropped, retried", fault(lambda s: s.faults.drop_next(3), _status(3))),
        ("corrupted, retried", fault(lambda s: s.faults.corrupt_next(1), _monitor(1))),
        ("silent drive", fault(lambda s: s.faults.drop_next(2, RETRIES + 1), _status(2))),
        ("trips", lambda bus: bus.drive(1).read_trip_history()),
        ("freq", lambda bus: bus.drive(1).set_frequency(20.0)),
        ("broadcast stop", lambda bus: bus.broadcast.stop()),
        ("absent node", lambda bus: bus.drive(9).read_status()),
        ("status again", lambda bus: bus.drive(1).read_status()),
    ]  # fmt: skip


#: The time-out of every run, live and replayed. A replay delivers each answer as long
#: after its request as it came live, so an answer that came close to the time-out may
#: land on the other side of it when the replaying host is late (a loaded machine): the
#: computed time-out (0.11 s here) once did, on a write answered in 16 ms live.
TIMEOUT_S = 0.2
#: One retry: each failed attempt costs a time-out and a drain as long.
RETRIES = 1


async def _calls(
    bus: sj.Bus[sj.Drive, sj.Broadcast], sim: SimulatedBus | None, calls: int | None
) -> list[tuple[str, Outcome]]:
    """The workload's first *calls* calls on *bus* (all: None), each one's outcome."""
    results: list[tuple[str, Outcome]] = []
    for name, call in _workload(sim)[:calls]:
        try:
            value = await call(bus)
        except sj.SJ300Error as exc:
            value = exc
        results.append((name, _outcome(value)))
    return results


async def _run(
    url: str, sim: SimulatedBus | None, calls: int | None = None, **options: Any
) -> list[tuple[str, Outcome]]:
    async with sj.open_bus(url, timeout=TIMEOUT_S, retries=RETRIES, **options) as bus:
        return await _calls(bus, sim, calls)


@pytest_asyncio.fixture
async def tcp_sim() -> AsyncIterator[tuple[SimulatedBus, SimulatorServer]]:
    sim = SimulatedBus((1, 2, 3))
    server = await serve_tcp(sim, "127.0.0.1", 0)
    try:
        yield sim, server
    finally:
        server.close()
        await server.wait_closed()


async def test_a_replay_gives_the_live_runs_typed_results(
    tcp_sim: tuple[SimulatedBus, SimulatorServer], tmp_path: Path
) -> None:
    sim, server = tcp_sim
    path = tmp_path / "live.pcapng"
    live = await _run(f"tcp://127.0.0.1:{server.port}?baudrate=19200", sim, capture=path)
    outcomes = dict(live)
    # The live run is what the workload says it is: each kind of result occurs.
    assert outcomes["NAK"] == ("NakError", (2, sj.NakCode.ABNORMAL_PARAMETER))
    assert outcomes["read back A020"] == ("value", 1234)
    assert outcomes["silent drive"] == ("ReplyTimeoutError", RETRIES + 1)
    assert outcomes["absent node"] == ("ReplyTimeoutError", RETRIES + 1)
    assert outcomes["dropped, retried"][0] == outcomes["corrupted, retried"][0] == "value"

    replayed = await _run(f"replay://{path}", None)
    assert replayed == live


async def test_a_replay_twice_over_gives_the_same_results_again(
    tcp_sim: tuple[SimulatedBus, SimulatorServer], tmp_path: Path
) -> None:
    """The second pass finds its requests by wrapping around to the capture's start."""
    sim, server = tcp_sim
    path = tmp_path / "live.pcapng"
    calls = 6  # no faults: what is tested is finding the requests again
    url = f"tcp://127.0.0.1:{server.port}?baudrate=19200"
    live = await _run(url, sim, calls, capture=path)
    async with sj.open_bus(f"replay://{path}", timeout=TIMEOUT_S) as bus:
        first = await _calls(bus, None, calls)
        second = await _calls(bus, None, calls)
    assert [first, second] == [live, live]


async def test_the_replay_times_like_the_capture(tmp_path: Path) -> None:
    """The line settings come from the capture; a reply comes as late as it came."""
    path = tmp_path / "slow.pcapng"
    sim = SimulatedBus((1,), wait_ms=40)
    async with sj.open_bus("sim://?baudrate=9600", simulator=sim, capture=path) as bus:
        await bus.drive(1).read_status()
    async with sj.open_bus(f"replay://{path}") as bus:
        assert (bus.line.baudrate, bus.line.parity) == (9600, "N")
        await bus.drive(1).read_status()
        assert bus.stats.transactions.latency_sum_s >= 0.040


async def test_a_request_the_capture_does_not_hold_is_refused_and_names_it(
    tmp_path: Path,
) -> None:
    path = tmp_path / "small.pcapng"
    async with sj.open_bus("sim://?nodes=1-2", capture=path) as bus:
        await bus.drive(1).read_status()
    async with sj.open_bus(f"replay://{path}") as bus:
        with pytest.raises(ReplayMismatchError) as refused:
            await bus.drive(2).read_parameter("F002")
        message = str(refused.value)
        assert "holds no node 02: command 06 (read parameter) F002" in message
        assert "node 01: command 04 (read status)" in message
        assert bus.stats.transactions.retries == 0  # refused at once, never retried
        assert (await bus.drive(1).read_status()).b is sj.StatusB.STOPPED  # still open


def _write(path: Path, packets: list[CapturedPacket], *linktypes: int) -> None:
    from sj300_async.wire._pcapng import PcapngInterface, PcapngWriter

    writer = PcapngWriter()
    data = writer.section("test")
    for linktype in linktypes:
        data += writer.interface(PcapngInterface(linktype, description="sj300 19200 8N1"))[1]
    for packet in packets:
        data += writer.packet(packet)
    path.write_bytes(data)


@pytest.mark.parametrize(
    ("make", "url_suffix", "message"),
    [
        (lambda p: None, "", "cannot read capture"),
        (lambda p: p.write_bytes(b"not a capture"), "", "not a pcapng file"),
        (lambda p: _write(p, [], 147, 147), "", "holds several lines: add ?interface=N"),
        (lambda p: _write(p, [], 147), "?interface=3", "has no interface 3"),
        (lambda p: _write(p, [], 161), "", "link type 161 is no protocol of ours"),
        (lambda p: _write(p, [], 148), "?protocol=sj300", "is a capture of fr700, not sj300"),
        (lambda p: _write(p, [], 147), "?nodes=3", "unknown option(s) nodes"),
    ],
    ids=["missing", "not-pcapng", "two-lines", "no-interface", "linktype", "protocol", "option"],
)
async def test_a_bad_replay_is_a_typed_error(
    tmp_path: Path, make: Callable[[Path], object], url_suffix: str, message: str
) -> None:
    path = tmp_path / "bad.pcapng"
    make(path)
    with pytest.raises(
        sj.LocalProtocolError,
        match=message.replace("?", r"\?").replace("(", r"\(").replace(")", r"\)"),
    ):
        async with sj.open_bus(f"replay://{path}{url_suffix}"):
            pass


async def test_one_line_of_a_gateway_capture_replays(tmp_path: Path) -> None:
    path = tmp_path / "two.pcapng"
    packets = [
        CapturedPacket(0, 1_000_000, b"\x02010405\r", PacketDirection.OUTBOUND),
        CapturedPacket(0, 1_010_000, b"\x02010200010002\r", PacketDirection.INBOUND),
        CapturedPacket(1, 1_000_000, b"\x02010405\r", PacketDirection.OUTBOUND),
        CapturedPacket(1, 1_010_000, b"\x02010300010003\r", PacketDirection.INBOUND),
    ]
    _write(path, packets, 147, 147)
    async with sj.open_bus(f"replay://{path}?interface=1") as bus:
        assert (await bus.drive(1).read_status()).a is sj.StatusA.RUNNING  # line 1's answer


async def test_the_cli_replays_what_the_user_saw(
    tcp_sim: tuple[SimulatedBus, SimulatorServer], tmp_path: Path
) -> None:
    sim, server = tcp_sim
    path = tmp_path / "bug.pcapng"
    url = f"tcp://127.0.0.1:{server.port}?baudrate=19200"
    sim.faults.drop_next(3, 3)
    live = await sj300("--url", url, "--capture", str(path), "status", "-n", "3", "--json")
    assert live.code == 1
    assert "node 03 did not answer" in live.err
    ok = await sj300("--url", url, "--capture", str(tmp_path / "ok.pcapng"), "status", "-n", "2")
    assert ok.code == 0

    replayed = await sj300("--url", f"replay://{path}", "status", "-n", "3", "--json")
    assert (replayed.code, replayed.out) == (live.code, live.out)
    replayed_ok = await sj300("--url", f"replay://{tmp_path / 'ok.pcapng'}", "status", "-n", "2")
    assert (replayed_ok.code, replayed_ok.out) == (0, ok.out)
    other = await sj300("--url", f"replay://{path}", "status", "-n", "1")
    other.assert_one_line_error(1, "the capture holds no node 01: command 04 (read status)")
    packets = read_pcapng(path.read_bytes()).packets
    assert {p.data[1:3] for p in packets if p.direction is PacketDirection.OUTBOUND} == {b"03"}
