"""The command line with FR-700 drives: ``--protocol fr700`` and the live monitor."""

from __future__ import annotations

import json

import pytest

from sj300_async.cli import main


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    try:
        code = main(list(args))
    except SystemExit as exc:  # argparse errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def test_monitor_shows_fr700_drives(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(
        capsys,
        "monitor",
        "--url", "sim://?protocol=fr700&nodes=0-2",
        "--nodes", "0-2",
        "--interval", "0.01",
        "--count", "6",
        "--json",
    )  # fmt: skip
    assert code == 0, err
    samples = [json.loads(line) for line in out.splitlines()]
    assert {s["node"] for s in samples} == {0, 1, 2}
    for sample in samples:
        assert sample["error"] is None
        assert set(sample["monitor"]) >= {"output_frequency_hz", "output_current_a"}


def test_monitor_demo_runs_fr700_drives_with_the_protocol_option(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, err = run(
        capsys, "monitor", "--protocol", "fr700", "--duration", "1.0", "--interval", "0.05"
    )
    assert code == 0, err
    lines = [line for line in out.splitlines() if " node " in line]
    assert lines
    assert "Traceback" not in err


def test_monitor_plain_lines_for_fr700(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(
        capsys,
        "monitor",
        "--url", "sim://?nodes=0-1",
        "--protocol", "fr700",
        "--nodes", "0-1",
        "--interval", "0.01",
        "--count", "2",
    )  # fmt: skip
    assert code == 0, err
    assert "node 00" in out
    assert "stop" in out


def test_sj300_commands_refuse_fr700(capsys: pytest.CaptureFixture[str]) -> None:
    code, _out, err = run(capsys, "status", "--protocol", "fr700")
    assert code == 2
    assert "SJ300 drives only" in err
    code, _out, err = run(capsys, "status", "--url", "sim://?protocol=fr700")
    assert code == 2
    assert err.count("\n") == 1


def test_sj300_monitor_still_refuses_node_0(capsys: pytest.CaptureFixture[str]) -> None:
    code, _out, err = run(
        capsys, "monitor", "--url", "sim://?nodes=1", "--nodes", "0", "--count", "1"
    )
    assert code == 2
    assert "1..32" in err
