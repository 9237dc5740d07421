"""``sj300 gateway`` as a service: it comes up with a line down, says which port it cannot have, and
stops at once on a signal.

Each test runs the real command in a subprocess on free loopback ports.

- A line whose device server is down at start (a closed port, a serial device not plugged in)
  is served as one lost later: the gateway starts, serves the other lines, its drives answer
  0x0B, /healthz answers 503 naming it, one WARNING names it, and it is connected when the
  server comes up. A URL that can never work is still refused at start, exit 2.
- A northbound that cannot listen (its port in use, an address not on this host) is one line
  naming the section and the address, exit 2: no traceback.
- SIGTERM ends it with 0 and SIGINT (Ctrl-C) with 130, as every other command, promptly: also
  while a line's connection attempt is still under way at start.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import signal
import socket
import textwrap
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest
from cli.clirun import TIMEOUT, Result, closed_port, running, sj300
from mqtt_broker import running_broker
from waiting import wait_for

from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .test_gateway_cli import client_of, http_get, until_polled

#: A generous bound on a stop, signal to exit (the issue wants 0.5 s; the figures are in
#: the report of issue 26, measured over 20 runs: a loaded machine must not fail this test).
STOP_WITHIN_S = 5.0
_PORT = re.compile(r"(modbus) on \S+:(\d+)|(http) on http://\S+:(\d+)/ |(mqtt) to ")


async def announced(proc: asyncio.subprocess.Process, count: int) -> dict[str, int]:
    """The first *count* lines of stdout: ``{"modbus": port, "http": port, "mqtt": 0}``."""
    assert proc.stdout is not None
    assert proc.stderr is not None
    found: dict[str, int] = {}
    async with asyncio.timeout(TIMEOUT):
        while len(found) < count:
            line = (await proc.stdout.readline()).decode()
            if not line:
                err = (await proc.stderr.read()).decode()
                raise AssertionError(f"the gateway ended (status {await proc.wait()}): {err}")
            match = _PORT.match(line)
            assert match is not None, f"unexpected line on stdout: {line!r}"
            groups = [g for g in match.groups() if g is not None]
            found[groups[0]] = int(groups[1]) if len(groups) > 1 else 0
    return found


async def stopped_by(proc: asyncio.subprocess.Process, sig: signal.Signals) -> tuple[Result, float]:
    """Send *sig*; the exit status, the rest of stdout and stderr, and the seconds it took."""
    start = time.monotonic()
    proc.send_signal(sig)
    async with asyncio.timeout(STOP_WITHIN_S):
        out, err = await proc.communicate()
    assert proc.returncode is not None
    return Result(proc.returncode, out.decode(), err.decode()), time.monotonic() - start


async def until_healthz(port: int, status: int) -> str:
    """Ask /healthz until it answers *status*; its body."""
    async with asyncio.timeout(TIMEOUT):
        while True:
            got, body = await http_get(port, "/healthz")
            if got == status:
                return body


# -- a line down at start ----------------------------------------------------------------------


def _two_lines(tmp_path: Path, down_url: str) -> Path:
    path = tmp_path / "gateway.toml"
    path.write_text(
        textwrap.dedent(
            f"""\
            [modbus]
            listen = "127.0.0.1:0"
            [metrics]
            listen = "127.0.0.1:0"
            [[lines]]
            name = "hall"
            url = "sim://?nodes=1-2"
            nodes = "1-2"
            interval_s = 0.1
            [[lines]]
            name = "yard"
            url = "{down_url}"
            nodes = "3"
            interval_s = 0.1
            """
        )
    )
    return path


async def test_a_line_down_at_start_is_served_offline_and_comes_up(tmp_path: Path) -> None:
    port = closed_port()  # nobody listens there: connection refused
    url = f"tcp://127.0.0.1:{port}"
    async with running("gateway", "--config", str(_two_lines(tmp_path, url))) as proc:
        ports = await announced(proc, 2)
        async with client_of(ports["modbus"]) as client:
            await until_polled(client, 1, 2)  # the healthy line is served
            async with asyncio.timeout(TIMEOUT):  # offline after the poller's failed polls
                while (await client.read_holding_registers(0, count=1, device_id=3)).registers[0]:
                    pass
            monitor = await client.read_holding_registers(100, count=4, device_id=3)
            assert monitor.isError()
            assert monitor.exception_code == 0x0B  # as for a line lost later
            assert await until_healthz(ports["http"], 503) == "line yard: link down\n"
            server = await serve_tcp(SimulatedBus([3]), port=port)  # the device server is back
            async with server:
                await until_polled(client, 3)  # reconnected with its back-off, and polled
                assert await until_healthz(ports["http"], 200) == "ok\n"
                result, _ = await stopped_by(proc, signal.SIGTERM)
    assert result.code == 0, result
    assert "Traceback" not in result.err, result.err
    down = [line for line in result.err.splitlines() if line.startswith("line yard:")]
    assert down == [
        f"line yard: {url} is down ([Errno 111] Connect call failed ('127.0.0.1', {port})): "
        "its drives are offline until it connects"
    ]


async def test_a_serial_device_not_there_is_a_line_down(tmp_path: Path) -> None:
    url = f"serial://{tmp_path}/ttyUSB9?baudrate=19200"  # a USB adapter not plugged in
    async with running("gateway", "--config", str(_two_lines(tmp_path, url))) as proc:
        ports = await announced(proc, 2)
        async with client_of(ports["modbus"]) as client:
            await until_polled(client, 1, 2)
        assert await until_healthz(ports["http"], 503) == "line yard: link down\n"
        result, _ = await stopped_by(proc, signal.SIGTERM)
    assert result.code == 0, result
    assert f"line yard: {url} is down (cannot open serial port" in result.err


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("tcp://127.0.0.1", "tcp URL needs a host and a port"),
        ("telnet://127.0.0.1:23", "unknown bus URL scheme 'telnet'"),
        ("tcp://127.0.0.1:99999", "bad port"),
    ],
    ids=["no-port", "unknown-scheme", "bad-port"],
)
async def test_a_url_that_can_never_work_is_still_refused_at_start(url: str, message: str) -> None:
    result = await sj300("gateway", "--url", url, "--nodes", "1", "--modbus", "127.0.0.1:0")
    result.assert_one_line_error(2, "--url: ", message)
    assert result.out == ""


# -- ports --------------------------------------------------------------------------------------


@pytest.fixture
def taken_port() -> Iterator[int]:
    """A loopback port another program listens on."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        yield listener.getsockname()[1]


@pytest.mark.parametrize(
    ("flag", "section"),
    [("--modbus", "modbus"), ("--http", "http"), ("--metrics", "http")],  # --metrics: the old name
)
async def test_a_port_in_use_is_one_line_naming_it(
    flag: str, section: str, taken_port: int
) -> None:
    endpoint = f"127.0.0.1:{taken_port}"
    result = await sj300("gateway", "--url", "sim://?nodes=1", "--nodes", "1", flag, endpoint)
    result.assert_one_line_error(2)
    assert result.err == (
        f"sj300 gateway: error: {section}: cannot listen on {endpoint}: Address already in use\n"
    )
    assert result.out == ""


async def test_an_address_not_on_this_host_is_one_line_naming_it() -> None:
    endpoint = "192.0.2.1:1502"  # TEST-NET-1: on no host
    result = await sj300("gateway", "--url", "sim://?nodes=1", "--nodes", "1", "--modbus", endpoint)
    result.assert_one_line_error(2)
    assert result.err == (
        f"sj300 gateway: error: modbus: cannot listen on {endpoint}: "
        "Cannot assign requested address\n"
    )


# -- signals ------------------------------------------------------------------------------------


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 0), (signal.SIGINT, 130)])
async def test_a_signal_ends_a_serving_gateway_at_once(
    sig: signal.Signals, code: int, tmp_path: Path
) -> None:
    async with running_broker(tmp_path) as broker:
        args = ["--url", "sim://?nodes=1-8", "--nodes", "1-8", "--interval", "0.1", "--id", "gw"]
        args += ["--modbus", "127.0.0.1:0", "--metrics", "127.0.0.1:0", "--mqtt", broker.url]
        async with running("gateway", *args) as proc:
            ports = await announced(proc, 3)
            async with client_of(ports["modbus"]) as client:
                await until_polled(client, *range(1, 9))
                async with asyncio.timeout(TIMEOUT):  # the broker took the bridge's session
                    while (
                        "sj300_mqtt_connects_total 1.0"
                        not in (await http_get(ports["http"], "/metrics"))[1]
                    ):
                        pass
                result, took = await stopped_by(proc, sig)  # a Modbus client still connected
    assert result.code == code, result
    assert result.err == "stopping\n", result.err
    print(f"{sig.name}: exit {result.code} {took * 1000:.0f} ms after the signal")


@contextlib.asynccontextmanager
async def silent_servers(
    count: int, log: list[str] | None = None
) -> AsyncIterator[tuple[list[int], asyncio.Event]]:
    """*count* TCP servers that take connections and never answer (hung RFC 2217 servers):
    their ports, and an event set at the first connection (*log* gets "open" and "closed")."""
    connected = asyncio.Event()
    events = [] if log is None else log

    async def hold(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        connected.set()
        events.append("open")
        await reader.read()
        events.append("closed")
        writer.close()

    async with contextlib.AsyncExitStack() as stack:
        ports = []
        for _ in range(count):
            server = await stack.enter_async_context(
                await asyncio.start_server(hold, "127.0.0.1", 0)
            )
            ports.append(server.sockets[0].getsockname()[1])
        yield ports, connected


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 0), (signal.SIGINT, 130)])
async def test_a_signal_ends_a_gateway_still_connecting_its_lines(
    sig: signal.Signals, code: int, tmp_path: Path
) -> None:
    # Three lines whose servers never agree the RFC 2217 options: 2 s each at start.
    async with silent_servers(3) as (ports, connected):
        lines = "".join(
            f'[[lines]]\nname = "l{n}"\nurl = "rfc2217://127.0.0.1:{port}?baudrate=9600"\n'
            f'nodes = "{n}"\n'
            for n, port in enumerate(ports, 1)
        )
        config = tmp_path / "gateway.toml"
        config.write_text(f'[modbus]\nlisten = "127.0.0.1:0"\n{lines}')
        async with running("gateway", "--config", str(config)) as proc:
            async with asyncio.timeout(TIMEOUT):
                await connected.wait()  # the gateway is in its first connection attempt
            result, _ = await stopped_by(proc, sig)  # not after the three attempts' 6 s
    assert result.code == code, result
    assert result.out == ""  # it never served
    assert result.err == "stopping\n", result.err


async def test_the_lines_are_connected_together_at_start(tmp_path: Path) -> None:
    # One after another, three silent lines would hold the start up for three
    # attempts (2 s each); together, for one. Each attempt is open at once.
    log: list[str] = []
    async with silent_servers(3, log) as (ports, _):
        lines = "".join(
            f'[[lines]]\nname = "l{n}"\nurl = "rfc2217://127.0.0.1:{port}?baudrate=9600"\n'
            f'nodes = "{n}"\n'
            for n, port in enumerate(ports, 1)
        )
        config = tmp_path / "gateway.toml"
        config.write_text(f'[modbus]\nlisten = "127.0.0.1:0"\n{lines}')
        async with running("gateway", "--config", str(config)) as proc:
            await wait_for(lambda: log.count("open") >= 3, "three attempts", timeout=TIMEOUT)
            assert log == ["open", "open", "open"]  # no attempt ended before the last began
            await stopped_by(proc, signal.SIGTERM)
