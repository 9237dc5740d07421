"""Every example runs against the in-memory simulator, as CI runs them."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import urllib.request
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _run(*args: str, timeout: float = 60) -> str:
    done = subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, timeout=timeout, check=False
    )
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    return done.stdout


def test_one_shot():
    out = _run(str(EXAMPLES / "one_shot.py"), "sim://?nodes=1-2")
    assert re.search(r"node 1: RUNNING, \d+\.\d\d Hz", out)
    assert "refused before sending" in out


def test_polling_loop():
    out = _run(str(EXAMPLES / "polling_loop.py"), "sim://?nodes=1-4", "--duration", "2")
    assert "REVERSE" in out
    assert re.search(r"node 04: \d+ polls, 0 failures", out)


def test_service_serves_drive_state_over_http():
    proc = subprocess.Popen(
        [
            sys.executable,
            str(EXAMPLES / "service.py"),
            "sim://?nodes=1-3",
            "--port",
            "0",
            "--run-for",
            "3",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        url = re.search(r"http://\S+", line)
        assert url, line
        state: dict[str, dict[str, float]] = {}
        for _ in range(50):  # until the poll loop has filled in every drive once
            with urllib.request.urlopen(url[0], timeout=5) as response:
                state = json.load(response)
            if len(state) == 3:
                break
        assert set(state) == {"1", "2", "3"}
        assert state["3"]["output_frequency_hz"] >= 0
        with urllib.request.urlopen(
            urllib.request.Request(url[0] + "stop", method="POST"), timeout=5
        ) as response:
            assert json.load(response) == {"stopped": True}
    finally:
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
