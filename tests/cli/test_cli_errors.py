"""Expected failures end in one line on stderr and a meaningful exit status, never a traceback.

The four kinds the issue names (time-out, NAK, unreachable bridge, bad
arguments) run through the real entry point in a subprocess; the longer
list of cases runs ``main()`` in this process, which is the same code
without an interpreter start each.
"""

from __future__ import annotations

import pytest

from sj300_async.cli import main

from .clirun import Result, TcpSim, closed_port, sj300


async def test_time_out_against_an_absent_node() -> None:
    (await sj300("status", "-n", "12", "--sim")).assert_one_line_error(1, "node 12 did not answer")


async def test_time_out_over_tcp_with_retries(tcp_sim: TcpSim) -> None:
    result = await sj300("read", "F002", "-n", "7", "--url", tcp_sim.url, "--retries", "1")
    result.assert_one_line_error(1, "sj300 read: error: node 07 did not answer")


async def test_nak_for_an_unknown_parameter() -> None:
    result = await sj300("read", "F999", "--sim")
    result.assert_one_line_error(
        1,
        "sj300 read: error: F999: node 01 answered NAK 16 (abnormal parameter code or value)",
        ": the drive has no such parameter",  # the profile's absent NAK
    )
    fr700 = await sj300("read", "Pr.999", "--protocol", "fr700", "--sim")
    fr700.assert_one_line_error(
        1, "Pr.999: station 01 answered NAK B (instruction code error): the drive has no such"
    )


async def test_unreachable_bridge() -> None:
    result = await sj300("status", "--url", f"tcp://127.0.0.1:{closed_port()}")
    result.assert_one_line_error(1, "sj300 status: error: could not connect to tcp://127.0.0.1:")


async def test_bad_arguments() -> None:
    (await sj300("status", "-n", "40")).assert_one_line_error(2, "node is 1..32")
    (await sj300("write", "F002", "9999")).assert_one_line_error(2, "within 0.01..3600 s")


async def test_missing_serial_device() -> None:
    result = await sj300("status", "--url", "/nonexistent/ttyUSB9")
    result.assert_one_line_error(1, "/nonexistent/ttyUSB9")


async def test_bad_url_in_the_environment() -> None:
    (await sj300("status", env_url="nonsense://")).assert_one_line_error(2, "nonsense")


async def test_no_subcommand_prints_help_and_exits_2() -> None:
    result = await sj300()
    assert result.code == 2
    assert "monitor" in result.err
    assert "Traceback" not in result.err


@pytest.mark.parametrize(
    ("args", "code", "fragments"),
    [
        (["trips", "-n", "9", "--timeout", "0.05", "--sim"], 1, ["did not answer"]),
        (["write", "P123", "5", "--sim"], 1, ["P123: node 01 answered NAK 16"]),
        (["write", "C072", "5", "--sim"], 1, ["C072 = 5: node 01 answered NAK 16"]),
        (["freq", "70", "--sim"], 1, ["NAK 16", "A004"]),
        (["run", "forward", "--url", "sim://?factory_defaults=1"], 1, ["NAK 13", "A002"]),
        (["freq", "5", "--url", "sim://?factory_defaults=1"], 1, ["NAK 13", "A001"]),
        (["read", "X12"], 2, ["not a parameter code"]),
        (["write", "F002", "1.234"], 2, ["resolution"]),
        (["write", "F002", "fast"], 2, ["VALUE must be a number"]),
        (["write", "F002", "-3", "--raw"], 2, ["raw value is 0..99999999"]),
        (["freq", "1.234", "--sim"], 2, ["0.01"]),
        (["freq", "x"], 2, ["HZ must be a number"]),
        (["run", "sideways"], 2, ["invalid choice"]),
        (["status", "--url", "ftp://x"], 2, ["unknown bus URL scheme"]),
        (["status", "--url", "tcp://127.0.0.1"], 2, ["needs a host and a port"]),
        (["stop", "--all", "--protocol", "fr700", "--sim"], 2, ["a broadcast stop"]),
        (["status", "--protocol", "fr700", "-n", "32"], 2, ["a station is 0..31, got '32'"]),
        (["status", "--timeout", "-1"], 2, ["positive"]),
        (["status", "--retries", "x"], 2, ["integer >= 0"]),
        (["status", "--parity", "X"], 2, ["invalid choice"]),
        (["status", "--baud", "10"], 2, ["baud rate"]),
        (["scan", "--nodes", "0-3"], 2, ["nodes are 1..32"]),
        (["monitor", "--count", "0"], 2, ["integer >= 1"]),
        (["monitor", "--interval", "0"], 2, ["positive"]),
        (["params", "restore", "/nonexistent/backup.json"], 2, ["No such file"]),
        (["params", "backup", "x.json", "--codes", "F002,Q1"], 2, ["not a parameter code"]),
        (["params"], 2, ["required"]),
        (["bogus"], 2, ["invalid choice"]),
    ],
)
def test_one_line_errors(
    capsys: pytest.CaptureFixture[str], args: list[str], code: int, fragments: list[str]
) -> None:
    try:
        status = main(args)
    except SystemExit as exc:  # argparse's errors exit
        status = exc.code if isinstance(exc.code, int) else -1
    captured = capsys.readouterr()
    Result(status, captured.out, captured.err).assert_one_line_error(code, *fragments)
