"""The HTTP door under attack (issue 41): nothing a client sends stalls the loop or the door.

A real gateway on a simulated line, real sockets on loopback; a second
client address is 127.0.0.2 (every 127/8 address is the host's own).
What the issue found, and what must hold now:

- 60 logins sent at once (heads first, then bodies) were 60 scrypt checks
  on the loop, 2.6-3.75 s of stall: now at most the address's budget of
  checks, off the loop, the rest 429 with ``Retry-After``, counted.
- 64 POSTs whose bodies never came held every slot for 24-32 s: now one
  address holds at most half the slots, another address is served
  meanwhile, and each stalled request is answered 408 (or cut) within
  ``body_timeout_s``, counted. aiohttp's lingering over an unread body
  ends at the same deadline.
- ``[`` x 1000 was a 500 with a traceback: now 400 with the reason, on
  every route that reads JSON.
- A client closing a parameter-read stream or cutting a body logged an
  ERROR with a traceback: now DEBUG.
- Event streams: at most ``max_streams_per_address`` from one address.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import logging
import threading
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass

import aiohttp
import pytest
from host_pauses import LoopLag
from waiting import wait_for

from sj300_async.gateway import Endpoint, Gateway
from sj300_async.gateway.http import DEFAULT_STREAMS_PER_ADDRESS
from sj300_async.gateway.http._api import serve_http
from sj300_async.gateway.http._bodies import MAX_DEPTH
from sj300_async.gateway.http._guards import LOGIN_BURST
from sj300_async.gateway.http._parameters import MAX_BACKUP_CONTAINERS
from sj300_async.gateway.http._server import make_registry

from .conftest import SimLine, running_gateway
from .test_workbench_writes import TOKEN, config_text, northbound, params_config

#: The bound the issue sets on the loop's lag under attack.
MAX_LAG_S = 0.2
#: Another client address of this host.
OTHER = "127.0.0.2"


@dataclass
class Answer:
    status: int
    headers: dict[str, str]
    body: bytes

    def json(self) -> dict[str, object]:
        data = json.loads(self.body)
        assert isinstance(data, dict)
        return data


async def connect(
    port: int, source: str = "127.0.0.1"
) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))


def head(path: str, length: int, extra: str = "") -> bytes:
    return (
        f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        f"Content-Length: {length}\r\n{extra}\r\n"
    ).encode()


async def read_answer(reader: asyncio.StreamReader) -> Answer | None:
    """The next response on the connection; None when it closes (or resets) first."""
    try:
        raw = await reader.readuntil(b"\r\n\r\n")
    except (asyncio.IncompleteReadError, ConnectionError):
        return None
    status_line, *lines = raw.decode("latin-1").split("\r\n")
    headers = {}
    for line in lines:
        name, _, value = line.partition(":")
        headers[name.strip().lower()] = value.strip()
    body = await reader.readexactly(int(headers.get("content-length", "0")))
    return Answer(int(status_line.split(" ", 2)[1]), headers, body)


async def closed(reader: asyncio.StreamReader) -> None:
    """Return once the server closed the connection (whatever it still sends is dropped)."""
    with contextlib.suppress(ConnectionError):
        while await reader.read(65536):
            pass


async def get(port: int, path: str, source: str) -> Answer | None:
    reader, writer = await connect(port, source)
    try:
        writer.write(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
        return await read_answer(reader)
    finally:
        writer.close()


def counter(gateway: Gateway, name: str, **labels: str) -> float:
    for family in gateway.metrics():
        for sample in family.samples:
            if sample.name == name and sample.labels == labels:
                return float(sample.value)
    raise AssertionError(f"{name}{labels} not exported")


@contextlib.contextmanager
def no_error_logged(caplog: pytest.LogCaptureFixture) -> Iterator[None]:
    caplog.set_level(logging.DEBUG)
    yield
    loud = [r for r in caplog.records if r.levelno >= logging.ERROR or r.exc_info]
    assert not loud, [(r.name, r.levelname, r.getMessage()[:200]) for r in loud]


# -- logins ------------------------------------------------------------------------------


async def test_a_login_burst_costs_at_most_its_budget_of_checks_and_never_the_loop(
    sim_line: SimLine,
) -> None:
    # The cap raised so that the 60 connections of one address all get in.
    text = config_text(sim_line.url, extra="max_connections = 128")
    # The collector tuned as `sj300 gateway` runs it: untuned, a full collection of the
    # pytest worker's heap held this loop 0.82 s in one clean run.
    async with running_gateway(text, tune_collector=True) as gateway:
        http = northbound(gateway)
        writes = http.writes
        assert writes is not None
        body = json.dumps({"name": "alice", "password": "not it"}).encode()
        connections = [await connect(http.port) for _ in range(60)]
        with LoopLag() as probe:
            for _, writer in connections:
                writer.write(head("/api/v1/login", len(body)))
            answers = [asyncio.ensure_future(read_answer(reader)) for reader, _ in connections]
            # Refused from the head alone, before any body is sent.
            await wait_for(
                lambda: sum(answer.done() for answer in answers) >= 60 - LOGIN_BURST,
                "the refusals of the heads past the budget",
                timeout=30,
            )
            for _, writer in connections:
                writer.write(body)
            got = await asyncio.wait_for(asyncio.gather(*answers), 60)
        for _, writer in connections:
            writer.close()
        checked = writes.checks.checked
        assert 1 <= checked <= LOGIN_BURST
        statuses = Counter(answer.status if answer else None for answer in got)
        assert statuses == {429: 60 - checked, 401: checked}
        refused = [answer for answer in got if answer is not None and answer.status == 429]
        assert all(int(answer.headers["retry-after"]) >= 1 for answer in refused)
        assert "too many logins" in str(refused[0].json()["error"])
        assert counter(gateway, "sj300_http_requests_refused_total", reason="login_rate") == (
            60 - checked
        )
        assert counter(gateway, "sj300_http_password_checks_total") == checked
        assert probe.close() < MAX_LAG_S, probe.describe()
        checkers = [t for t in threading.enumerate() if t.name.startswith("sj300-password")]
        assert checkers  # the checks ran in a thread of their own
    # The gateway stopped: its door checks nothing more (PasswordChecks closed; the
    # thread is the process's, shared by every door).
    assert await writes.checks.verify("x", "scrypt$1$1$1$AA==$AA==") is None


async def test_past_the_checks_queue_a_login_is_refused_busy_unchecked(sim_line: SimLine) -> None:
    """One check runs and 8 wait (PasswordChecks); 12 logins at once from 3 addresses,
    each within its budget, leave some refused 503 before their password is checked."""
    async with running_gateway(config_text(sim_line.url)) as gateway:
        http = northbound(gateway)
        writes = http.writes
        assert writes is not None
        body = json.dumps({"name": "alice", "password": "not it"}).encode()
        sources = ["127.0.0.1", OTHER, "127.0.0.3"]
        connections = [await connect(http.port, sources[i % 3]) for i in range(12)]
        for _, writer in connections:
            writer.write(head("/api/v1/login", len(body)) + body)
        got = await asyncio.wait_for(
            asyncio.gather(*(read_answer(reader) for reader, _ in connections)), 60
        )
        for _, writer in connections:
            writer.close()
        statuses = Counter(answer.status if answer else None for answer in got)
        busy = writes.checks.busy
        assert busy >= 1
        assert statuses == {401: writes.checks.checked, 503: busy}
        refused = next(answer for answer in got if answer is not None and answer.status == 503)
        assert refused.headers["retry-after"] == "1"
        assert refused.json()["refusal"] == "busy"
        assert counter(gateway, "sj300_http_requests_refused_total", reason="login_busy") == busy
        assert writes.guard.refused == 0  # not counted as failed logins


# -- bodies that never come --------------------------------------------------------------

BODY_TIMEOUT_S = 5.0


async def _stalled(port: int, path: str, length: int) -> tuple[float, Answer | None, float]:
    """A POST announcing *length* bytes and sending none: (sent, its answer, closed), in
    loop times."""
    loop = asyncio.get_running_loop()
    reader, writer = await connect(port)
    sent = loop.time()
    try:
        writer.write(head(path, length))
        answer = await read_answer(reader)
        await closed(reader)
        return sent, answer, loop.time()
    finally:
        writer.close()


async def test_bodies_that_never_come_hold_half_the_slots_and_end_at_their_deadline(
    sim_line: SimLine,
) -> None:
    text = params_config(sim_line.url).replace(
        '[http]\nlisten = "127.0.0.1:0"',
        f'[http]\nlisten = "127.0.0.1:0"\nbody_timeout_s = {BODY_TIMEOUT_S}',
    )
    assert f"body_timeout_s = {BODY_TIMEOUT_S}" in text
    async with running_gateway(text) as gateway:
        http = northbound(gateway)
        limit, server = http.limit, http.server
        assert server is not None
        assert (limit.max_connections, limit.max_per_address) == (64, 32)
        # A login's body is at most 64 KiB (a longer one is 413 at once), a backup's 1 MiB.
        kinds = [("/api/v1/login", 1000), ("/api/v1/parameters/check?protocol=sj300", 100_000)]
        stalled = [asyncio.ensure_future(_stalled(http.port, *kinds[i % 2])) for i in range(64)]
        await wait_for(
            lambda: limit.open == 32 and limit.refused_per_address == 32,
            "32 held, 32 refused at the address's cap",
            timeout=30,
        )
        # While one address holds its half, another is served.
        health = await get(http.port, "/healthz", OTHER)
        assert health is not None
        assert (health.status, health.body) == (200, b"ok\n")
        assert server.timed_out == 0, "the stalled requests ended before /healthz was asked"
        results = await asyncio.wait_for(asyncio.gather(*stalled), BODY_TIMEOUT_S + 30)
        at_once = [r for r in results if r[1] is None and r[2] - r[0] < BODY_TIMEOUT_S / 2]
        held = [r for r in results if r not in at_once]
        assert (len(at_once), len(held)) == (32, 32)
        statuses = Counter(answer.status for _, answer, _ in held if answer is not None)
        # 408 from a handler reading the body; 429 at once past the address's budget of
        # logins or backup checks, their connections then cut at the deadline all the same.
        assert statuses[408] >= 1, statuses
        assert statuses[408] + statuses[429] == 32, statuses
        for sent, _, ended in held:
            assert BODY_TIMEOUT_S - 0.1 <= ended - sent <= BODY_TIMEOUT_S + 2.0, ended - sent
        await wait_for(lambda: limit.open == 0, "every slot freed")
        assert server.timed_out == 32
        assert counter(gateway, "sj300_http_requests_timed_out_total") == 32
        assert counter(gateway, "sj300_http_connections_refused_per_address_total") == 32


async def test_an_unread_body_is_not_lingered_over_past_its_deadline() -> None:
    """A body nobody reads (405 here) is dropped by aiohttp for up to its lingering time,
    10 s by default, holding the slot: the request's deadline ends it."""
    server = await serve_http(
        Endpoint("127.0.0.1", 0), make_registry(list), list, idle_timeout_s=60, body_timeout_s=1
    )
    loop = asyncio.get_running_loop()
    try:
        reader, writer = await connect(server.port)
        sent = loop.time()
        writer.write(head("/healthz", 100_000) + b"{")
        answer = await read_answer(reader)
        assert answer is not None
        assert answer.status == 405
        await asyncio.wait_for(closed(reader), 30)
        assert 0.9 <= loop.time() - sent <= 3.0, loop.time() - sent
        writer.close()
        assert server.timed_out == 1
        assert server.limit.timed_out == 0  # not an idle connection: its request's deadline
    finally:
        server.close()
        await server.wait_closed()


# -- nested JSON -------------------------------------------------------------------------

DEEP = [b"[" * 1000, b'{"a":' * 1000 + b"1" + b"}" * 1000, b"[" * (MAX_DEPTH + 1)]
#: More arrays than a backup holds (a request's body is one object).
WIDE = b"[" + b",".join([b"[]"] * (MAX_BACKUP_CONTAINERS + 1)) + b"]"


async def test_nested_json_is_a_400_with_its_reason_on_every_route_that_reads_json(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    with no_error_logged(caplog):
        async with (
            running_gateway(params_config(sim_line.url)) as gateway,
            aiohttp.ClientSession() as session,
        ):
            base = f"http://127.0.0.1:{northbound(gateway).port}"
            token = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
            routes = [
                ("/api/v1/login", {"Content-Type": "application/json"}),
                ("/api/v1/drives/hall/1/stop", token),
                ("/api/v1/parameters/check?protocol=sj300", {}),
            ]
            for path, headers in routes:
                for data in DEEP:
                    async with session.post(base + path, data=data, headers=headers) as response:
                        assert response.status == 400, (path, data[:8])
                        error = (await response.json())["error"]
                        assert f"nested deeper than {MAX_DEPTH} levels" in error, error
                async with session.post(base + path, data=WIDE, headers=headers) as response:
                    assert response.status == 400, path
                    assert "arrays and objects" in (await response.json())["error"]
            # As deep as allowed is read: the stop's body is an object, its tab ignored.
            allowed = b'{"tab": ' + b"[" * (MAX_DEPTH - 1) + b"]" * (MAX_DEPTH - 1) + b"}"
            async with session.post(base + routes[1][0], data=allowed, headers=token) as response:
                assert response.status == 200, await response.text()


# -- clients that go away ----------------------------------------------------------------


async def test_a_closed_stream_and_a_cut_body_are_debug_lines(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    def logged(text: str) -> bool:
        return any(text in record.getMessage() for record in caplog.records)

    with no_error_logged(caplog):
        async with (
            running_gateway(params_config(sim_line.url)) as gateway,
            aiohttp.ClientSession() as session,
        ):
            port = northbound(gateway).port
            url = f"http://127.0.0.1:{port}/api/v1/drives/hall/1/parameters"
            async with session.get(url) as response:
                assert response.status == 200
                assert (await response.content.readline()).startswith(b"event: progress")
                response.close()  # stop it, as the documentation says
            await wait_for(lambda: logged("parameter read"), "the stream's end logged")
            for path in ("/api/v1/parameters/check?protocol=sj300", "/api/v1/login"):
                _, writer = await connect(port)
                writer.write(head(path, 1000) + b'{"name": "al')
                await writer.drain()
                writer.close()  # the body cut
                route = path.partition("?")[0]
                await wait_for(functools.partial(logged, route), f"the cut body of {route} logged")
            # The door still serves.
            async with session.get(url) as response:
                assert response.status == 200
    assert logged("went away")


# -- event streams ----------------------------------------------------------------------


async def test_event_streams_are_capped_per_address(sim_line: SimLine) -> None:
    text = params_config(sim_line.url)
    async with (
        running_gateway(text) as gateway,
        aiohttp.ClientSession() as mine,
        aiohttp.ClientSession(connector=aiohttp.TCPConnector(local_addr=(OTHER, 0))) as other,
    ):
        http = northbound(gateway)
        base = f"http://127.0.0.1:{http.port}"
        events = base + "/api/v1/events"
        async with contextlib.AsyncExitStack() as streams:
            for _ in range(DEFAULT_STREAMS_PER_ADDRESS):
                response = await streams.enter_async_context(mine.get(events))
                assert response.status == 200
                assert await response.content.readline() == b"retry: 2000\n"
            for path in ("/api/v1/events", "/api/v1/drives/hall/1/parameters"):
                async with mine.get(base + path) as refused:
                    assert refused.status == 429
                    assert int(refused.headers["Retry-After"]) >= 1
                    assert "max_streams_per_address" in (await refused.json())["error"]
            async with other.get(events) as theirs:  # another address has its own
                assert theirs.status == 200
            assert counter(gateway, "sj300_http_requests_refused_total", reason="streams") == 2
        await wait_for(lambda: http.per_address.streams.held("127.0.0.1") == 0, "closed")
        async with mine.get(events) as again:
            assert again.status == 200
