"""The workbench's JSON API and event stream, over a real gateway on a simulated line.

What a script sees of the HTTP northbound: every route, its errors, the
trend against the samples the gateway took, the CSV, the event stream's
first state and its following of a change, and that the read-only
gateway has no route that writes. The page itself is tested in a real
browser (tests/workbench).
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
import json
import math
from collections.abc import AsyncIterator, Callable
from typing import Any

import aiohttp
import pytest
from waiting import wait_for

from sj300_async.gateway import Gateway, ServedDrive
from sj300_async.gateway.http._northbound import HttpNorthbound
from sj300_async.profiles import DriveSnapshot
from sj300_async.wire import PacketDirection, read_pcapng

from .conftest import SimLine, gateway_toml, running_gateway

HTTP = '[http]\nlisten = "127.0.0.1:0"\ntrend_s = 60\n'


def http(gateway: Gateway) -> HttpNorthbound:
    northbound = gateway.northbounds["http"]
    assert isinstance(northbound, HttpNorthbound)
    return northbound


class Client:
    """An HTTP client of one gateway's workbench."""

    def __init__(self, session: aiohttp.ClientSession, port: int) -> None:
        self.session = session
        self.base = f"http://127.0.0.1:{port}"

    async def get(self, path: str) -> tuple[int, Any]:
        async with self.session.get(self.base + path) as response:
            body = await response.read()
            kind = response.headers.get("Content-Type", "")
            return response.status, json.loads(body) if "json" in kind else body.decode()

    async def json(self, path: str) -> Any:
        status, body = await self.get(path)
        assert status == 200, (path, status, body)
        return body


@contextlib.asynccontextmanager
async def serving(sim_line: SimLine) -> AsyncIterator[tuple[Gateway, Client]]:
    """A gateway with the workbench on *sim_line*, and a client of it.

    A context manager in the test's own task, not a fixture: the gateway's task
    groups must be left in the task that entered them.
    """
    async with (
        running_gateway(gateway_toml(sim_line.url, extra=HTTP)) as gateway,
        aiohttp.ClientSession() as session,
    ):
        yield gateway, Client(session, http(gateway).port)


def snapshot_of(gateway: Gateway, node: int) -> DriveSnapshot:
    drive = gateway.drive("hall", node)
    assert drive is not None
    return drive.snapshot


async def until_samples(gateway: Gateway, count: int) -> None:
    await wait_for(
        lambda: all(d.trend is not None and len(d.trend) >= count for d in gateway.drives),
        f"{count} trend samples of every drive",
    )


async def test_the_gateway_lines_and_drives(sim_line: SimLine) -> None:
    async with serving(sim_line) as (gateway, client):
        await until_samples(gateway, 1)
        about = await client.json("/api/v1/gateway")
        assert about["writes"] is False
        assert about["trend_s"] == 60
        assert about["lines"] == [
            {
                "name": "hall",
                "protocol": "sj300",
                "nodes": [1, 2, 3, 4],
                "interval_s": 0.1,
                "lease_s": 5.0,
                "grants": [],  # a read-only gateway shows none
            }
        ]
        (line,) = await client.json("/api/v1/lines")
        assert line["name"] == "hall"
        assert line["connected"] is True
        assert line["drives"] == 4
        assert line["requests"] >= line["replies"] > 0
        assert line["timeouts"] == line["naks"] == line["early_frames"] == 0
        drives = await client.json("/api/v1/drives")
        assert [(d["line"], d["node"]) for d in drives] == [("hall", n) for n in (1, 2, 3, 4)]
        one = await client.json("/api/v1/drives/hall/2")
        assert one["node"] == 2
        assert one["online"] is True
        assert one["state"] == "stopped"
        assert one["parameters"]["A004"]["unit"] == "Hz"


@pytest.mark.parametrize(
    ("path", "status", "error"),
    [
        ("/api/v1/drives/hall/9", 404, "no drive '9' on line 'hall'"),
        ("/api/v1/drives/yard/1", 404, "no drive '1' on line 'yard'"),
        ("/api/v1/drives/hall/x1", 404, "no drive 'x1' on line 'hall'"),
        ("/api/v1/drives/hall/1/trend?since=soon", 400, "since: expected Unix seconds, got 'soon'"),
        ("/api/v1/drives/hall/1/trend?since=nan", 400, "since: expected Unix seconds, got 'nan'"),
    ],
)
async def test_a_bad_path_or_query_is_a_json_error(
    sim_line: SimLine, path: str, status: int, error: str
) -> None:
    async with serving(sim_line) as (_, client):
        assert await client.get(path) == (status, {"error": error})


@pytest.mark.parametrize("method", ["POST", "PUT", "DELETE", "PATCH"])
@pytest.mark.parametrize(
    "path", ["/api/v1/drives/hall/1", "/api/v1/drives/hall/1/trend", "/api/v1/events", "/"]
)
async def test_a_read_only_gateway_has_no_route_that_writes(
    sim_line: SimLine, method: str, path: str
) -> None:
    async with (
        serving(sim_line) as (_, client),
        client.session.request(method, client.base + path, data=b"{}") as response,
    ):
        assert response.status == 405
        assert set(response.headers["Allow"].replace(" ", "").split(",")) == {"GET", "HEAD"}


async def test_the_trend_is_every_monitor_sample_the_gateway_took(sim_line: SimLine) -> None:
    published: list[DriveSnapshot] = []
    async with running_gateway(gateway_toml(sim_line.url, extra=HTTP)) as gateway:
        northbound = http(gateway)
        original: Callable[[ServedDrive], None] = northbound.publish

        def spy(served: ServedDrive) -> None:
            published.append(served.snapshot)
            original(served)

        northbound.publish = spy  # type: ignore[method-assign]
        await gateway.lines[0].bus.drive(3).set_frequency(20.0)
        await gateway.lines[0].bus.drive(3).run_forward()
        await wait_for(
            lambda: (snapshot_of(gateway, 3).output_frequency_hz or 0) > 2.0,
            "drive 3 ramping up",
        )
        async with aiohttp.ClientSession() as session:
            client = Client(session, northbound.port)
            trend = await client.json("/api/v1/drives/hall/3/trend")
            last = trend["time"][-1]
            later = await client.json(f"/api/v1/drives/hall/3/trend?since={last - 1e-6}")
    mine = [s for s in published if s.node == 3]
    # One sample per monitor read: the snapshots of a read-back or trip read repeat one.
    reads: dict[float, DriveSnapshot] = {}
    for snapshot in mine:
        reads.setdefault(snapshot.monitor_at, snapshot)
    samples = [s for s in reads.values() if s.monitor_at != -math.inf]
    served = list(
        zip(
            trend["output_frequency_hz"],
            trend["output_current_a"],
            trend["output_voltage_v"],
            strict=True,
        )
    )
    taken = [(s.output_frequency_hz, s.output_current_a, s.output_voltage_v) for s in samples][
        : len(served)
    ]
    assert served == taken
    assert trend["time"] == sorted(set(trend["time"]))
    assert trend["capacity"] == 660  # 60 s at 0.1 s, and one in ten more
    assert later["time"] == [last]


async def test_the_csv_is_the_trend(sim_line: SimLine) -> None:
    async with serving(sim_line) as (gateway, client):
        await until_samples(gateway, 3)
        trend = await client.json("/api/v1/drives/hall/1/trend")
        async with client.session.get(client.base + "/api/v1/drives/hall/1/trend.csv") as response:
            assert response.status == 200
            assert response.headers["Content-Type"].startswith("text/csv")
            assert response.headers["Content-Disposition"] == (
                'attachment; filename="hall-1-trend.csv"'
            )
            rows = list(csv.reader(io.StringIO(await response.text())))
        assert rows[0] == [
            "time_utc",
            "time_unix",
            "output_frequency_hz",
            "output_current_a",
            "output_voltage_v",
        ]
        count = len(trend["time"])
        assert len(rows) - 1 >= count  # the CSV was read after the JSON: maybe more samples
        for row, at, hz in zip(rows[1:], trend["time"], trend["output_frequency_hz"], strict=False):
            assert float(row[1]) == pytest.approx(at, abs=5e-4)
            assert float(row[2]) == hz


async def test_the_trip_history_route(sim_line: SimLine) -> None:
    async with serving(sim_line) as (gateway, client):
        log = await client.json("/api/v1/drives/hall/1/trips")
        assert set(log) == {"time", "total_count", "records"}
        await wait_for(
            lambda: snapshot_of(gateway, 1).trips is not None,
            "drive 1's trip history read",
        )
        log = await client.json("/api/v1/drives/hall/1/trips")
        assert log["time"] is not None
        assert isinstance(log["records"], list)


class Events:
    """An event-stream reader: each event as (name, data)."""

    def __init__(self, response: aiohttp.ClientResponse) -> None:
        self.response = response

    async def next(self) -> tuple[str, Any]:
        name = ""
        data = ""
        while True:
            raw = await self.response.content.readline()
            if not raw:
                raise AssertionError("the event stream ended")
            line = raw.decode().rstrip("\n")
            if line.startswith("event: "):
                name = line.removeprefix("event: ")
            elif line.startswith("data: "):
                data = line.removeprefix("data: ")
            elif line == "" and name:
                return name, json.loads(data)

    async def until(self, predicate: Callable[[str, Any], bool], what: str) -> Any:
        # A deadline checked at each event, besides the time-out around the read: a
        # stream that keeps sending other events must not wait forever either.
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 10
        while loop.time() < deadline:
            async with asyncio.timeout_at(deadline):
                name, data = await self.next()
            if predicate(name, data):
                return data
        raise AssertionError(f"no event within 10 s: {what}")


async def test_the_event_stream_starts_with_everything_then_follows(
    sim_line: SimLine,
) -> None:
    async with running_gateway(gateway_toml(sim_line.url, extra=HTTP)) as gateway:
        northbound = http(gateway)
        async with (
            aiohttp.ClientSession() as session,
            session.get(f"http://127.0.0.1:{northbound.port}/api/v1/events") as response,
        ):
            assert response.headers["Content-Type"] == "text/event-stream"
            events = Events(response)
            first = [await events.next() for _ in range(6)]
            assert [name for name, _ in first] == ["gateway", "line"] + ["drive"] * 4
            assert [data["node"] for name, data in first if name == "drive"] == [1, 2, 3, 4]
            await wait_for(lambda: northbound.workbench is not None, "started")
            await gateway.lines[0].bus.drive(2).set_frequency(15.0)
            await gateway.lines[0].bus.drive(2).run_forward()
            running = await events.until(
                lambda name, data: (
                    name == "drive" and data["node"] == 2 and (data["output_frequency_hz"] or 0) > 0
                ),
                "drive 2 ramping up",
            )
            assert running["running"] is True
            assert running["direction"] == "forward"
            line = await events.until(lambda name, data: name == "line", "a line event")
            assert line["utilisation"] is not None
            workbench = northbound.workbench
            assert workbench is not None
            assert len(workbench.hub) == 1
        await wait_for(lambda: len(workbench.hub) == 0, "the stream closed on the server too")


async def test_a_slow_stream_gets_the_latest_state_not_a_backlog(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url, extra=HTTP)) as gateway:
        workbench = http(gateway).workbench
        assert workbench is not None
        stream = workbench.hub.open()  # a client that does not read
        replaced = workbench.hub.replaced
        await wait_for(lambda: workbench.hub.replaced >= replaced + 40, "40 states replaced")
        chunk = await stream.take(0)
        assert chunk is not None
        frames = [f for f in chunk.split(b"\n\n") if f]
        subjects = set()
        for frame in frames:
            data = json.loads(frame.split(b"data: ", 1)[1])
            subjects.add(data.get("node", data.get("name")))
        # One pending frame per subject at most: four drives and the line.
        assert len(frames) == len(subjects) <= 5
        workbench.hub.discard(stream)


async def test_stopping_the_gateway_ends_the_event_streams(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url, extra=HTTP)) as gateway:
        port = http(gateway).port
        session = aiohttp.ClientSession()
        response = await session.get(f"http://127.0.0.1:{port}/api/v1/events")
        events = Events(response)
        await events.next()
    # The gateway is stopped: the stream ends (it did not hold the shutdown up).
    async with asyncio.timeout(5):
        while await response.content.readline():
            pass
    response.close()
    await session.close()


async def test_security_headers_and_the_page(sim_line: SimLine) -> None:
    async with serving(sim_line) as (_, client):
        async with client.session.get(client.base + "/") as response:
            assert response.status == 200
            page = await response.text()
            headers = response.headers
        assert "/static/app.js" in page
        assert "http://" not in page.replace("http://www.w3.org", "")  # nothing from elsewhere
        assert headers["X-Content-Type-Options"] == "nosniff"
        assert headers["X-Frame-Options"] == "DENY"
        assert "default-src 'self'" in headers["Content-Security-Policy"]
        assert headers["Server"] == "sj300-gateway"
        for asset in (
            "/static/app.js",
            "/static/app.css",
            "/static/vendor/uplot/uPlot.iife.min.js",
        ):
            status, _ = await client.get(asset)
            assert status == 200, asset
        status, _ = await client.get("/static/../__init__.py")
        assert status in (403, 404)


# -- the line, seen ---------------------------------------------------------------------------


async def test_the_line_s_frames_are_paired_and_timed(sim_line: SimLine) -> None:
    async with serving(sim_line) as (gateway, client):
        await until_samples(gateway, 3)
        answer = await client.json("/api/v1/lines/hall/frames?seconds=2")
        frames = answer["frames"]
        assert answer["line"] == "hall"
        requests = {f["n"]: f for f in frames if f["role"] == "request"}
        replies = [f for f in frames if f["role"] == "reply"]
        assert len(replies) >= 8
        for reply in replies:
            if reply["answers"] in requests:  # its request is in the window too
                request = requests[reply["answers"]]
                assert request["node"] == reply["node"]
                assert request["direction"] == "tx"
                assert reply["direction"] == "rx"
                assert 0 < reply["latency_ms"] < 1000
        assert not any(f["anomalies"] for f in frames)  # a clean line
        assert [f["time"] for f in frames] == sorted(f["time"] for f in frames)
        two = await client.json("/api/v1/lines/hall/frames?seconds=2&node=2")
        assert two["frames"]
        assert {f["node"] for f in two["frames"]} == {2}


async def test_a_corrupted_reply_is_flagged_on_the_line(sim_line: SimLine) -> None:
    async with serving(sim_line) as (gateway, client):
        await until_samples(gateway, 1)
        sim_line.sim.faults.corrupt_next(3)
        await wait_for(
            lambda: gateway.lines[0].bus.stats.bad_frames > 0, "the corrupted reply received"
        )
        frames = (await client.json("/api/v1/lines/hall/frames?seconds=10"))["frames"]
        flagged = [f for f in frames if "bad check code" in f["anomalies"]]
        assert len(flagged) == 1
        assert flagged[0]["role"] == "broken"
        line = await client.json("/api/v1/lines")
        assert line[0]["bad_frames"] == 1


async def test_the_last_seconds_download_as_pcapng(sim_line: SimLine) -> None:
    async with serving(sim_line) as (gateway, client):
        await until_samples(gateway, 3)
        url = client.base + "/api/v1/lines/hall/capture.pcapng?seconds=2"
        async with client.session.get(url) as response:
            assert response.status == 200
            assert response.headers["Content-Type"] == "application/x-pcapng"
            assert response.headers["Content-Disposition"].startswith('attachment; filename="hall-')
            data = await response.read()
    capture = read_pcapng(data)
    (interface,) = capture.interfaces
    assert interface.name == "hall"
    assert len(capture.packets) >= 8
    directions = {p.direction for p in capture.packets}
    assert directions == {PacketDirection.INBOUND, PacketDirection.OUTBOUND}
    # The packets are the frames, byte for byte: the requests start with STX and end CR.
    assert all(p.data.startswith(b"\x02") and p.data.endswith(b"\r") for p in capture.packets)


_SECONDS = "seconds: expected 0 < seconds <= 300, got"


@pytest.mark.parametrize(
    ("path", "status", "error"),
    [
        ("/api/v1/lines/yard/frames", 404, "no line 'yard'"),
        ("/api/v1/lines/hall/frames?seconds=0", 400, f"{_SECONDS} '0'"),
        ("/api/v1/lines/hall/frames?seconds=301", 400, f"{_SECONDS} '301'"),
        ("/api/v1/lines/hall/frames?node=-1", 400, "node: expected a node number, got '-1'"),
        ("/api/v1/lines/hall/capture.pcapng?seconds=x", 400, f"{_SECONDS} 'x'"),
    ],
)
async def test_a_bad_line_query_is_a_json_error(
    sim_line: SimLine, path: str, status: int, error: str
) -> None:
    async with serving(sim_line) as (_, client):
        assert await client.get(path) == (status, {"error": error})
