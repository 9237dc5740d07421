"""``sj300 simulate --protocol fr700`` as a user runs it: a subprocess, raw bytes over TCP."""

from __future__ import annotations

import asyncio
import re
import signal
import sys

import pytest

from sj300_async.cli import main

from .fr700wire import ack, data_reply, nak, request

TIMEOUT = 10.0


async def start(*args: str) -> asyncio.subprocess.Process:
    return await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "simulate",
        "--protocol",
        "fr700",
        *args,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )


async def port_of(proc: asyncio.subprocess.Process) -> int:
    assert proc.stdout is not None
    line = (await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)).decode()
    match = re.fullmatch(r"listening on tcp://127\.0\.0\.1:(\d+)\n", line)
    assert match, line
    return int(match[1])


async def ask(port: int, raw: bytes, n: int) -> bytes:
    reader, writer = await asyncio.wait_for(asyncio.open_connection("127.0.0.1", port), TIMEOUT)
    try:
        writer.write(raw)
        return await asyncio.wait_for(reader.readexactly(n), TIMEOUT)
    finally:
        writer.close()


async def finish(proc: asyncio.subprocess.Process) -> tuple[int | None, str]:
    proc.send_signal(signal.SIGINT)
    _out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    return proc.returncode, err.decode()


async def test_factory_line_settings_by_default() -> None:
    proc = await start("--listen", "tcp://127.0.0.1:0", "--nodes", "0-3")
    try:
        port = await port_of(proc)
        assert await ask(port, request(3, 0xED, b"1770"), 4) == ack(3)
        reply = data_reply(3, b"1770")
        assert await ask(port, request(3, 0x6D), len(reply)) == reply
        mode = data_reply(0, b"0000")  # network operation mode
        assert await ask(port, request(0, 0x7B), len(mode)) == mode
        code, err = await finish(proc)
        assert code == 130  # Ctrl-C, as every command
        assert "FR-700, network mode, terminator cr" in err
        assert "Traceback" not in err
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_line_settings_are_configurable() -> None:
    proc = await start(
        "--listen", "tcp://127.0.0.1:0", "--nodes", "31", "--terminator", "none",
        "--no-wait-field", "--wait-ms", "20", "--factory-defaults",
    )  # fmt: skip
    try:
        port = await port_of(proc)
        raw = request(31, 0xFA, b"02", wait=b"", term=b"")
        assert await ask(port, raw, 4) == nak(31, b"A", b"")  # external mode: mode error
        reply = data_reply(31, b"0014", b"")  # Pr.123 = 20 ms
        assert await ask(port, request(31, 0xFF, b"01", wait=b"", term=b""), 3) == ack(31, b"")
        assert await ask(port, request(31, 0x17, wait=b"", term=b""), len(reply)) == reply
        assert (await finish(proc))[0] == 130
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--nodes", "0-32"], "stations are 0..31"),
        (["--wait-ms", "20"], "Pr.123 is 9999"),
        (["--no-wait-field", "--wait-ms", "200"], "0..150"),
        (["--terminator", "lf"], "invalid choice"),
    ],
)
def test_bad_fr700_arguments_print_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    code: int | str | None
    try:
        code = main(["simulate", "--protocol", "fr700", "--listen", "tcp://127.0.0.1:0", *args])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert message in err
