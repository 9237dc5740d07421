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
        assert (sample["protocol"], sample["state"]) == ("fr700", "stopped")
        assert sample["output_frequency_hz"] == sample["output_current_a"] == 0.0


def test_monitor_demo_runs_fr700_drives_with_the_protocol_option(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, err = run(
        capsys, "monitor", "--protocol", "fr700", "--duration", "1.0", "--interval", "0.05"
    )
    assert code == 0, err
    lines = [line for line in out.splitlines() if " station " in line]
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
    assert "station 00" in out
    assert "stop" in out


def test_the_commands_work_through_the_fr700_profile(
    capsys: pytest.CaptureFixture[str],
) -> None:
    sim = ("--url", "sim://?protocol=fr700&nodes=0-2")
    code, out, err = run(capsys, "status", "-n", "0", *sim)
    assert code == 0, err
    assert out.splitlines()[0] == "station 00"
    assert "state             stopped" in out
    code, out, err = run(capsys, "read", "Pr.7", "pr.1", "-n", "2", "--json", *sim)
    assert code == 0, err
    codes = [p["code"] for p in json.loads(out)["parameters"]]
    assert codes == ["Pr.7", "Pr.1"]
    code, out, err = run(capsys, "scan", "--json", *sim)
    assert code == 0, err
    assert json.loads(out)["answering"] == [0, 1, 2]
    assert json.loads(out)["scanned"] == list(range(32))


def test_what_fr700_drives_lack_is_refused_before_anything_is_sent(
    capsys: pytest.CaptureFixture[str],
) -> None:
    for args, what in (
        (("stop", "--all", "--protocol", "fr700", "--sim"), "a broadcast stop"),
        (
            ("write", "Pr.7", "5", "--store", "--protocol", "fr700", "--sim"),
            "storing settings apart",
        ),
    ):
        code, _out, err = run(capsys, *args)
        assert code == 2, err
        assert err.count("\n") == 1, err
        assert f"needs {what}, which FR-700 drives (protocol fr700) do not have here" in err


def test_sj300_monitor_still_refuses_node_0(capsys: pytest.CaptureFixture[str]) -> None:
    code, _out, err = run(
        capsys, "monitor", "--url", "sim://?nodes=1", "--nodes", "0", "--count", "1"
    )
    assert code == 2
    assert "1..32" in err
