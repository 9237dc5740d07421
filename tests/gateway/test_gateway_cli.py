"""``sj300 gateway`` as a user runs it: a subprocess, its stdout read as it comes, SIGTERM.

The simulated line is served in the test's process (the ``sim_line`` fixture), with a line
log: it shows what the gateway sent, from start-up to exit. A gateway that only serves
reads never sends a command, neither on start-up nor on a clean stop; one that stops with
a control lease held sends that drive's stop, once, before it exits.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import signal
import sys
import textwrap
from collections.abc import AsyncIterator
from contextlib import AbstractAsyncContextManager
from pathlib import Path

import pytest
from cli.clirun import TIMEOUT, Result, running, sj300
from pymodbus.client import AsyncModbusTcpClient

from sj300_async import sj300 as sj3
from sj300_async.cli._install import gateway_install_command
from sj300_async.simulator import RunState

from .conftest import SimLine

#: Seconds a clean stop may take, SIGTERM to exit.
STOP_WITHIN_S = 5.0
_MODBUS = re.compile(r"modbus on (\S+):(\d+)")
_METRICS = re.compile(r"http on http://(\S+):(\d+)/ \(workbench, /metrics, /healthz\)")


def gateway_process(*args: str) -> AbstractAsyncContextManager[asyncio.subprocess.Process]:
    """``sj300 gateway ARGS``, stdout and stderr on pipes; killed if still running at the end."""
    return running("gateway", *args)


async def read_servers(proc: asyncio.subprocess.Process, *kinds: str) -> dict[str, int]:
    """The ports of the servers (``"modbus"``, ``"metrics"``) as the gateway prints them."""
    assert proc.stdout is not None
    assert proc.stderr is not None
    ports: dict[str, int] = {}
    async with asyncio.timeout(TIMEOUT):
        while set(ports) != set(kinds):
            line = (await proc.stdout.readline()).decode()
            if not line:
                err = (await proc.stderr.read()).decode()
                raise AssertionError(f"the gateway ended (status {await proc.wait()}): {err}")
            if found := _MODBUS.fullmatch(line.strip()):
                assert found[1] == "127.0.0.1", line
                ports["modbus"] = int(found[2])
            elif found := _METRICS.fullmatch(line.strip()):
                assert found[1] == "127.0.0.1", line
                ports["metrics"] = int(found[2])
            else:
                raise AssertionError(f"unexpected line on stdout: {line!r}")
    return ports


async def stop(proc: asyncio.subprocess.Process) -> Result:
    """SIGTERM; the exit status and what is left of stdout and stderr."""
    proc.send_signal(signal.SIGTERM)
    async with asyncio.timeout(STOP_WITHIN_S):
        out, err = await proc.communicate()
    assert proc.returncode is not None
    return Result(proc.returncode, out.decode(), err.decode())


async def http_get(port: int, path: str) -> tuple[int, str]:
    """One ``GET``, the connection closed by the server after its answer (asked to: an
    HTTP/1.1 server keeps it open, and this read to the end waited out its 5 s keep-alive
    at every call): status and body."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        request = f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
        writer.write(request.encode())
        await writer.drain()
        async with asyncio.timeout(TIMEOUT):
            data = await reader.read()
    finally:
        writer.close()
        await writer.wait_closed()
    head, _, body = data.partition(b"\r\n\r\n")
    return int(head.split()[1]), body.decode()


@contextlib.asynccontextmanager
async def client_of(port: int) -> AsyncIterator[AsyncModbusTcpClient]:
    client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=5, retries=0)
    assert await client.connect()
    try:
        yield client
    finally:
        client.close()


async def until_polled(client: AsyncModbusTcpClient, *units: int) -> None:
    """Ask until each unit's monitor is served (a question to the gateway each time, no sleep)."""
    async with asyncio.timeout(TIMEOUT):
        for unit in units:
            while (await client.read_holding_registers(100, count=4, device_id=unit)).isError():
                pass


def _config(tmp_path: Path, url: str, body: str = "") -> Path:
    path = tmp_path / "gateway.toml"
    path.write_text(
        textwrap.dedent(
            f"""\
            [modbus]
            listen = "127.0.0.1:0"
            [[lines]]
            url = "{url}"
            nodes = "1-2"
            interval_s = 0.1
            """
        )
        + textwrap.dedent(body)
    )
    return path


def _commands(sim_line: SimLine) -> list[tuple[int, sj3.Command, bytes]]:
    """The requests on the line that change a drive: (node, command, data)."""
    return [
        (r.node, r.command, r.data)
        for r in sim_line.log.requests()
        if r.command in sj3.MUTATING_COMMANDS
    ]


@pytest.mark.parametrize("mode", ["flags", "config"])
async def test_serves_then_stops_on_sigterm_without_a_command(
    mode: str, sim_line: SimLine, tmp_path: Path
) -> None:
    if mode == "flags":
        args = ["--url", sim_line.url, "--nodes", "1-2", "--interval", "0.1"]
        args += ["--modbus", "127.0.0.1:0", "--metrics", "127.0.0.1:0"]
    else:
        metrics = '[metrics]\nlisten = "127.0.0.1:0"\n'
        args = ["--config", str(_config(tmp_path, sim_line.url, metrics))]
    async with gateway_process(*args) as proc:
        ports = await read_servers(proc, "modbus", "metrics")
        async with client_of(ports["modbus"]) as client:
            await until_polled(client, 1, 2)
            for unit in (1, 2):
                ident = await client.read_holding_registers(0, count=4, device_id=unit)
                assert ident.registers[0] == 1  # online
                assert ident.registers[2:] == [1, unit]  # SJ300, its node
                monitor = await client.read_holding_registers(100, count=4, device_id=unit)
                assert monitor.registers == [0, 0, 0, 0]  # stopped
            absent = await client.read_holding_registers(0, count=4, device_id=3)
            assert absent.isError()
            assert absent.exception_code == 0x0A  # unit 3: not in --nodes
        status, body = await http_get(ports["metrics"], "/metrics")
        assert status == 200
        assert re.search(r'^sj300_drive_online\{line="line1",node="2"\} 1\.0$', body, re.M), body
        assert re.search(r'^sj300_modbus_requests_total\{client="127.0.0.1"\} \d', body, re.M)
        assert await http_get(ports["metrics"], "/healthz") == (200, "ok\n")
        result = await stop(proc)
    assert result.code == 0, result
    assert result.out == ""
    assert "Traceback" not in result.err, result
    assert {r.node for r in sim_line.log.requests()} == {1, 2}  # it polled
    assert _commands(sim_line) == []  # and never wrote, starting or stopping
    assert sim_line.log.interleaved() == []


async def test_a_lease_held_at_sigterm_sends_one_stop(sim_line: SimLine, tmp_path: Path) -> None:
    grant = """\
        lease_s = 60
        [[lines.writes]]
        nodes = "1"
        control = true
        [gateway]
        audit_log = "audit.jsonl"
        """
    async with gateway_process("--config", str(_config(tmp_path, sim_line.url, grant))) as proc:
        ports = await read_servers(proc, "modbus")
        async with client_of(ports["modbus"]) as client:
            await until_polled(client, 1, 2)
            for register, value in ((1000, 1), (1003, 1000), (1002, 1)):  # lease, 10 Hz, run
                response = await client.write_register(register, value, device_id=1)
                assert not response.isError(), (register, response)
            assert sim_line.sim.drives[1].parameters["F001"] == 1000
            # Node 2 is not granted control: refused, and audited as such.
            refused = await client.write_register(1002, 1, device_id=2)
            assert refused.isError(), refused
            assert refused.exception_code == 0x01, refused
            run = sim_line.sim.drives[1].state(asyncio.get_running_loop().time())
            assert run.outputting
            result = await stop(proc)  # the client is still connected, its lease held
    assert result.code == 0, result
    assert "the control lease of 127.0.0.1 lapsed: stop" in result.err
    stop_request = (1, sj3.Command.RUN, b"0")
    assert _commands(sim_line) == [
        (1, sj3.Command.SET_FREQUENCY, b"001000"),
        (1, sj3.Command.RUN, b"1"),
        stop_request,
    ]
    # The drive answered the stop (the gateway waited for it) and is on its way down.
    frames = sim_line.log.frames()
    at = next(
        i for i, f in enumerate(frames) if f[1] == "rx" and f[3] == sj3.Request.build(*stop_request)
    )
    assert frames[at + 1][1:3] == ("tx", 1)
    state = sim_line.sim.drives[1].state(asyncio.get_running_loop().time())
    assert state in (RunState.DECELERATING, RunState.STOPPED)
    audit = [json.loads(line) for line in (tmp_path / "audit.jsonl").read_text().splitlines()]
    assert [(a["node"], a["what"], a["result"]) for a in audit] == [
        (1, "heartbeat", "ok"),
        (1, "set frequency (Hz)", "ok"),
        (1, "command", "ok"),
        (2, "command", "refused"),
        (1, "lease lapsed: stop", "ok"),
    ]
    assert (audit[3]["reason"], audit[3]["detail"]) == (
        "not_allowed",
        "the configuration does not allow control of this drive",
    )
    assert audit[4]["new"].startswith("confirmed stopped")
    assert "reason" not in audit[0]
    assert sim_line.log.interleaved() == []


@pytest.mark.parametrize(
    ("body", "line", "message"),
    [
        ("lease_s = 0\n", 7, "lines[0].lease_s: must be > 0, got 0"),
        (
            '[metrics]\nlistn = "127.0.0.1:0"\n',
            8,
            "metrics.listn: unknown key 'listn' (did you mean 'listen'?)",
        ),
    ],
    ids=["bad-value", "misspelt-key"],
)
async def test_a_bad_config_file_starts_nothing(
    body: str, line: int, message: str, sim_line: SimLine, tmp_path: Path
) -> None:
    path = _config(tmp_path, sim_line.url, body)
    result = await sj300("gateway", "--config", str(path))
    result.assert_one_line_error(2)
    assert result.err == f"sj300 gateway: error: {path}:{line}: {message}\n"
    assert result.out == ""  # no server line: nothing listened
    assert sim_line.log.chunks == []  # and the line was never opened


@pytest.mark.parametrize("flag", [["--url", "tcp://127.0.0.1:1"], ["--nodes", "1-2"]])
async def test_config_and_line_flags_together_are_refused(
    flag: list[str], sim_line: SimLine, tmp_path: Path
) -> None:
    path = _config(tmp_path, sim_line.url)
    result = await sj300("gateway", "--config", str(path), *flag)
    result.assert_one_line_error(2, flag[0])
    assert result.out == ""
    assert sim_line.log.chunks == []


async def test_no_arguments_is_a_usage_error() -> None:
    result = await sj300("gateway")
    result.assert_one_line_error(2, "sj300 gateway: error: give --config FILE, or --url URL")


@pytest.mark.parametrize(
    ("module", "flag"),
    [
        ("orjson", ["--mqtt", "mqtt://127.0.0.1:1"]),  # protobuf is Sparkplug's only
        ("prometheus_client", ["--metrics", "127.0.0.1:0"]),
    ],
)
async def test_a_missing_library_names_the_extra_and_how_to_install_it(
    module: str, flag: list[str]
) -> None:
    args = ["gateway", "--url", "sim://?nodes=1", "--nodes", "1", *flag]
    code = (
        f"import sys; sys.modules[{module!r}] = None; from sj300_async.cli import main; "
        f"sys.exit(main({args!r}))"
    )
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-c", code, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode is not None
    result = Result(proc.returncode, out.decode(), err.decode())
    result.assert_one_line_error(2, f"needs the gateway extra ({module} is missing): ")
    # In this checkout's .venv: make gateway (tests/cli/test_cli_install.py: each form).
    assert result.err.endswith(f": {gateway_install_command()}\n"), result.err
