"""Every example runs against the in-memory simulator, as CI runs them."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from sj300_async.wire import Direction

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
#: The one-shot examples' last line, in words (not a dataclass's repr), with N NAKs.
STATS = (
    r"(?m)^bus statistics: requests \d+, replies \d+, time-outs 0, retries 0, "
    r"NAKs %d, mean round trip \d+\.\d ms$"
)


def _run(*args: str, timeout: float = 60) -> str:
    done = subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, timeout=timeout, check=False
    )
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    return done.stdout


def _start(*args: str) -> subprocess.Popen[str]:
    """An example in a child process whose output arrives line by line, even through a pipe."""
    return subprocess.Popen(
        [sys.executable, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


@contextmanager
def _service(*args: str) -> Iterator[str]:
    """examples/service.py on a free port against three simulated drives; yields its URL."""
    proc = _start(str(EXAMPLES / "service.py"), "sim://?nodes=1-3", "--port", "0", *args)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        url = re.search(r"http://\S+", line)
        assert url, line
        yield url[0]
    finally:
        if proc.poll() is None and "--run-for" not in args:
            proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode in (0, 130), err
    assert "Traceback" not in err


def _get_state(url: str) -> dict[str, dict[str, Any]]:
    """The service's state once the poll loop has filled in every drive."""
    state: dict[str, dict[str, Any]] = {}
    for _ in range(50):
        with urllib.request.urlopen(url, timeout=5) as response:
            state = json.load(response)
        if len(state) == 3:
            break
    return state


def test_one_shot() -> None:
    out = _run(str(EXAMPLES / "one_shot.py"), "sim://?nodes=1-2")
    assert re.search(r"node 1: RUNNING, \d+\.\d\d Hz", out)
    assert "refused before sending" in out
    assert re.search(STATS % 0, out), out


def test_fr700_one_shot() -> None:
    out = _run(str(EXAMPLES / "fr700_one_shot.py"))
    assert re.search(r"station 0: running, \d+\.\d\d Hz", out)
    assert "refused by the drive (data range)" in out
    assert re.search(STATS % 1, out), out  # the refusal above


def test_polling_loop() -> None:
    out = _run(str(EXAMPLES / "polling_loop.py"), "sim://?nodes=1-4", "--duration", "2")
    assert "REVERSE" in out
    assert re.search(r"node 04: \d+ polls, 0 failures", out)


def test_service_serves_drive_state_over_http() -> None:
    with _service("--run-for", "3") as url:
        state = _get_state(url)
        assert set(state) == {"1", "2", "3"}
        assert state["3"]["output_frequency_hz"] >= 0
        with urllib.request.urlopen(
            urllib.request.Request(url + "stop", method="POST"), timeout=5
        ) as response:
            assert json.load(response) == {"stopped": True}


def test_service_writes_enumerations_by_name() -> None:
    with _service() as url:
        state = _get_state(url)
    assert {drive["direction"] for drive in state.values()} <= {d.name for d in Direction}
    assert all(isinstance(drive["input_terminals"], int) for drive in state.values())


@pytest.mark.parametrize(
    ("method", "path", "code"),
    [("GET", "nowhere", 404), ("POST", "stop/now", 404), ("GET", "stop", 405)],
)
def test_service_refuses_unknown_paths(method: str, path: str, code: int) -> None:
    with _service() as url:
        request = urllib.request.Request(url + path, method=method)
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=5)
        refused.value.close()
    assert refused.value.code == code


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT cannot be sent to a child on Windows")
@pytest.mark.parametrize(
    "args",
    [
        ["one_shot.py"],
        ["fr700_one_shot.py"],
        ["polling_loop.py", "--duration", "30"],
        ["service.py", "--port", "0"],
    ],
    ids=lambda args: args[0],
)
def test_ctrl_c_exits_cleanly(args: list[str]) -> None:
    proc = _start(str(EXAMPLES / args[0]), *args[1:])
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline()  # it is running and has printed something
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
