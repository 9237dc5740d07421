"""Issue 27, items 3 and 4 on the command line: the errors say what happened and the fix.

- ``--url 127.0.0.1:4001`` (no scheme) is a serial port path: the one-line
  error names the errno once and suggests ``tcp://``.
- A peer that answers sooner than the line allows (here the simulator over
  TCP answering at once, on a URL at the default 19200 baud): the time-out
  says the answers came and were refused as early, ``--trace`` marks them,
  and ``baudrate=0`` in the URL makes the same peer work.
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from sj300_async.cli._trace import EARLY_MARK
from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.wire import INSTANT_LINE

from .clirun import closed_port, sj300


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost", "[::1]"])
async def test_host_port_without_tcp_is_one_line_suggesting_tcp(host: str) -> None:
    text = f"{host}:{closed_port()}"
    result = await sj300("--url", text, "status", "-n", "1")
    result.assert_one_line_error(
        1,
        f"cannot open serial port {text}: No such file or directory (errno 2); ",
        f"for a TCP bridge use tcp://{text}",
    )
    assert result.err.count("rrno") == 1, result.err


async def test_a_missing_serial_path_gets_no_tcp_hint() -> None:
    result = await sj300("--url", "/dev/ttyUSB-sj300-none", "status", "-n", "1")
    result.assert_one_line_error(
        1, "cannot open serial port /dev/ttyUSB-sj300-none: No such file or directory (errno 2)"
    )
    assert "tcp://" not in result.err


@pytest.fixture
async def instant_peer() -> AsyncIterator[str]:
    """``tcp://HOST:PORT`` of simulated drive 1, answering the moment a request is in."""
    server = await serve_tcp(SimulatedBus([1]), pacing=INSTANT_LINE)
    async with server:
        yield f"tcp://127.0.0.1:{server.port}"


async def test_answers_refused_as_early_are_named_with_the_fix(instant_peer: str) -> None:
    # One attempt: its answer must come within the ~7 ms floor of 19200 baud,
    # which a local socket does by a wide margin.
    result = await sj300("--url", instant_peer, "--retries", "0", "status", "-n", "1")
    result.assert_one_line_error(
        1,
        "node 01 did not answer command 04: 1 attempt",
        "; 1 answer came up to ",
        "sooner than a 19200-baud line can carry request and answer, and was refused as early",
        "add baudrate=0 to the URL, which turns the check off",
    )


async def test_trace_shows_the_answer_and_the_refusal(instant_peer: str) -> None:
    result = await sj300("--url", instant_peer, "--retries", "0", "--trace", "status", "-n", "1")
    assert result.code == 1, result
    assert "Traceback" not in result.err
    lines = result.err.splitlines()
    assert "→ tx" in lines[0], lines
    assert "command 04 read status" in lines[0], lines
    assert "← rx" in lines[1], lines
    assert "node 01 data" in lines[1], lines  # it did answer
    assert lines[1].endswith(f"node 01 data 02000100 {EARLY_MARK}"), lines  # and was refused
    assert "baudrate=0" in EARLY_MARK
    assert lines[-1].startswith("sj300 status: error: node 01 did not answer"), lines
    assert "was refused as early" in lines[-1]
    assert "baudrate=0" in lines[-1]


async def test_baudrate_0_makes_the_same_peer_work(instant_peer: str) -> None:
    result = await sj300("--url", f"{instant_peer}?baudrate=0", "--json", "status", "-n", "1")
    assert result.code == 0, result
    assert result.json()["node"] == 1
