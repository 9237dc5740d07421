"""The gateway's Prometheus metrics and health check, over the real HTTP server.

Real buses (``sim://`` lines, one behind an echoing adapter), the real
collector and registry, the real server on a free port of 127.0.0.1, a raw
asyncio client; the exposition is parsed with prometheus_client's own parser
and compared with the buses' counters. The only stand-in is the
:class:`Source`, the test's own input in place of the gateway's cache.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import AsyncIterator, Callable, Iterable, Iterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import pytest
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry
from prometheus_client.core import Metric
from prometheus_client.parser import text_string_to_metric_families
from prometheus_client.samples import Sample
from waiting import wait_for

import sj300_async as sj
from sj300_async.bus import Bus
from sj300_async.bus._stats import LATENCY_BUCKETS_S
from sj300_async.gateway import (
    ConnectionLimit,
    DriveView,
    Endpoint,
    LineView,
    busy_seconds,
    cumulative_buckets,
    excerpt,
    gateway_metrics,
    line_problems,
)
from sj300_async.gateway.http._api import serve_http
from sj300_async.gateway.http._server import MAX_LINE_BYTES, make_registry
from sj300_async.gateway.modbus import OTHER_CLIENT, ClientCounters, client_families
from sj300_async.simulator import LinePacing, PlausibleLine, SimulatorEndpoint
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.transports import loopback_connector
from sj300_async.wire import LineSettings

# -- the test's input and its HTTP client ---------------------------------------------------


@dataclass
class Source:
    """A MetricsSource: the lines and drives the test sets up."""

    line_views: list[LineView] = field(default_factory=list)
    drive_views: list[DriveView] = field(default_factory=list)

    def lines(self) -> Iterable[LineView]:
        return self.line_views

    def drives(self) -> Iterable[DriveView]:
        return self.drive_views


def registry_of(source: Source, clients: ClientCounters) -> CollectorRegistry:
    """The registry the HTTP northbound serves: the lines' and drives' families, then the
    Modbus northbound's (its clients'), built at each scrape."""

    def collect() -> Iterator[Metric]:
        yield from gateway_metrics(source.lines(), source.drives())
        yield from client_families(clients)

    return make_registry(collect)


@dataclass(frozen=True)
class Response:
    status: int
    headers: dict[str, str]
    body: bytes


@asynccontextmanager
async def http_server(
    registry: CollectorRegistry, health: Callable[[], list[str]] = list
) -> AsyncIterator[int]:
    """Serve on a free port of 127.0.0.1; yield the port."""
    server = await serve_http(Endpoint("127.0.0.1", 0), registry, health)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()
        await server.wait_closed()


async def exchange(port: int, request: bytes) -> bytes:
    """Send *request* raw and return everything the server sends until it closes."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(request)
        await writer.drain()
        return await reader.read()  # to EOF: the server closes after one response
    finally:
        writer.close()
        await writer.wait_closed()


def parse_response(raw: bytes) -> Response:
    head, _, body = raw.partition(b"\r\n\r\n")
    status_line, *header_lines = head.decode("ascii").split("\r\n")
    version, status, _reason = status_line.split(" ", 2)
    assert version.startswith("HTTP/"), status_line  # a refusal answers in the request's version
    headers = {}
    for line in header_lines:
        name, _, value = line.partition(":")
        headers[name.strip().lower()] = value.strip()
    return Response(int(status), headers, body)


async def fetch(port: int, path: str, method: str = "GET") -> Response:
    request = (
        f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: */*\r\nConnection: close\r\n\r\n"
    )
    return parse_response(await exchange(port, request.encode("ascii")))


async def scrape(port: int) -> list[Sample]:
    response = await fetch(port, "/metrics")
    assert response.status == 200
    assert response.headers["content-type"] == CONTENT_TYPE_LATEST
    assert response.headers["connection"] == "close"
    assert int(response.headers["content-length"]) == len(response.body)
    families = text_string_to_metric_families(response.body.decode("utf-8"))
    return [sample for family in families for sample in family.samples]


def value(samples: list[Sample], name: str, **labels: str) -> float:
    """The one sample named *name* whose labels include *labels*."""
    found = [s.value for s in samples if s.name == name and labels.items() <= s.labels.items()]
    assert len(found) == 1, f"{name}{labels}: {len(found)} samples"
    return found[0]


def buckets(samples: list[Sample], line: str) -> list[tuple[float, float]]:
    """The latency histogram's (le, cumulative count) pairs of *line*, in bound order."""
    found = [
        (float(s.labels["le"]), s.value)
        for s in samples
        if s.name == "sj300_line_latency_seconds_bucket" and s.labels["line"] == line
    ]
    return sorted(found)


# -- per line ---------------------------------------------------------------------------------


async def test_line_counters_are_the_bus_counters() -> None:
    async with sj.open_bus("sim://?nodes=1-2", timeout=0.05) as bus:
        for _ in range(3):
            await bus.drive(1).read_status()
        with pytest.raises(sj.NakError) as refused:
            await bus.drive(1).read_parameter_raw("A999")
        assert refused.value.code == sj.NakCode.ABNORMAL_PARAMETER  # 16: not retried
        bus.simulator.faults.silence(2)
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(2).read_status()
        source = Source([LineView("hall-a", bus)])
        async with http_server(registry_of(source, ClientCounters())) as port:
            samples = await scrape(port)
        totals, stats = bus.stats.transactions, bus.stats
        # The scenario did what it says: three attempts at node 2, two of them retries.
        assert totals.timeouts == 3
        assert totals.retries == 2
        line = {"line": "hall-a"}
        assert value(samples, "sj300_line_up", **line) == 1
        expected = {
            "sj300_line_requests_total": totals.requests,
            "sj300_line_replies_total": totals.replies,
            "sj300_line_retries_total": totals.retries,
            "sj300_line_timeouts_total": totals.timeouts,
            "sj300_line_broadcasts_total": totals.broadcasts,
            "sj300_line_protocol_errors_total": totals.protocol_errors,
            "sj300_line_transport_errors_total": totals.transport_errors,
            "sj300_line_bad_frames_total": stats.bad_frames,
            "sj300_line_discarded_bytes_total": stats.discarded_bytes,
            "sj300_line_resyncs_total": stats.resyncs,
            "sj300_line_reconnects_total": stats.disconnects,
        }
        assert {name: value(samples, name, **line) for name in expected} == expected
        assert value(samples, "sj300_line_naks_total", code="16", **line) == 1
        assert value(samples, "sj300_line_bytes_total", direction="tx", **line) == (
            stats.bytes_written
        )
        assert value(samples, "sj300_line_bytes_total", direction="rx", **line) == (
            stats.bytes_received
        )
        for kind in ("stray", "unsolicited", "early"):
            assert value(samples, "sj300_line_discarded_frames_total", kind=kind, **line) == (
                getattr(stats, f"{kind}_frames")
            )
        # An instant line (baud rate 0) takes no wire time at all.
        assert bus.line.baudrate == 0
        assert value(samples, "sj300_line_busy_seconds_total", **line) == 0.0


async def test_latency_histogram_is_cumulative_and_counts_the_replies() -> None:
    async with sj.open_bus("sim://?nodes=1&baudrate=19200") as bus:
        for _ in range(5):
            await bus.drive(1).read_status()
        async with http_server(
            registry_of(Source([LineView("l1", bus)]), ClientCounters())
        ) as port:
            samples = await scrape(port)
    totals = bus.stats.transactions
    pairs = buckets(samples, "l1")
    assert [le for le, _ in pairs] == [*LATENCY_BUCKETS_S, math.inf]
    counts = [count for _, count in pairs]
    assert counts == sorted(counts)  # cumulative: never decreasing
    assert counts[-1] == totals.replies == 5
    assert value(samples, "sj300_line_latency_seconds_count", line="l1") == totals.replies
    assert value(samples, "sj300_line_latency_seconds_sum", line="l1") == totals.latency_sum_s
    # Each bucket counts what the bus counted at or below its bound.
    running = 0
    for (_, count), own in zip(pairs, totals.latency_counts, strict=True):
        running += own
        assert count == running


def test_cumulative_buckets_put_the_slowest_under_inf_only() -> None:
    counts = [0] * len(LATENCY_BUCKETS_S) + [2]
    counts[0] = 1
    built = cumulative_buckets(counts)
    assert built[0] == ("0.005", 1)
    assert built[-2] == ("5.0", 1)
    assert built[-1] == ("+Inf", 3)
    with pytest.raises(ValueError, match="bucket counts"):
        cumulative_buckets([1, 2])


async def test_busy_seconds_are_the_bytes_wire_time() -> None:
    async with sj.open_bus("sim://?nodes=1&baudrate=19200") as bus:
        await bus.drive(1).read_status()
        await bus.drive(1).read_parameter_raw("A004")
        async with http_server(
            registry_of(Source([LineView("l1", bus)]), ClientCounters())
        ) as port:
            samples = await scrape(port)
    stats = bus.stats
    assert stats.echo_bytes == 0
    assert stats.bytes_written > 0
    expected = (stats.bytes_written + stats.bytes_received) * 10 / 19200  # 8N1: 10 bits a byte
    assert value(samples, "sj300_line_busy_seconds_total", line="l1") == pytest.approx(expected)
    assert busy_seconds(bus) == pytest.approx(expected)


@dataclass
class EchoingAdapter:
    """An RS-485 adapter without echo suppression: it hands every written byte back first."""

    inner: SimulatorEndpoint
    send: Callable[[bytes], object]

    def data_received(self, data: bytes) -> None:
        self.send(data)
        self.inner.data_received(data)

    def close(self) -> None:
        self.inner.close()


async def test_busy_seconds_count_a_local_echo_once() -> None:
    """The bus counts an echo as written and received; the line carried it once."""
    line = LineSettings(19200)
    pacing = LinePacing(line.baudrate, line.bytesize, line.parity, line.stopbits)
    sim = SimulatedBus(nodes=[1])

    def adapter(send: Callable[[bytes], None]) -> EchoingAdapter:
        return EchoingAdapter(SimulatorEndpoint(sim, send=send, line=PlausibleLine(pacing)), send)

    bus: Bus[Any, Any] = Bus(
        loopback_connector(adapter),
        description="echoing line",
        line=line,
        timing=sj.BusTiming(),
        strip_echo=True,
    )
    async with bus:
        await bus.drive(1).read_status()
        await bus.drive(1).read_parameter_raw("A004")
    stats = bus.stats
    assert stats.echo_bytes == stats.bytes_written > 0  # every written byte came back
    assert stats.transactions.replies == 2
    assert busy_seconds(bus) == pytest.approx(stats.bytes_received * line.char_time_s)


async def test_a_closed_line_is_down_and_unhealthy() -> None:
    async with (
        sj.open_bus("sim://?nodes=1") as up,
        sj.open_bus("sim://?nodes=1") as down,
    ):
        await down.drive(1).read_status()
        await down.aclose()  # its counters stay readable
        source = Source([LineView("hall-a", up), LineView("hall-b", down)])
        registry = registry_of(source, ClientCounters())
        async with http_server(registry, lambda: line_problems(source.lines())) as port:
            samples = await scrape(port)
            health = await fetch(port, "/healthz")
        assert value(samples, "sj300_line_up", line="hall-a") == 1
        assert value(samples, "sj300_line_up", line="hall-b") == 0
        assert value(samples, "sj300_line_replies_total", line="hall-b") == 1
        assert health.status == 503
        assert health.body == b"line hall-b: link down\n"
        assert health.headers["content-type"].startswith("text/plain")


# -- per drive and per client ----------------------------------------------------------------


async def test_drive_metrics_leave_out_what_is_not_known() -> None:
    source = Source(
        drive_views=[
            DriveView("hall-a", 1, True, 0.25, 42.5, 3.1),
            DriveView("hall-a", 2, False, None, None, None),
            DriveView("hall-b", 7, False, 12.0, None, 0.0),
        ]
    )
    async with http_server(registry_of(source, ClientCounters())) as port:
        samples = await scrape(port)
    one, two, seven = (
        {"line": "hall-a", "node": "1"},
        {"line": "hall-a", "node": "2"},
        {"line": "hall-b", "node": "7"},
    )
    assert value(samples, "sj300_drive_online", **one) == 1
    assert value(samples, "sj300_drive_online", **two) == 0
    assert value(samples, "sj300_drive_sample_age_seconds", **one) == 0.25
    assert value(samples, "sj300_drive_output_frequency_hertz", **one) == 42.5
    assert value(samples, "sj300_drive_output_current_amperes", **one) == 3.1
    assert value(samples, "sj300_drive_sample_age_seconds", **seven) == 12.0
    assert value(samples, "sj300_drive_output_current_amperes", **seven) == 0.0  # 0 is known
    # Nodes 2 and 7 have no sample of what is not known (None), and nothing made up.
    present = {
        (s.labels["node"], s.name)
        for s in samples
        if s.labels.get("node") in ("2", "7") and s.name != "sj300_drive_online"
    }
    assert present == {
        ("7", "sj300_drive_sample_age_seconds"),
        ("7", "sj300_drive_output_current_amperes"),
    }


async def test_client_counters() -> None:
    clients = ClientCounters()
    for _ in range(3):
        clients.request("10.0.0.5")
    clients.request("10.0.0.6")
    clients.exception("10.0.0.5", 2)
    clients.exception("10.0.0.5", 11)
    clients.exception("10.0.0.5", 11)
    async with http_server(registry_of(Source(), clients)) as port:
        samples = await scrape(port)
    assert value(samples, "sj300_modbus_requests_total", client="10.0.0.5") == 3
    assert value(samples, "sj300_modbus_requests_total", client="10.0.0.6") == 1
    assert value(samples, "sj300_modbus_exceptions_total", client="10.0.0.5", code="2") == 1
    assert value(samples, "sj300_modbus_exceptions_total", client="10.0.0.5", code="11") == 2
    assert not any(
        s.name == "sj300_modbus_exceptions_total" and s.labels["client"] == "10.0.0.6"
        for s in samples
    )


def test_client_addresses_past_the_cap_share_one_label(caplog: pytest.LogCaptureFixture) -> None:
    clients = ClientCounters(max_clients=2)
    for address in ("10.0.0.1", "10.0.0.2", "10.0.0.3", "10.0.0.4", "10.0.0.1"):
        clients.request(address)
    clients.exception("10.0.0.9", 4)
    assert clients.requests == {"10.0.0.1": 2, "10.0.0.2": 1, OTHER_CLIENT: 2}
    assert clients.exceptions == {(OTHER_CLIENT, 4): 1}
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert "10.0.0.3" in warnings[0].getMessage()


async def test_an_empty_gateway_exports_its_families_without_samples() -> None:
    async with http_server(registry_of(Source(), ClientCounters())) as port:
        response = await fetch(port, "/metrics")
    text = response.body.decode()
    assert "# TYPE sj300_line_latency_seconds histogram" in text
    assert "# HELP sj300_line_busy_seconds_total" in text
    assert "rate(sj300_line_busy_seconds_total[1m])" in text
    assert [s for f in text_string_to_metric_families(text) for s in f.samples] == []


def test_the_registry_is_not_the_global_one() -> None:
    from prometheus_client import REGISTRY

    registry = registry_of(Source(), ClientCounters())
    assert registry is not REGISTRY
    assert not any(family.name.startswith("sj300_") for family in REGISTRY.collect())


# -- HTTP ---------------------------------------------------------------------------------------


async def test_healthz_ok() -> None:
    async with http_server(registry_of(Source(), ClientCounters()), list) as port:
        response = await fetch(port, "/healthz")
    assert (response.status, response.body) == (200, b"ok\n")
    assert response.headers["connection"] == "close"


async def test_healthz_lists_every_problem() -> None:
    problems = ["line hall-a: link down", "line hall-b: link down"]
    async with http_server(registry_of(Source(), ClientCounters()), lambda: problems) as port:
        response = await fetch(port, "/healthz")
    assert response.status == 503
    assert response.body == b"line hall-a: link down\nline hall-b: link down\n"


@pytest.mark.parametrize("path", ["/metrics", "/healthz", "/nowhere"])
async def test_head_is_get_without_the_body(path: str) -> None:
    async with http_server(registry_of(Source(), ClientCounters()), lambda: ["x"]) as port:
        got = await fetch(port, path)
        head = await fetch(port, path, "HEAD")
    assert head.status == got.status
    assert head.body == b""
    del head.headers["date"], got.headers["date"]  # a second may tick between the two
    assert head.headers == got.headers  # Content-Length included: the GET's body length
    assert int(head.headers["content-length"]) == len(got.body) > 0


async def test_a_query_string_is_ignored() -> None:
    async with http_server(registry_of(Source(), ClientCounters())) as port:
        response = await fetch(port, "/healthz?verbose=1")
    assert (response.status, response.body) == (200, b"ok\n")


@pytest.mark.parametrize(
    ("request_bytes", "status"),
    [
        (b"GET /metricz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n", 404),
        (b"GET / HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n", 404),
        (
            b"POST /metrics HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
            405,
        ),
        (b"DELETE /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n", 405),
        (b"GET /metrics HTTP/1.1\r\n\r\n", 400),  # HTTP/1.1 without Host (RFC 9112, 3.2)
        (b"GET  /metrics HTTP/1.1\r\n\r\n", 400),
        (b"GET metrics HTTP/1.1\r\n\r\n", 400),
        (b"GET /metrics HTTP/x\r\n\r\n", 400),
        (b"GET /m\xe9trics HTTP/1.1\r\n\r\n", 400),
        (b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\n\n", 400),  # TLS to a plain port
    ],
)
async def test_refusals(
    request_bytes: bytes, status: int, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.http")
    async with http_server(registry_of(Source(), ClientCounters())) as port:
        response = parse_response(await exchange(port, request_bytes))
    assert response.status == status  # and closed: exchange() reads to the end
    if status == 405:
        assert response.headers["allow"].replace(" ", "").split(",") == ["GET", "HEAD"]
    # Nothing dropped silently: the refusal is logged with an escaped excerpt of the request.
    logged = [r.getMessage() for r in caplog.records if f"refused {status}" in r.getMessage()]
    assert len(logged) == 1, [r.getMessage() for r in caplog.records]
    assert excerpt(request_bytes[:16]) in logged[0]


async def test_bare_lf_line_ends_are_refused_cleanly() -> None:
    # RFC 9112 lets a server take a bare LF; aiohttp's parser does not. A clean 400
    # and a closed connection, not a hang, is what matters.
    async with http_server(registry_of(Source(), ClientCounters())) as port:
        response = parse_response(await exchange(port, b"GET /healthz HTTP/1.0\n\n"))
        good = await fetch(port, "/healthz")
    assert response.status == 400
    assert (good.status, good.body) == (200, b"ok\n")


async def test_an_oversized_head_is_refused(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.http")
    one_long_line = b"X-Long: " + b"a" * (2 * MAX_LINE_BYTES) + b"\r\n"
    long_target = b"/metrics?" + b"a" * (2 * MAX_LINE_BYTES)
    async with http_server(registry_of(Source(), ClientCounters())) as port:
        for request in (
            b"GET /metrics HTTP/1.1\r\n" + one_long_line + b"\r\n",
            b"GET " + long_target + b" HTTP/1.1\r\n\r\n",
        ):
            response = parse_response(await exchange(port, request))
            assert 400 <= response.status < 500  # and closed: exchange() reads to the end
    refusals = [r.getMessage() for r in caplog.records if "refused 4" in r.getMessage()]
    assert len(refusals) == 2
    assert all(len(message) < 400 for message in refusals)  # an excerpt, not the request


async def test_a_slow_head_is_closed_without_an_answer(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.http")
    limit = ConnectionLimit("http", 8, logging.getLogger("test.http"))
    server = await serve_http(
        Endpoint("127.0.0.1", 0), make_registry(list), list, limit=limit, idle_timeout_s=0.05
    )
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
        writer.write(b"GET /metrics HTTP/1.1\r\nHost: x\r\n")  # and then nothing
        await writer.drain()
        assert await asyncio.wait_for(reader.read(), 5) == b""  # closed by the server
        writer.close()
        await writer.wait_closed()
    finally:
        server.close()
        await server.wait_closed()
    assert limit.timed_out == 1
    logged = [r.getMessage() for r in caplog.records if "no request for" in r.getMessage()]
    assert len(logged) == 1
    assert "Host: x" in logged[0]


async def test_a_client_that_leaves_early_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway.http")
    async with http_server(registry_of(Source(), ClientCounters())) as port:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /metrics HTTP/1.1\r\n")
        writer.write_eof()  # half-closed: the head can never end
        assert await asyncio.wait_for(reader.read(), 5) == b""
        writer.close()
        await writer.wait_closed()
        await wait_for(
            lambda: any("before a whole request" in r.getMessage() for r in caplog.records),
            "the unfinished request logged",
        )


async def test_a_failing_health_check_is_a_500_with_its_traceback_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    def broken() -> list[str]:
        raise RuntimeError("cache gone")

    async with http_server(registry_of(Source(), ClientCounters()), broken) as port:
        response = await fetch(port, "/healthz")
        healthy_metrics = await fetch(port, "/metrics")
    assert response.status == 500
    assert healthy_metrics.status == 200  # one failing route does not take the server down
    errors = [r for r in caplog.records if r.levelno == logging.ERROR]
    assert len(errors) == 1
    assert errors[0].exc_info is not None
    assert "cache gone" in str(errors[0].exc_info[1])


async def test_concurrent_scrapes() -> None:
    async with sj.open_bus("sim://?nodes=1") as bus:
        await bus.drive(1).read_status()
        registry = registry_of(Source([LineView("l1", bus)]), ClientCounters())
        async with http_server(registry) as port:
            responses = await asyncio.gather(*(fetch(port, "/metrics") for _ in range(20)))
    assert {r.status for r in responses} == {200}
    assert len({r.body for r in responses}) == 1
