"""``sj300 simulate`` as a user runs it: a subprocess, raw bytes over TCP and pty, then a signal."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import socket
import sys
from collections.abc import AsyncIterator

import pytest

from sj300_async.cli import main
from sj300_async.cli._args import format_nodes, parse_listen, parse_nodes

from .simwire import ack, ack_data, nak, request

TIMEOUT = 10.0  # generous: a cold interpreter start on a loaded CI machine

Process = asyncio.subprocess.Process


async def start(*args: str) -> Process:
    return await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "simulate",
        *args,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )


async def read_line(proc: Process) -> str:
    assert proc.stdout is not None
    return (await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)).decode()


async def stop(proc: Process, sig: int = signal.SIGTERM) -> tuple[int, str]:
    proc.send_signal(sig)
    _out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode is not None
    return proc.returncode, err.decode()


@pytest.fixture
async def procs() -> AsyncIterator[list[Process]]:
    started: list[Process] = []
    yield started
    for proc in started:  # whatever a failing test left running
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def tcp_port(proc: Process) -> int:
    line = await read_line(proc)
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


async def test_simulate_over_tcp_then_sigint_exits_130(procs: list[Process]) -> None:
    proc = await start("--listen", "tcp://127.0.0.1:0", "--nodes", "1-2")
    procs.append(proc)
    port = await tcp_port(proc)
    assert port != 0  # the real bound port is printed
    assert await ask(port, bytes.fromhex("02 30 31 30 30 31 33 30 0D"), 7) == ack(b"01")
    assert await ask(port, request(b"02", b"06", b"C072"), 15) == ack_data(b"02", b"00000002")
    code, err = await stop(proc, signal.SIGINT)
    assert code == 130  # Ctrl-C, as every command
    assert "Traceback" not in err


async def test_sigterm_exits_0(procs: list[Process]) -> None:
    proc = await start("--listen", "tcp://127.0.0.1:0")
    procs.append(proc)
    await tcp_port(proc)
    code, err = await stop(proc, signal.SIGTERM)
    assert code == 0
    assert "Traceback" not in err


async def test_options_reach_the_drives(procs: list[Process]) -> None:
    proc = await start(
        "--listen", "tcp://127.0.0.1:0", "--nodes", "3", "--wait-ms", "30", "--factory-defaults"
    )
    procs.append(proc)
    port = await tcp_port(proc)
    assert await ask(port, request(b"03", b"06", b"C078"), 15) == ack_data(b"03", b"00000030")
    assert await ask(port, request(b"03", b"00", b"1"), 9) == nak(b"03", b"13")
    assert (await stop(proc))[0] == 0


async def test_pty_and_tcp_together(procs: list[Process]) -> None:
    proc = await start("--listen", "tcp://127.0.0.1:0", "--pty", "--baud", "115200", "--pace")
    procs.append(proc)
    await tcp_port(proc)
    line = await read_line(proc)
    assert line.startswith("listening on /dev/"), line
    path = line.split()[-1]
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    loop = asyncio.get_running_loop()
    readable = asyncio.Event()
    loop.add_reader(fd, readable.set)
    try:
        os.write(fd, request(b"01", b"0B"))
        reply = b""
        async with asyncio.timeout(TIMEOUT):
            while len(reply) < 7:
                await readable.wait()
                readable.clear()
                reply += os.read(fd, 64)
        assert reply == ack(b"01")
    finally:
        loop.remove_reader(fd)
        os.close(fd)
    assert (await stop(proc))[0] == 0


async def test_device_serves_an_existing_serial_port(procs: list[Process]) -> None:
    master, slave = os.openpty()  # the slave stands in for a real port
    loop = asyncio.get_running_loop()
    readable = asyncio.Event()
    os.set_blocking(master, False)
    loop.add_reader(master, readable.set)
    try:
        path = os.ttyname(slave)
        proc = await start("--device", path, "--nodes", "5", "--baud", "9600")
        procs.append(proc)
        assert await read_line(proc) == f"listening on {path}\n"
        os.write(master, request(b"05", b"06", b"C071"))
        reply = b""
        async with asyncio.timeout(TIMEOUT):
            while len(reply) < 15:
                await readable.wait()
                readable.clear()
                reply += os.read(master, 64)
        assert reply == ack_data(b"05", b"00000005")  # C071 = 05: 9600 bps
        assert (await stop(proc))[0] == 0
    finally:
        loop.remove_reader(master)
        os.close(master)
        os.close(slave)


async def test_trip_every_trips_a_running_drive(procs: list[Process]) -> None:
    proc = await start("--listen", "tcp://127.0.0.1:0", "--trip-every", "0.05")
    procs.append(proc)
    port = await tcp_port(proc)
    assert await ask(port, request(b"01", b"00", b"1"), 7) == ack(b"01")
    line = await read_line(proc)
    assert re.fullmatch(r"node 01 tripped: E0[1-4]\n", line), line
    assert (await stop(proc))[0] == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--nodes", "1-40"], "nodes are 1..32"),
        (["--nodes", "8-1"], "runs backwards"),
        (["--nodes", "x"], "bad node list"),
        (["--listen", "udp://127.0.0.1:1"], "only tcp://"),
        (["--wait-ms", "2000"], "0..1000"),
        (["--trip-every", "0"], "positive"),
        (["--device", "/nonexistent/tty"], "cannot serve on /nonexistent/tty"),
    ],
)
def test_bad_arguments_print_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    try:
        code = main(["simulate", *args])  # a startup error returns 2
    except SystemExit as exc:  # argparse's errors exit with 2
        code = exc.code  # type: ignore[assignment]
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert message in err


async def test_port_in_use_prints_one_line_and_exits_2() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = await start("--listen", f"tcp://127.0.0.1:{port}")
        _out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 2
    lines = err.decode().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("sj300 simulate: error: cannot listen on")


def test_no_subcommand_shows_help_and_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    assert "simulate" in capsys.readouterr().err


def test_node_lists() -> None:
    assert parse_nodes("1-8,12,20-22") == [*range(1, 9), 12, 20, 21, 22]
    assert parse_nodes(" 3 , 1-2,2") == [1, 2, 3]
    assert format_nodes([1, 2, 3, 5, 7, 8]) == "1-3,5,7-8"


def test_listen_addresses_stay_on_loopback_unless_a_host_is_written() -> None:
    assert str(parse_listen("tcp://")) == "tcp://127.0.0.1:4001"
    assert str(parse_listen("tcp://:5000")) == "tcp://127.0.0.1:5000"
    assert parse_listen("tcp://:5000").is_loopback
    assert not parse_listen("tcp://0.0.0.0:5000").is_loopback
    assert str(parse_listen("tcp://[::1]:0")) == "tcp://[::1]:0"


@pytest.mark.parametrize(
    ("options", "said"),
    [
        ((), None),
        (("--parity", "E", "--stopbits", "2"), "answering as 19200 bps 8E2"),  # was ignored
        (("--baud", "9600"), "answering as 9600 bps 8N1"),
        (("--baud", "9600", "--bytesize", "7", "--pace"), "paced at 9600 bps 7N1"),
    ],
)
async def test_the_summary_names_the_line_the_listeners_answer_as(
    procs: list[Process], options: tuple[str, ...], said: str | None
) -> None:
    proc = await start("--listen", "tcp://127.0.0.1:0", *options)
    procs.append(proc)
    await tcp_port(proc)
    code, err = await stop(proc)
    assert code == 0, err
    summary = err.splitlines()[0]
    assert summary.startswith("simulating node(s) 1 (serial control"), summary
    if said is None:
        assert "bps" not in summary, summary
    else:
        assert f", {said})" in summary, summary
