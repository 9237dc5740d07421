"""A record's CSV made in a child process (recorder._csv_process): the same text as
``samples_csv``; JSON that is no record is ValueError with the child's reason; a child
that fails, does not start, or overruns its time is CsvFailed; a child is never left
running, whether it overran or its caller was cancelled."""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

import orjson
import pytest
from waiting import process_gone, wait_for

from sj300_async.gateway.recorder import CsvFailed, record_csv, samples_csv
from sj300_async.gateway.recorder._record import new_record, record_id


def _record(samples: int) -> dict[str, object]:
    unix = 1_767_225_600.0
    columns: dict[str, list[object]] = {
        "time": [unix + i / 20 for i in range(samples)],
        "output_frequency_hz": [i / 10 if i % 7 else None for i in range(samples)],
        "tripped": [i > samples // 2 for i in range(samples)],
    }
    return new_record(record=record_id(unix, "hall", 3), gateway="gw", line="hall", node=3,
                      unit=3, protocol="sj300", unix=unix, seen_by="poll", interval_s=0.05,
                      before_s=1, after_s=1, trip=None, samples=columns,
                      writes=[])  # fmt: skip


def _sleeper(pid_file: Path) -> tuple[str, ...]:
    """A child that says its pid and then never answers: a hung child, its sleep the
    hang itself (the test waits on the pid file and the timeout, never on the sleep,
    and the child is killed long before it ends)."""
    code = f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid())); time.sleep(600)"
    return (sys.executable, "-c", code)


async def test_the_childs_csv_is_samples_csv() -> None:
    record = _record(500)
    csv = await record_csv(orjson.dumps(record))
    assert csv == samples_csv(record).encode()
    rows = csv.decode().split("\r\n")
    assert rows[0] == "time_utc,time_unix,output_frequency_hz,tripped"
    assert rows[1] == "2026-01-01T00:00:00.000+00:00,1767225600.000,,False"
    assert len(rows) == 502  # the header, 500 rows, and the last line's end


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"\x00\xff garbage {", "not valid UTF-8"),
        (b"garbage {", "unexpected character"),
        (b"[" * 5_000 + b"]" * 5_000, "depth limit exceeded"),
        (b"[1, 2]", "not a JSON object"),
        (b'{"samples": {"time": "no"}}', "the record has no samples"),
        (b'{"samples": {"time": [1, "x"]}}', "sample 1: its time is not a number"),
        (b'{"samples": {"time": [1e300]}}', "out of range"),
    ],
)
async def test_json_that_is_no_record_is_a_value_error_with_the_childs_reason(
    data: bytes, reason: str
) -> None:
    with pytest.raises(ValueError, match=reason) as caught:
        await record_csv(data)
    assert "\n" not in str(caught.value)
    assert len(str(caught.value)) <= 200


async def test_a_child_that_fails_or_does_not_start_is_csv_failed(tmp_path: Path) -> None:
    with pytest.raises(CsvFailed, match=r"status 1: .*ZeroDivisionError"):
        await record_csv(b"{}", child=(sys.executable, "-c", "1/0"))
    with pytest.raises(CsvFailed, match="did not start"):
        await record_csv(b"{}", child=(str(tmp_path / "no-such-python"),))


async def test_a_child_past_its_time_is_killed(tmp_path: Path) -> None:
    pid_file = tmp_path / "pid"
    with pytest.raises(CsvFailed, match=r"more than 0\.5 s"):
        await record_csv(b"{}", timeout_s=0.5, child=_sleeper(pid_file))
    assert process_gone(int(pid_file.read_text()))


async def test_a_cancelled_caller_leaves_no_child(tmp_path: Path) -> None:
    pid_file = tmp_path / "pid"
    task = asyncio.create_task(record_csv(b"{}", child=_sleeper(pid_file)))
    await wait_for(lambda: pid_file.exists() and pid_file.read_text() != "", "the child's pid")
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert process_gone(int(pid_file.read_text()))
