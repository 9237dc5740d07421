"""The trip black box (issue 45) in a running gateway, both protocols, on simulated lines.

A simulated drive is run by a client's writes, then tripped by the
simulator's fault hook; the gateway's recorder must keep a record of the
seconds before and after it: every polled field at the poll's rate (the
trip's sample in it), the line's frames as a pcapng that tshark reads with
the project's dissector (the trip history's reply in it), and the writes of
the window. The record is kept across a restart, the oldest are pruned, and
a damaged file is skipped.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import sys
import textwrap
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
from tshark import FR700_FIELDS, SJ300_FIELDS, decode
from waiting import wait_for

from sj300_async.gateway import (
    Gateway,
    GatewayDrive,
    Heartbeat,
    RunCommand,
    SetFrequency,
    load_config,
)
from sj300_async.gateway.recorder._store import RecordSummary, TripStore
from sj300_async.wire import Direction

SCADA = "10.0.0.5"
#: Each protocol's trip history read, as the dissector names it: SJ300 command 05,
#: FR-700 instruction H74.
HISTORY_READ = {"sj300": ("sj300.command", "0x05"), "fr700": ("fr700.instruction", "0x74")}
INTERVAL_S = 0.05
BEFORE_S = 2.0
AFTER_S = 1.0
#: Each protocol's simulated line, and the trip code its fault hook is given.
LINES = {
    "sj300": ('url = "sim://?nodes=1-2"', 7, "E07"),
    "fr700": ('url = "sim://?protocol=fr700&nodes=1-2"\nprotocol = "fr700"', 0x31, None),
}


def _text(protocol: str, recorder: str = "") -> str:
    url = LINES[protocol][0]
    return (
        textwrap.dedent(
            f"""\
        [recorder]
        directory = "trips"
        before_s = {BEFORE_S}
        after_s = {AFTER_S}
        {recorder}
        [[lines]]
        name = "hall"
        nodes = "1-2"
        interval_s = {INTERVAL_S}
        trips_interval_s = 60
        lease_s = 30
        """
        )
        + f'{url}\n[[lines.writes]]\nnodes = "1-2"\ncontrol = true\n'
    )


@asynccontextmanager
async def gateway_of(path: Path) -> AsyncIterator[Gateway]:
    async with Gateway(load_config(path)) as gateway:
        await wait_for(
            lambda: all(d.readings.last_ok is not None for d in gateway.drives),
            "every drive polled",
            timeout=10,
        )
        yield gateway


def _drive(gateway: Gateway, node: int) -> GatewayDrive:
    drive = gateway.drive("hall", node)
    assert drive is not None
    return drive


def _simulator(gateway: Gateway) -> Any:
    """The simulated line (either protocol's: each has ``drives`` with the fault hook)."""
    sim = gateway.lines[0].bus.simulator
    assert sim is not None
    return sim


async def _run(gateway: Gateway, node: int) -> None:
    drive = _drive(gateway, node)
    for request in (Heartbeat(), SetFrequency(20.0), RunCommand(Direction.FORWARD)):
        result = await gateway.write(SCADA, drive, request)
        assert result.ok, result


def _span(drive: GatewayDrive) -> float:
    trend = drive.trend
    assert trend is not None
    times = trend.columns()["time"]
    return 0.0 if len(times) < 2 else float(times[-1] or 0) - float(times[0] or 0)


async def _trip(gateway: Gateway, node: int, code: int) -> None:
    """Trip *node* once its trend holds more than before_s, a write just before it."""
    drive = _drive(gateway, node)
    await wait_for(lambda: _span(drive) > BEFORE_S + 0.5, "before_s of samples", timeout=15)
    assert (await gateway.write(SCADA, drive, SetFrequency(25.0))).ok
    assert _simulator(gateway).drives[node].trip(code, now=asyncio.get_running_loop().time())


async def _record(gateway: Gateway, count: int = 1) -> RecordSummary:
    recorder = gateway.recorder
    assert recorder is not None
    await wait_for(
        lambda: recorder.store.counts["written"] >= count, "the trip's record", timeout=15
    )
    return recorder.store.summaries()[0]


async def _json(gateway: Gateway, summary: RecordSummary) -> dict[str, Any]:
    assert gateway.recorder is not None
    data = await gateway.recorder.store.read(summary.id)
    assert data is not None
    record: dict[str, Any] = json.loads(data)
    return record


@pytest.mark.parametrize("protocol", sorted(LINES))
async def test_a_trip_is_recorded_with_its_seconds_and_frames(
    protocol: str, tmp_path: Path
) -> None:
    path = tmp_path / "gw.toml"
    path.write_text(_text(protocol))
    _, code, shown = LINES[protocol]
    async with gateway_of(path) as gateway:
        await _run(gateway, 1)
        await _trip(gateway, 1, code)
        summary = await _record(gateway)
        record = await _json(gateway, summary)
        drive = _drive(gateway, 1)
        assert drive.snapshot.trip is not None
        expected_code = shown or drive.snapshot.trip.code
    assert (summary.line, summary.node, summary.protocol) == ("hall", 1, protocol)
    assert (summary.code, record["seen_by"]) == (expected_code, "poll")
    assert summary.meaning
    assert record["trip"]["meaning"] == summary.meaning
    # The samples: every polled field, from before_s before to after_s after, at the
    # poll's rate, the trip's own sample marked.
    samples, at = record["samples"], record["time"]
    times = samples["time"]
    assert {"output_frequency_hz", "output_current_a", "output_voltage_v", "running",
            "tripped", "direction", "set_frequency_hz"} <= set(samples)  # fmt: skip
    assert times[0] - (at - BEFORE_S) < 4 * INTERVAL_S
    assert (at + AFTER_S) - times[-1] < 4 * INTERVAL_S
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert sorted(gaps)[len(gaps) // 2] < 2.5 * INTERVAL_S  # the median: the poll's rate
    index = record["trip_sample"]
    assert samples["tripped"][index] is True
    assert not any(samples["tripped"][: index - 1])
    assert abs(times[index] - at) < 3 * INTERVAL_S
    assert max(samples["output_frequency_hz"][:index]) > 1  # it ran before the trip
    # The writes of the window: the one just before the trip.
    assert [w["client"] for w in record["writes"]][-1:] == [SCADA]
    assert all(at - BEFORE_S <= w["time"] <= at + AFTER_S for w in record["writes"])
    # The frames: a pcapng that tshark reads, the history read after the trip in it.
    frames = tmp_path / "trips" / f"{summary.id}.pcapng"
    fields = SJ300_FIELDS if protocol == "sj300" else FR700_FIELDS
    rows = decode(frames, fields, tmp_path / "home")
    assert len(rows) > BEFORE_S / INTERVAL_S  # a poll's exchange or more per interval
    command, number = HISTORY_READ[protocol]
    replies = [r for r in rows if r[f"{protocol}.type"] == "reply" and r[command] == number]
    assert replies, "the trip history's reply"


async def test_a_record_survives_a_restart_and_a_damaged_file_is_skipped(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "gw.toml"
    path.write_text(_text("sj300"))
    async with gateway_of(path) as gateway:
        await _run(gateway, 2)
        await _trip(gateway, 2, 7)
        summary = await _record(gateway)
        kept = await _json(gateway, summary)
    trips = tmp_path / "trips"
    (trips / "20260101T000000.000Z-hall-1.json").write_text('{"format": "sj300-trip-rec')
    (trips / "20260101T000000.000Z-hall-1.pcapng").write_bytes(b"")
    caplog.set_level(logging.WARNING, "sj300_async.gateway.recorder")
    async with gateway_of(path) as gateway:
        assert gateway.recorder is not None
        assert gateway.recorder.store.summaries() == [summary]
        assert await _json(gateway, summary) == kept
        assert gateway.recorder.store.counts["damaged"] == 1
    warnings = [r.getMessage() for r in caplog.records if r.name.endswith(".recorder")]
    assert len(warnings) == 1
    assert "20260101T000000.000Z-hall-1.json" in warnings[0], warnings


async def test_the_oldest_records_are_pruned_past_max_records(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    path.write_text(_text("sj300", "max_records = 2"))
    async with gateway_of(path) as gateway:
        sim = _simulator(gateway)
        await _run(gateway, 1)
        for count in (1, 2, 3):
            await _trip(gateway, 1, 7)
            await _record(gateway, count)
            # Reset, then run again (the reset stops it) for the next trip.
            assert sim.drives[1].reset(asyncio.get_running_loop().time())
            await wait_for(lambda: _drive(gateway, 1).snapshot.tripped is False, "the reset")
            await _run(gateway, 1)
        recorder = gateway.recorder
        assert recorder is not None
        ids = [s.id for s in recorder.store.summaries()]
        assert (len(ids), recorder.store.counts["pruned"]) == (2, 1)
    on_disk = sorted(p.name for p in (tmp_path / "trips").iterdir())
    assert on_disk == sorted(f"{i}{suffix}" for i in ids for suffix in (".json", ".pcapng"))


async def test_a_store_in_memory_prunes_by_bytes_and_keeps_the_newest() -> None:
    from sj300_async.gateway.recorder import RecorderConfig
    from sj300_async.gateway.recorder._record import new_record, record_id

    store = TripStore(RecorderConfig(directory=None, max_bytes=3000))
    for second in range(5):
        at = 1_764_763_200.0 + second
        name = record_id(at, "hall", 1)
        record = new_record(record=name, gateway="gw", line="hall", node=1, unit=1,
                            protocol="sj300", unix=at, seen_by="poll", interval_s=0.5,
                            before_s=60, after_s=10, trip=None, samples={"time": [at]},
                            writes=[])  # fmt: skip
        assert await store.add(record, b"\0" * 1000) is not None
    kept = store.summaries()
    assert 1 <= len(kept) < 5
    assert store.size <= 3000
    assert kept[0].id == record_id(1_764_763_204.0, "hall", 1)
    assert await store.read(kept[0].id) is not None
    assert await store.frames(record_id(1_764_763_200.0, "hall", 1)) is None  # pruned


# -- served over HTTP ----------------------------------------------------------------------


async def test_the_http_api_lists_and_serves_a_record(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import aiohttp

    path = tmp_path / "gw.toml"
    path.write_text('[http]\nlisten = "127.0.0.1:0"\n' + _text("fr700"))
    async with gateway_of(path) as gateway, aiohttp.ClientSession() as client:
        await _run(gateway, 2)
        await _trip(gateway, 2, 0x31)
        summary = await _record(gateway)
        port = gateway.northbounds["http"].port  # type: ignore[attr-defined]
        base = f"http://127.0.0.1:{port}/api/v1/trips"

        async def get(url: str, status: int = 200) -> aiohttp.ClientResponse:
            async with client.get(url) as answer:
                await answer.read()
                assert answer.status == status, (url, await answer.text())
                return answer

        async with client.get(base) as answer:
            listed = await answer.json()
        assert listed == {"recording": True, "trips": [summary.as_json()]}
        async with client.get(f"{base}?line=hall&node=1") as answer:
            assert (await answer.json())["trips"] == []
        async with client.get(f"{base}/{summary.id}") as answer:
            record = await answer.json()
        assert (record["id"], record["node"], record["trip"]["code"]) == (
            summary.id, 2, summary.code,
        )  # fmt: skip
        async with client.get(f"{base}/{summary.id}/frames.pcapng") as answer:
            frames = await answer.read()
        assert frames[:4] == b"\x0a\x0d\x0d\x0a"  # a pcapng section header block
        async with client.get(f"{base}/{summary.id}.csv") as answer:
            rows = (await answer.text()).splitlines()
            assert answer.headers["Content-Type"] == "text/csv; charset=utf-8"
        assert rows[0].startswith("time_utc,time_unix,output_frequency_hz,")
        assert len(rows) == 1 + len(record["samples"]["time"])
        await get(f"{base}/../../etc/passwd", 404)
        await get(f"{base}/20260101T000000.000Z-hall-9", 404)
        await get(f"{base}/20260101T000000.000Z-hall-9.csv", 404)
        await get(f"{base}?node=x", 400)
        await get(f"{base}?limit=0", 400)
        # A CSV whose child cannot run is 503, said: the record may be fine.
        failing = (sys.executable, "-c", "import sys; sys.exit(9)")
        monkeypatch.setattr("sj300_async.gateway.recorder._csv_process.CHILD", failing)
        answer = await get(f"{base}/{summary.id}.csv", 503)
        assert "status 9" in (await answer.json())["error"]


async def test_a_gateway_without_the_recorder_says_so(tmp_path: Path) -> None:
    import aiohttp

    path = tmp_path / "gw.toml"
    path.write_text('[http]\nlisten = "127.0.0.1:0"\n' + _text("sj300", "enabled = false"))
    async with gateway_of(path) as gateway, aiohttp.ClientSession() as client:
        assert gateway.recorder is None
        port = gateway.northbounds["http"].port  # type: ignore[attr-defined]
        async with client.get(f"http://127.0.0.1:{port}/api/v1/trips") as answer:
            assert await answer.json() == {"recording": False, "trips": []}


async def test_a_line_replaced_by_a_reload_keeps_its_pending_record_and_records_on(
    tmp_path: Path,
) -> None:
    """A reload that replaces the line (its URL changed) while a record waits for its
    after_s: the record is kept at once, with the old line's frames; the new line's next
    trip has its own frames (the new line's traffic is recorded, not let go)."""
    path = tmp_path / "gw.toml"
    longer = _text("sj300").replace(f"after_s = {AFTER_S}", "after_s = 30")
    path.write_text(longer)
    async with gateway_of(path) as gateway:
        await _run(gateway, 1)
        await _trip(gateway, 1, 7)
        recorder = gateway.recorder
        assert recorder is not None
        await wait_for(lambda: recorder.pending == 1, "the record pending")
        path.write_text(longer.replace("sim://?nodes=1-2", "sim://?nodes=1-3"))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert [c.name for c in outcome.plan.replaced] == ["hall"]
        first = await _record(gateway)  # taken at the replacement, not 30 s later
        await wait_for(
            lambda: all(d.readings.last_ok is not None for d in gateway.drives), "new polls"
        )
        frames = await recorder.store.frames(first.id)
        assert frames is not None
        assert len(frames) > 1000  # the old line's polls before the trip
        await _run(gateway, 2)
        await _trip(gateway, 2, 7)
        await wait_for(lambda: recorder.pending == 1, "the second record pending")
        await gateway.reload_file(path)  # nothing changes: the pending record stays pending
        assert recorder.pending == 1
    assert recorder.store.counts["written"] == 2  # the stop took the second one
    second = recorder.store.summaries()[0]
    assert second.node == 2
    frames = await recorder.store.frames(second.id)
    assert frames is not None
    assert len(frames) > 1000  # the new line's polls: its traffic was kept
