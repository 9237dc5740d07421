"""The bus options and --json are global: before the subcommand or after it, the later one wins."""

from __future__ import annotations

import asyncio
import re

import pytest

from sj300_async.cli import build_parser, main
from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .clirun import TcpSim, closed_port, sj300

_TX = re.compile(r" +\d+\.\d{3} → tx ")


async def test_options_before_and_after_the_subcommand(tcp_sim: TcpSim) -> None:
    after, before, split = await asyncio.gather(
        sj300("status", "-n", "2", "--json", "--url", tcp_sim.url),
        sj300("--url", tcp_sim.url, "--json", "status", "-n", "2"),
        sj300("--url", tcp_sim.url, "scan", "--nodes", "3-5", "--json", "--timeout", "0.5"),
    )
    assert after.code == before.code == 0, (after.err, before.err)
    assert after.err == before.err == ""
    assert after.json()["status"] == before.json()["status"]
    assert split.json() == {"scanned": [3, 4, 5], "answering": [3, 4]}


async def test_given_on_both_sides_the_one_after_the_subcommand_wins(tcp_sim: TcpSim) -> None:
    dead = f"tcp://127.0.0.1:{closed_port()}"
    works, fails = await asyncio.gather(
        sj300("--url", dead, "status", "--url", tcp_sim.url),
        sj300("--url", tcp_sim.url, "status", "--url", dead),
    )
    assert works.code == 0, works.err
    fails.assert_one_line_error(1, f"could not connect to {dead}")


async def test_line_settings_and_the_protocol_before_the_subcommand() -> None:
    # A simulator answering as a 19200-baud line would (the default): a client told
    # the line is slower (9600) still takes its answers (its floor assumes the
    # line may run at 19200); tcp_sim's faster line would be refused as too early.
    async with await serve_tcp(SimulatedBus((1,)), "127.0.0.1", 0) as server:
        url = f"tcp://127.0.0.1:{server.port}"
        fine = await sj300("--baud", "9600", "--parity", "e", "status", "--url", url)
        assert fine.code == 0, fine.err
        # The protocol before the subcommand holds: F002 is no FR-700 parameter (nothing sent).
        wrong = await sj300("--protocol", "fr700", "read", "F002", "--url", url)
        wrong.assert_one_line_error(2, "argument CODE: a parameter is a number 0..999")
    bad = await sj300("--parity", "X", "status")
    bad.assert_one_line_error(2, "sj300: error: argument --parity: invalid choice")


async def test_retries_default_per_command_unless_given(tcp_sim: TcpSim) -> None:
    """Counted on the trace: the attempts at an absent node, the first and the retries."""
    absent = ("-n", "9", "--timeout", "0.02", "--url", tcp_sim.url, "--trace")
    default, before, both = await asyncio.gather(
        sj300("status", *absent),
        sj300("--retries", "0", "status", *absent),
        sj300("--retries", "0", "status", *absent, "--retries", "1"),
    )
    attempts = [len(_TX.findall(r.err)) for r in (default, before, both)]
    assert attempts == [3, 1, 2], [r.err for r in (default, before, both)]


def test_the_parser_keeps_a_value_given_before_the_subcommand() -> None:
    parser = build_parser()
    scan = parser.parse_args(["scan"])
    assert (scan.retries, scan.default_retries, scan.url, scan.json, scan.trace) == (
        None,
        0,
        None,
        False,
        False,
    )
    before = parser.parse_args(
        ["--retries", "3", "--json", "--trace", "--url", "tcp://a:1", "scan"]
    )
    assert (before.retries, before.json, before.trace, before.url) == (3, True, True, "tcp://a:1")
    both = parser.parse_args(["--retries", "3", "--timeout", "2", "scan", "--retries", "1"])
    assert (both.retries, both.timeout) == (1, 2.0)
    nested = parser.parse_args(["--sim", "params", "restore", "f.json", "--baud", "9600"])
    assert (nested.sim, nested.baud, nested.command_name) == (True, 9600, "params restore")


@pytest.mark.parametrize("option", [["--url", "tcp://a:1"], ["--json"], ["--sim"], ["--trace"]])
def test_an_option_before_a_command_that_does_not_take_it_is_refused(
    capsys: pytest.CaptureFixture[str], option: list[str]
) -> None:
    with pytest.raises(SystemExit) as exited:
        main([*option, "simulate", "--listen", "tcp://127.0.0.1:0"])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert err == f"sj300: error: {option[0]} does not apply to `simulate` (see --help)\n"


def test_help_says_where_global_options_go(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "before or after COMMAND; given on both sides, the one after COMMAND wins" in out
    with pytest.raises(SystemExit):
        main(["status", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "also before the command (sj300 --url URL status)" in out
