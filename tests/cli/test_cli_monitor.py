"""``sj300 monitor``: the demo, a real URL, plain lines, JSON lines, a terminal, signals."""

from __future__ import annotations

import asyncio
import re
import signal
import sys
import time

import pytest

from sj300_async.cli._record import FIELDS

from .clirun import TIMEOUT, TcpSim, cli_env, closed_port, sj300, sj300_on_terminal

_LINE = re.compile(
    r"\d\d:\d\d:\d\d\.\d{3} node (0[1-8]) (online |offline) .+ set +[\d.]+ Hz  out +[\d.]+ Hz"
    r" +[\d.]+ A +[\d.]+ V +-?\d+ % +[\d.]+ kW +[\d.]+ ms"
)


async def test_demo_prints_plain_lines_when_not_on_a_terminal() -> None:
    result = await sj300("monitor", "--count", "2", "--interval", "0.1")  # 2 cycles of 8
    assert result.code == 0, result.err
    assert result.err == "sj300 monitor: note: no --url given: these are simulated drives " + (
        "(sim://?nodes=1-8)\n"  # the demo: no --url, no --sim
    )
    lines = result.out.splitlines()
    assert len(lines) == 16
    for line in lines:
        assert _LINE.fullmatch(line), line
    assert [_LINE.fullmatch(line)[1] for line in lines[:8]] == [f"0{n}" for n in range(1, 9)]  # type: ignore[index]


async def test_demo_json_lines_are_drive_records() -> None:
    start = time.time()
    result = await sj300("monitor", "--json", "--count", "3", "--interval", "0.1")
    assert result.code == 0, result.err
    samples = result.json_lines()
    assert len(samples) == 24
    for sample in samples:
        assert list(sample) == [*FIELDS, "simulated"]  # the demo: no --url
        assert sample["line"] == "sim://(nodes 1-8)"
        assert (sample["gateway"], sample["gateway_online"], sample["lapse_pending"]) == (
            None,
            None,
            None,
        )
        assert sample["online"] is True
        assert sample["error"] is None
        assert set(sample["status"]) == {"a", "b", "c"}
        assert isinstance(sample["output_frequency_hz"], float)
        assert set(sample["parameters"]) == {"F001"}
        assert sample["set_frequency_hz"] == sample["parameters"]["F001"]
        assert start <= sample["time"] <= time.time()  # wall-clock, not the event loop's
    assert {s["node"] for s in samples} == set(range(1, 9))
    # The demo gets drives going within a few polls.
    assert any(s["status"]["a"] == "RUNNING" for s in samples[8:])


async def test_a_url_is_polled_without_the_demo_and_a_silent_node_goes_offline(
    tcp_sim: TcpSim,
) -> None:
    # A cycle count, not a duration, and a timeout the present nodes meet on
    # a loaded machine: node 05 fails at least three polls whatever the timing.
    args = ("--url", tcp_sim.url, "--nodes", "3-5", "--interval", "0.05", "--timeout", "0.3")
    result = await sj300("monitor", *args, "--json", "--retries", "0", "--count", "4")
    assert result.code == 0, result.err
    samples = result.json_lines()
    by_node = {n: [s for s in samples if s["node"] == n] for n in (3, 4, 5)}
    for node in (3, 4):
        assert by_node[node], node
        assert all(s["online"] and s["error"] is None for s in by_node[node])
        assert all(s["status"]["b"] == "STOPPED" for s in by_node[node])  # no demo here
    absent = by_node[5]
    assert len(absent) >= 3  # an offline node is probed less often
    assert all("node 05 did not answer" in s["error"] for s in absent)
    assert all(s["online"] is False for s in absent)  # it never answered
    assert absent[-1]["status"] is None
    assert absent[-1]["state"] is None
    assert absent[-1]["latency_s"] is None
    assert tcp_sim.bus.drives[3].parameters["F002"] == 3000  # the demo wrote nothing

    plain = await sj300("monitor", *args, "--retries", "0", "--count", "3")
    assert plain.code == 0, plain.err
    lines = [line for line in plain.out.splitlines() if " node 05 " in line]
    assert lines
    assert all(
        re.search(r"node 05 (online |offline) -  .*  error: ReplyTimeoutError", ln) for ln in lines
    )


async def test_duration_ends_the_monitor() -> None:
    start = time.monotonic()
    result = await sj300("monitor", "--duration", "0.5", "--nodes", "1-2")
    assert result.code == 0, result.err
    assert time.monotonic() - start < TIMEOUT / 2
    assert len(result.out.splitlines()) >= 2


async def test_on_a_terminal_a_live_table() -> None:
    result = await sj300_on_terminal("monitor", "--count", "3", "--interval", "0.1")
    assert result.code == 0, result.out
    screen = result.out
    assert "sj300 monitor — demo: 8 simulated drives" in screen
    for header in ("node", "state", "set Hz", "out Hz", "current A", "latency ms", "link"):
        assert header in screen
    assert "online" in screen
    assert "Traceback" not in screen


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 0)])
async def test_a_signal_stops_it_cleanly(sig: signal.Signals, code: int) -> None:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "sj300_async",
        "monitor",
        "--sim",
        "--interval",
        "0.1",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=cli_env(),
    )
    try:
        assert proc.stdout is not None
        first = await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)
        assert _LINE.fullmatch(first.decode().rstrip("\n")), first
        proc.send_signal(sig)
        _out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert proc.returncode == code  # Ctrl-C: 130, as --help says
    assert err.decode() == ""


async def test_an_unreachable_bridge_is_one_line() -> None:
    result = await sj300("monitor", "--url", f"tcp://127.0.0.1:{closed_port()}", "--count", "1")
    result.assert_one_line_error(1, "sj300 monitor: error: could not connect")
