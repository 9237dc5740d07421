"""Bad input, refused before the wire: one table row per thing a caller can get wrong.

Every invalid node, command, value, parameter code, URL and line setting must
raise a typed LocalProtocolError (also a ValueError) whose message names the
problem, and nothing may reach the line: the bus under test records every
frame it writes, and its simulated drives count every byte they hear. A
read-only bus refuses each command that changes a drive (00, 01, 02, 07,
08, 0A, 0B) the same way, with ReadOnlyError.

The library bugs this table found (a cached drive for drive(True), port 0,
an IPv6 ValueError escaping, a serial line without a baud rate, an infinite
or non-numeric time-out) are fixed; their rows stay as regression tests.
"""

from __future__ import annotations

import math
import re
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import pytest

import sj300_async as sj
from sj300_async import bus as sjbus
from sj300_async import sj300 as sj3
from sj300_async.simulator.sj300 import SimulatedBus

from .rel_leaks import Baseline

SJBus = sj.Bus[sj.Drive, sj.Broadcast]


@dataclass
class Rig:
    bus: SJBus
    written: list[bytes] = field(default_factory=list)

    def trace(self, record: sjbus.TraceRecord) -> None:
        if record.direction == "tx":
            self.written.append(record.data)

    def heard(self) -> int:
        """Frames and bytes the simulated drives received."""
        sim = self.bus.simulator
        assert isinstance(sim, SimulatedBus)
        return sim.stats.requests + sim.stats.bad_frames + sim.stats.discarded_bytes


@pytest.fixture
async def rig() -> AsyncIterator[Rig]:
    async with sj.open_bus("sim://?nodes=1-8", timeout=0.05) as bus:
        rig = Rig(bus)
        bus.trace = rig.trace
        yield rig


async def outcome(call: Callable[[], Any]) -> BaseException | None:
    """Run *call* (awaiting what it returns, if anything); return what it raised."""
    try:
        result = call()
        if hasattr(result, "__await__"):
            await result
    except Exception as exc:
        return exc
    return None


def assert_refused(exc: BaseException | None, error: type[Exception], match: str) -> None:
    assert exc is not None, "accepted"
    assert isinstance(exc, error), f"{type(exc).__name__} instead of {error.__name__}: {exc}"
    assert isinstance(exc, ValueError)  # LocalProtocolError is one, so is ReadOnlyError
    assert re.search(match, str(exc)), f"the message does not say why: {exc}"


# -- the Drive API, on a live bus ------------------------------------------------------

NAN, INF = math.nan, math.inf
DriveCall = Callable[[SJBus], Any]


def _d(bus: SJBus) -> sj.Drive:
    return bus.drive(1)


DRIVE_CASES: list[Any] = [
    # nodes
    pytest.param(lambda b: b.drive(0), "1..32", id="node 0"),
    pytest.param(lambda b: b.drive(33), "1..32", id="node 33"),
    pytest.param(lambda b: b.drive(-1), "1..32", id="node -1"),
    pytest.param(lambda b: b.drive(255), "1..32", id="node 255 (broadcast is bus.broadcast)"),
    pytest.param(lambda b: b.drive(None), "1..32", id="node None"),
    pytest.param(lambda b: b.drive("1"), "1..32", id="node '1'"),
    pytest.param(lambda b: b.drive(1.5), "1..32", id="node 1.5"),
    pytest.param(
        lambda b: (b.drive(1), b.drive(True)),
        "1..32",
        id="node True",
    ),
    pytest.param(
        lambda b: (b.drive(1), b.drive(1.0)),
        "1..32",
        id="node 1.0",
    ),
    pytest.param(lambda b: b.drive(1, wait_time_s=2), "0..1 s", id="C078 wait 2 s"),
    pytest.param(lambda b: b.drive(1, wait_time_s=-1), "0..1 s", id="C078 wait -1 s"),
    pytest.param(lambda b: b.drive(1, wait_time_s=NAN), "0..1 s", id="C078 wait NaN"),
    # frequencies (command 01)
    pytest.param(lambda b: _d(b).set_frequency(-1), "within", id="frequency -1 Hz"),
    pytest.param(lambda b: _d(b).set_frequency(10000), "within", id="frequency 10000 Hz"),
    pytest.param(lambda b: _d(b).set_frequency(NAN), "number", id="frequency NaN"),
    pytest.param(lambda b: _d(b).set_frequency(INF), "within", id="frequency inf"),
    pytest.param(lambda b: _d(b).set_frequency(1.001), "resolution", id="frequency 1.001 Hz"),
    pytest.param(lambda b: _d(b).set_frequency(True), "number", id="frequency True"),
    pytest.param(lambda b: _d(b).set_frequency("50"), "number", id="frequency '50'"),  # type: ignore[arg-type]
    pytest.param(lambda b: _d(b).set_frequency(None), "number", id="frequency None"),  # type: ignore[arg-type]
    # parameter codes (commands 06 / 07)
    pytest.param(
        lambda b: _d(b).read_parameter_raw("X001"), "not a parameter code", id="code X001"
    ),
    pytest.param(lambda b: _d(b).read_parameter_raw("A01"), "not a parameter code", id="code A01"),
    pytest.param(lambda b: _d(b).read_parameter_raw("A0011"), "not a parameter", id="code A0011"),
    pytest.param(lambda b: _d(b).read_parameter_raw(""), "not a parameter code", id="code ''"),
    pytest.param(lambda b: _d(b).read_parameter_raw(" A020"), "not a parameter", id="code ' A020'"),
    pytest.param(
        lambda b: _d(b).read_parameter_raw("A\uff10\uff12\uff10"),
        "not a parameter",
        id="wide digits",
    ),
    pytest.param(
        lambda b: _d(b).read_parameter_raw("AA20"), "not a parameter code", id="code AA20"
    ),
    pytest.param(lambda b: _d(b).read_parameter_raw(1234), "must be a str", id="code 1234"),  # type: ignore[arg-type]
    pytest.param(lambda b: _d(b).read_parameter(None), "must be a str", id="code None"),  # type: ignore[arg-type]
    pytest.param(
        lambda b: _d(b).write_parameter("Z999", 1), "not a parameter code", id="write Z999"
    ),
    # parameter values (command 07)
    pytest.param(lambda b: _d(b).write_parameter("A020", -1), "within", id="A020 = -1 Hz"),
    pytest.param(lambda b: _d(b).write_parameter("A020", 400.01), "within", id="A020 = 400.01"),
    pytest.param(lambda b: _d(b).write_parameter("A020", 1.001), "resolution", id="A020 = 1.001"),
    pytest.param(lambda b: _d(b).write_parameter("A020", NAN), "number", id="A020 = NaN"),
    pytest.param(lambda b: _d(b).write_parameter("A020", INF), "within", id="A020 = inf"),
    pytest.param(lambda b: _d(b).write_parameter("A020", True), "number", id="A020 = True"),
    pytest.param(lambda b: _d(b).write_parameter("A020", "1"), "number", id="A020 = '1'"),  # type: ignore[arg-type]
    pytest.param(lambda b: _d(b).write_parameter("C078", 0.5), "resolution", id="C078 = 0.5 ms"),
    pytest.param(lambda b: _d(b).write_parameter("F002", 0), "within", id="F002 = 0 s"),
    pytest.param(lambda b: _d(b).write_parameter_raw("A020", -1), "within", id="raw -1"),
    pytest.param(lambda b: _d(b).write_parameter_raw("A020", 10**8), "within", id="raw 10**8"),
    pytest.param(lambda b: _d(b).write_parameter_raw("A020", 1.5), "must be an int", id="raw 1.5"),  # type: ignore[arg-type]
    pytest.param(
        lambda b: _d(b).write_parameter_raw("A020", True), "must be an int", id="raw True"
    ),
    pytest.param(lambda b: _d(b).write_parameter_raw("A020", "1"), "must be an int", id="raw '1'"),  # type: ignore[arg-type]
    # terminals (command 02)
    pytest.param(lambda b: _d(b).set_terminals(1 << 10), "unassigned", id="terminal bit 10"),
    pytest.param(lambda b: _d(b).set_terminals(1 << 19), "unassigned", id="terminal bit 19"),
    pytest.param(lambda b: _d(b).set_terminals(1 << 63), "unassigned", id="terminal bit 63"),
    pytest.param(lambda b: _d(b).set_terminals(1 << 64), "64 bits", id="terminal bit 64"),
    pytest.param(lambda b: _d(b).set_terminals(-1), "InputTerminal", id="terminals -1"),
    pytest.param(lambda b: _d(b).set_terminals(True), "InputTerminal", id="terminals True"),
    pytest.param(lambda b: _d(b).set_terminals(1.0), "InputTerminal", id="terminals 1.0"),  # type: ignore[arg-type]
    # broadcasts
    pytest.param(lambda b: b.broadcast.set_frequency(-5), "within", id="broadcast frequency -5"),
    pytest.param(
        lambda b: b.broadcast.write_parameter("A0", 1), "not a parameter", id="broadcast A0"
    ),
    # pollers
    pytest.param(lambda b: sj.Poller(reads=["speed"]), "unknown reads", id="poller read 'speed'"),  # type: ignore[list-item]
    pytest.param(lambda b: sj.Poller(interval_s=-1), "interval_s", id="poller interval -1"),
    pytest.param(lambda b: sj.Poller(offline_after=0), "offline_after", id="poller offline 0"),
    pytest.param(lambda b: sj.Poller(parameters=["X1"]), "not a parameter", id="poller code X1"),
    pytest.param(lambda b: sj.Poller().add(b, [0]), "1..32", id="poller node 0"),
]


@pytest.mark.parametrize(("call", "match"), DRIVE_CASES)
async def test_drive_api_refuses_before_the_wire(rig: Rig, call: DriveCall, match: str) -> None:
    assert_refused(await outcome(lambda: call(rig.bus)), sj.LocalProtocolError, match)
    assert rig.written == [], "a refused request reached the line"
    assert rig.heard() == 0
    assert rig.bus.stats.transactions.requests == 0


# -- raw requests (the sans-IO encoder) --------------------------------------------------

REQUEST_CASES = [
    pytest.param(1, 12, b"", "unknown command", id="command 0C"),
    pytest.param(1, -1, b"", "unknown command", id="command -1"),
    pytest.param(1, "00", b"", "must be a Command", id="command '00'"),
    pytest.param(1, None, b"", "must be a Command", id="command None"),
    pytest.param(0, 0, b"1", "1..32", id="node 0"),
    pytest.param(sj3.BROADCAST, sj3.Command.READ_STATUS, b"", "may not be broadcast", id="FF 04"),
    pytest.param(sj3.BROADCAST, sj3.Command.RECALCULATE, b"", "may not be broadcast", id="FF 0B"),
    pytest.param(1, sj3.Command.RUN, b"3", "b'0', b'1' or b'2'", id="00 data 3"),
    pytest.param(1, sj3.Command.RUN, "1", "must be bytes", id="00 data str"),
    pytest.param(1, sj3.Command.SET_FREQUENCY, b"12345", "six decimal digits", id="01 five digits"),
    pytest.param(1, sj3.Command.SET_FREQUENCY, b"1234a6", "six decimal digits", id="01 letter"),
    pytest.param(1, sj3.Command.SET_TERMINALS, b"0" * 15, "sixteen hex", id="02 fifteen digits"),
    pytest.param(1, sj3.Command.SET_TERMINALS, b"0" * 15 + b"G", "sixteen hex", id="02 letter G"),
    pytest.param(1, sj3.Command.READ_STATUS, b"1", "takes no data", id="04 with data"),
    pytest.param(1, sj3.Command.READ_PARAMETER, b"A0201", "not a parameter code", id="06 A0201"),
    pytest.param(1, sj3.Command.WRITE_PARAMETER, b"A020123", "eight decimal digits", id="07 short"),
]


@pytest.mark.parametrize(("node", "command", "data", "match"), REQUEST_CASES)
def test_encoder_refuses(node: Any, command: Any, data: Any, match: str) -> None:
    exc = None
    try:
        sj3.encode_request(node, command, data)
    except Exception as caught:
        exc = caught
    assert_refused(exc, sj.LocalProtocolError, match)


# -- URLs and settings: refused before anything is opened ---------------------------------

URL_CASES = [
    pytest.param("", "non-empty", id="empty"),
    pytest.param("   ", "non-empty", id="blank"),
    pytest.param(None, "non-empty", id="None"),
    pytest.param(4001, "non-empty", id="a number"),
    pytest.param("http://127.0.0.1:4001", "scheme", id="http"),
    pytest.param("tcp://127.0.0.1", "host and a port", id="tcp without port"),
    pytest.param("tcp://:4001", "host and a port", id="tcp without host"),
    pytest.param("tcp://127.0.0.1:99999", "port", id="tcp port 99999"),
    pytest.param("tcp://127.0.0.1:-1", "port", id="tcp port -1"),
    pytest.param(
        "tcp://127.0.0.1:0",
        "port",
        id="tcp port 0",
    ),
    pytest.param(
        "tcp://[::1:4001",
        "",
        id="tcp bad IPv6",
    ),
    pytest.param("tcp://127.0.0.1:4001?baudrate=abc", "numbers", id="baudrate abc"),
    pytest.param("tcp://127.0.0.1:4001?baudrate=10", "baud rate", id="baudrate 10"),
    pytest.param("tcp://127.0.0.1:4001?baudrate=19200.5", "numbers", id="baudrate 19200.5"),
    pytest.param("tcp://127.0.0.1:4001?bytesize=9", "data bits", id="bytesize 9"),
    pytest.param("tcp://127.0.0.1:4001?parity=X", "parity", id="parity X"),
    pytest.param("tcp://127.0.0.1:4001?stopbits=3", "stop bits", id="stopbits 3"),
    pytest.param("tcp://127.0.0.1:4001?echo=maybe", "echo", id="echo maybe"),
    pytest.param("tcp://127.0.0.1:4001?baud=9600", "unknown option", id="typo baud"),
    pytest.param("serial://", "device path", id="serial without device"),
    pytest.param("serial:///dev/ttyS0?parity=Q", "parity", id="serial parity Q"),
    pytest.param(
        "serial:///dev/ttyS0?baudrate=0",
        "baud",
        id="serial baudrate 0",
    ),
    pytest.param("sim://?nodes=0", "nodes are 1..32", id="sim node 0"),
    pytest.param("sim://?nodes=1-40", "nodes are 1..32", id="sim nodes 1-40"),
    pytest.param("sim://?nodes=5-1", "backwards", id="sim nodes 5-1"),
    pytest.param("sim://?nodes=a", "not N or N-M", id="sim nodes a"),
    pytest.param("sim://?nodes=", "no nodes", id="sim no nodes"),
    pytest.param("sim://?wait_ms=x", "wait_ms", id="sim wait_ms x"),
    pytest.param("sim://?wait_ms=2000", "0..1000", id="sim wait_ms 2000"),
    pytest.param("sim://?pace=1&baudrate=0", "cannot be paced", id="sim pace at 0 bps"),
    pytest.param("sim://?factory_defaults=2", "true or false", id="sim factory_defaults 2"),
    pytest.param("sim://?foo=1", "unknown option", id="sim unknown option"),
]


@pytest.mark.parametrize(("url", "match"), URL_CASES)
async def test_bad_url_opens_nothing(url: Any, match: str) -> None:
    baseline = Baseline.take()

    async def open_it() -> None:
        async with sj.open_bus(url):
            pass

    assert_refused(await outcome(open_it), sj.LocalProtocolError, match)
    assert await baseline.leaks(settle_s=0.05) == []


SETTINGS_CASES = [
    pytest.param(lambda: sj.LineSettings(baudrate=10), "baud rate", id="line 10 bps"),
    pytest.param(lambda: sj.LineSettings(baudrate=19200.0), "int", id="line 19200.0 bps"),  # type: ignore[arg-type]
    pytest.param(lambda: sj.LineSettings(baudrate=True), "int", id="line True bps"),
    pytest.param(lambda: sj.LineSettings(bytesize=6), "data bits", id="line 6 data bits"),
    pytest.param(lambda: sj.LineSettings(parity="X"), "parity", id="line parity X"),  # type: ignore[arg-type]
    pytest.param(lambda: sj.LineSettings(stopbits=3), "stop bits", id="line 3 stop bits"),
    pytest.param(lambda: sj.LineSettings.parse(parity="mark"), "parity", id="line parity mark"),
    pytest.param(lambda: sj.BusTiming(margin_s=-1), "margin_s", id="timing margin -1"),
    pytest.param(lambda: sj.BusTiming(guard_chars=NAN), "guard_chars", id="timing guard NaN"),
    pytest.param(lambda: sj.BusTiming(fixed_timeout_s=0), "timeout", id="timing timeout 0"),
    pytest.param(lambda: sj.ReconnectPolicy(initial_s=0), "reconnect", id="reconnect 0 s"),
    pytest.param(lambda: sj.ReconnectPolicy(factor=0.5), "reconnect", id="reconnect factor 0.5"),
    pytest.param(lambda: sj.ReconnectPolicy(jitter=2), "reconnect", id="reconnect jitter 2"),
    pytest.param(lambda: sj.ReconnectPolicy(connect_timeout_s=0), "connect", id="connect 0 s"),
]


@pytest.mark.parametrize(("make", "match"), SETTINGS_CASES)
def test_bad_setting_is_refused(make: Callable[[], Any], match: str) -> None:
    exc = None
    try:
        make()
    except Exception as caught:
        exc = caught
    assert_refused(exc, sj.LocalProtocolError, match)


OPEN_CASES = [
    pytest.param("sim://", {"timeout": 0}, "timeout", id="timeout 0"),
    pytest.param("sim://", {"timeout": -1}, "timeout", id="timeout -1"),
    pytest.param("sim://", {"timeout": NAN}, "timeout", id="timeout NaN"),
    pytest.param(
        "sim://",
        {"timeout": "1"},
        "timeout",
        id="timeout '1'",
    ),
    pytest.param(
        "sim://",
        {"timeout": INF},
        "timeout",
        id="timeout inf",
    ),
    pytest.param("sim://", {"retries": -1}, "retries", id="retries -1"),
    pytest.param("sim://", {"retries": 1.5}, "retries", id="retries 1.5"),
    pytest.param("sim://", {"retries": True}, "retries", id="retries True"),
    pytest.param("sim://", {"retries": "2"}, "retries", id="retries '2'"),
    pytest.param("tcp://127.0.0.1:4001", {"faults": (None, None)}, "sim://", id="faults on tcp"),
]


@pytest.mark.parametrize(("url", "kwargs", "match"), OPEN_CASES)
async def test_bad_open_argument_opens_nothing(
    url: str, kwargs: dict[str, Any], match: str
) -> None:
    baseline = Baseline.take()

    async def open_it() -> None:
        async with sj.open_bus(url, **kwargs):
            pass

    assert_refused(await outcome(open_it), sj.LocalProtocolError, match)
    assert await baseline.leaks(settle_s=0.05) == []


# -- a read-only bus ---------------------------------------------------------------------

MUTATING = [
    ("00", "run forward", lambda d: d.run_forward()),
    ("00", "run reverse", lambda d: d.run_reverse()),
    ("00", "stop", lambda d: d.stop()),
    ("01", "frequency", lambda d: d.set_frequency(10)),
    ("02", "terminals", lambda d: d.set_terminals(sj.InputTerminal.FW)),
    ("07", "write", lambda d: d.write_parameter("A020", 5)),
    ("07", "write raw", lambda d: d.write_parameter_raw("A020", 500)),
    ("08", "initialize", lambda d: d.initialize()),
    ("0A", "store", lambda d: d.store()),
    ("0B", "recalculate", lambda d: d.recalculate_constants()),
]
READ_ONLY_CASES = [
    pytest.param(target, call, command, id=f"{target} {command} {name}")
    for target in ("drive", "broadcast")
    for command, name, call in MUTATING
    if not (target == "broadcast" and command == "0B")  # 0B may not be broadcast at all
]


@pytest.mark.parametrize(("target", "call", "command"), READ_ONLY_CASES)
async def test_read_only_bus_refuses_every_change(
    target: str, call: Callable[[Any], Any], command: str
) -> None:
    async with sj.open_bus("sim://?nodes=1-2", read_only=True) as bus:
        written: list[bytes] = []
        bus.trace = lambda r: written.append(r.data) if r.direction == "tx" else None
        subject = bus.drive(1) if target == "drive" else bus.broadcast
        assert_refused(await outcome(lambda: call(subject)), sj.ReadOnlyError, command)
        assert written == []
        # Reads still work on a read-only bus.
        assert await bus.drive(1).read_parameter_raw("C072") == 1
