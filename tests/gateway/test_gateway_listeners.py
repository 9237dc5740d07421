"""The listeners' limits (gateway/_listeners.py): configuration, the HTTP cap and the
per-address cap, the log."""

from __future__ import annotations

import asyncio
import logging
import textwrap

import pytest
from waiting import wait_for

from sj300_async.gateway import (
    ConnectionLimit,
    Endpoint,
    GatewayConfigError,
    ListenerLimits,
    RateLimitedLog,
    listener_families,
    parse_config,
)
from sj300_async.gateway._listeners import Slot
from sj300_async.gateway.http import HttpConfig
from sj300_async.gateway.http._api import serve_http
from sj300_async.gateway.http._server import make_registry
from sj300_async.gateway.modbus import ModbusConfig

from .test_gateway_metrics import fetch

_LINE = '[[lines]]\nurl = "sim://?nodes=1"\nnodes = "1"\n'


def _config(section: str) -> str:
    return textwrap.dedent(section) + _LINE


def test_the_limits_are_configured_per_listener() -> None:
    config = parse_config(
        _config(
            """\
            [modbus]
            listen = "127.0.0.1:1502"
            max_connections = 8
            idle_timeout_s = 2.5
            [metrics]
            listen = "127.0.0.1:9300"
            idle_timeout_s = 1
            """
        ),
        "test.toml",
    )
    modbus = config.northbounds["modbus"]
    assert isinstance(modbus, ModbusConfig)
    assert modbus.limits == ListenerLimits(8, 2.5)
    metrics = config.northbounds["http"]
    assert metrics == HttpConfig(Endpoint("127.0.0.1", 9300), ListenerLimits(64, 1.0))
    defaults = parse_config(_config('[modbus]\nlisten = "127.0.0.1:1502"\n'), "test.toml")
    assert defaults.northbounds["modbus"] == ModbusConfig(
        Endpoint("127.0.0.1", 1502), ListenerLimits(64, 60.0)
    )
    assert ListenerLimits(64, 60.0).per_address == 32  # half the cap when not set
    assert ListenerLimits(1, 60.0).per_address == 1


def test_the_per_address_cap_and_the_http_door_limits_are_configured() -> None:
    config = parse_config(
        _config(
            """\
            [modbus]
            listen = "127.0.0.1:1502"
            max_connections = 8
            max_connections_per_address = 8
            [http]
            listen = "127.0.0.1:9300"
            max_connections_per_address = 3
            body_timeout_s = 2.5
            max_streams_per_address = 6
            """
        ),
        "test.toml",
    )
    modbus = config.northbounds["modbus"]
    assert isinstance(modbus, ModbusConfig)
    assert modbus.limits == ListenerLimits(8, 60.0, 8)
    http = config.northbounds["http"]
    assert isinstance(http, HttpConfig)
    assert http.limits == ListenerLimits(64, 5.0, 3)
    assert http.limits.per_address == 3
    assert (http.body_timeout_s, http.max_streams_per_address) == (2.5, 6)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("max_connections = 0", "test.toml:3: modbus.max_connections: must be >= 1, got 0"),
        ("max_connections = 1.5", "test.toml:3: modbus.max_connections: expected an integer"),
        ("idle_timeout_s = 0", "test.toml:3: modbus.idle_timeout_s: must be > 0, got 0"),
        ('idle_timeout_s = "1"', "test.toml:3: modbus.idle_timeout_s: expected a number"),
        (
            "max_connections_per_address = 65",
            "test.toml:3: modbus.max_connections_per_address: must be 1..max_connections (64), "
            "got 65",
        ),
        (
            "max_connections = 4\nmax_connections_per_address = 0",
            "test.toml:4: modbus.max_connections_per_address: must be 1..max_connections (4), "
            "got 0",
        ),
    ],
)
def test_a_bad_limit_names_file_line_and_key(line: str, message: str) -> None:
    with pytest.raises(GatewayConfigError) as raised:
        parse_config(_config(f'[modbus]\nlisten = "127.0.0.1:1502"\n{line}\n'), "test.toml")
    assert str(raised.value).startswith(message), str(raised.value)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("body_timeout_s = 0", "test.toml:3: http.body_timeout_s: must be > 0, got 0"),
        ("max_streams_per_address = 0", "test.toml:3: http.max_streams_per_address: must be >= 1"),
    ],
)
def test_a_bad_http_door_limit_names_file_line_and_key(line: str, message: str) -> None:
    with pytest.raises(GatewayConfigError) as raised:
        parse_config(_config(f'[http]\nlisten = "127.0.0.1:9300"\n{line}\n'), "test.toml")
    assert str(raised.value).startswith(message), str(raised.value)


async def test_the_http_listener_refuses_past_its_cap() -> None:
    limit = ConnectionLimit("http", 2, logging.getLogger("test.http"), max_per_address=2)
    server = await serve_http(Endpoint("127.0.0.1", 0), make_registry(list), list, limit=limit)
    port = server.sockets[0].getsockname()[1]
    try:
        idle = [await asyncio.open_connection("127.0.0.1", port) for _ in range(2)]
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        async with asyncio.timeout(5):
            assert await reader.read() == b""  # closed at once, unanswered
        writer.close()
        assert (limit.open, limit.refused) == (2, 1)
        for _, idle_writer in idle:
            idle_writer.close()
        await wait_for(lambda: limit.open == 0, "the idle connections released")
        assert (await fetch(port, "/healthz")).status == 200
    finally:
        server.close()
        await server.wait_closed()


async def test_one_address_holds_at_most_its_share_and_another_still_gets_in() -> None:
    limit = ConnectionLimit("http", 4, logging.getLogger("test.http"))  # 2 per address
    server = await serve_http(Endpoint("127.0.0.1", 0), make_registry(list), list, limit=limit)
    port = server.port

    async def connect(source: str) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        return await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))

    try:
        mine = [await connect("127.0.0.1") for _ in range(2)]
        await wait_for(lambda: limit.open_from("127.0.0.1") == 2, "two admitted")
        reader, writer = await connect("127.0.0.1")
        async with asyncio.timeout(5):
            assert await reader.read() == b""  # closed at once: the address's share is used
        writer.close()
        assert (limit.open, limit.refused, limit.refused_per_address) == (2, 0, 1)
        other_reader, other_writer = await connect("127.0.0.2")  # another address: in
        other_writer.write(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        async with asyncio.timeout(5):
            assert (await other_reader.read()).startswith(b"HTTP/1.1 200")
        other_writer.close()
        for _, idle_writer in mine:
            idle_writer.close()
        await wait_for(lambda: limit.open == 0, "every slot released")
        assert limit.open_from("127.0.0.1") == 0
        assert (await fetch(port, "/healthz")).status == 200  # its share is back
    finally:
        server.close()
        await server.wait_closed()


def test_the_rate_limited_log_warns_once_per_interval(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG, logger="test.rate")
    now = [100.0]
    log = RateLimitedLog(logging.getLogger("test.rate"), 10.0, clock=lambda: now[0])
    for at in (100.0, 101.0, 109.9, 110.0, 111.0):
        now[0] = at
        log.log("refused %s", at)
    assert [(r.levelno, r.getMessage()) for r in caplog.records] == [
        (logging.WARNING, "refused 100.0"),
        (logging.DEBUG, "refused 101.0"),
        (logging.DEBUG, "refused 109.9"),
        (logging.WARNING, "refused 110.0 (2 more since the last warning, at DEBUG)"),
        (logging.DEBUG, "refused 111.0"),
    ]


# -- fair share: at the cap, a lighter address's newcomer takes the heaviest's idlest ------


class _Door:
    """A listener's admissions without sockets: each connection a slot and a closed flag."""

    def __init__(self, cap: int, per_address: int | None = None) -> None:
        self.limit = ConnectionLimit("test", cap, logging.getLogger("test.fair"), per_address)
        self.closed: list[str] = []

    def connect(self, address: str, name: str) -> Slot | None:
        if not self.limit.admit(address):
            return None
        return self.limit.hold(address, lambda: self.closed.append(name))


def test_a_newcomer_at_the_cap_closes_the_idlest_connection_of_the_heaviest_address(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="test.fair")
    door = _Door(8, per_address=4)
    slots = {f"a{i}": door.connect("10.0.0.1", f"a{i}") for i in range(4)}
    slots |= {f"b{i}": door.connect("10.0.0.2", f"b{i}") for i in range(3)}
    slots["c0"] = door.connect("10.0.0.3", "c0")
    assert door.limit.open == 8
    a0, a1 = slots["a0"], slots["a1"]
    assert a0 is not None
    assert a1 is not None
    a0.busy()  # a request in progress: never closed for a newcomer
    a1.active()  # active since: the last of its address to go
    assert door.connect("10.0.0.4", "d0") is not None  # a fresh address: in
    assert door.closed == ["a2"]  # a0 busy, a1 active last: a2 idle the longest
    assert (door.limit.open, door.limit.evicted, door.limit.refused) == (8, 1, 0)
    assert door.limit.open_from("10.0.0.1") == 3
    victim = slots["a2"]
    assert victim is not None
    assert victim.released
    victim.release()  # its connection_lost, a loop turn later: not released twice
    assert (door.limit.open, door.limit.open_from("10.0.0.1")) == (8, 3)
    assert door.connect("10.0.0.5", "e0") is not None  # a and b tie at the top, 3 each
    assert door.closed[1] in {"a3", "b0"}  # one of them gives way (its idlest), never c, d
    assert door.limit.open_from("10.0.0.3") == door.limit.open_from("10.0.0.4") == 1
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warned == ["test: 8 connections open (max_connections): closed the idlest of "
                      "10.0.0.1's 4 for 10.0.0.4"]  # fmt: skip


def test_the_heaviest_address_itself_and_equal_shares_are_refused_as_before() -> None:
    door = _Door(5, per_address=5)
    for i in range(3):
        door.connect("10.0.0.1", f"a{i}")
    door.connect("10.0.0.2", "b0")
    door.connect("10.0.0.2", "b1")
    assert door.connect("10.0.0.1", "a3") is None  # the top address itself
    assert door.connect("10.0.0.2", "b2") is None  # 3 once in, the top 3 less one: a swap
    assert door.closed == []
    assert (door.limit.refused, door.limit.evicted) == (2, 0)
    even = _Door(4)  # two addresses, two each: every address holds the same share
    for i in range(4):
        even.connect(f"10.0.0.{i % 2}", f"x{i}")
    assert even.connect("10.0.0.0", "x4") is None
    assert even.connect("10.0.0.1", "x5") is None
    assert even.connect("10.0.0.9", "y0") is not None  # but a fresh address gets in
    assert (even.limit.refused, even.limit.evicted, len(even.closed)) == (2, 1, 1)


def test_a_top_address_with_every_connection_busy_or_unmade_gives_nothing_up() -> None:
    door = _Door(4, per_address=4)
    busy = [door.connect("10.0.0.1", f"a{i}") for i in range(2)]
    for slot in busy:
        assert slot is not None
        slot.busy()
    assert door.limit.admit("10.0.0.1")  # admitted, its connection not made yet (TLS)
    assert door.connect("10.0.0.2", "b0") is not None
    assert door.connect("10.0.0.3", "c0") is None  # nothing of 10.0.0.1's to close
    assert (door.closed, door.limit.refused) == ([], 1)
    first = busy[0]
    assert first is not None
    first.active()  # its request ended: now it may go
    assert door.connect("10.0.0.3", "c0") is not None
    assert door.closed == ["a0"]


def test_the_heaviest_address_is_tracked_as_connections_come_and_go() -> None:
    door = _Door(6, per_address=6)
    a = [door.connect("10.0.0.1", f"a{i}") for i in range(3)]
    b = [door.connect("10.0.0.2", f"b{i}") for i in range(3)]
    for slot in a[:2]:
        assert slot is not None
        slot.release()  # 10.0.0.1 holds 1, 10.0.0.2 3: the top is b
    door.connect("10.0.0.3", "c0")
    door.connect("10.0.0.3", "c1")
    assert door.limit.open == 6
    assert door.connect("10.0.0.1", "a3") is not None  # 1 + 1 < 3
    assert door.closed == ["b0"]
    for slot in b:
        assert slot is not None
        slot.release()  # b0 released already: once only
    assert (door.limit.open, door.limit.open_from("10.0.0.2")) == (4, 0)
    for name in ("d0", "d1"):
        assert door.connect("10.0.0.4", name) is not None  # under the cap: no eviction
    assert door.connect("10.0.0.4", "d2") is None  # 2, 2, 2 held: a tie
    assert door.connect("10.0.0.5", "e0") is not None  # but a fresh address gets in
    assert door.limit.evicted == 2


def test_the_evictions_are_a_metric_of_the_listener() -> None:
    door = _Door(2, per_address=2)
    door.connect("10.0.0.1", "a0")
    door.connect("10.0.0.1", "a1")
    door.connect("10.0.0.2", "b0")
    families = {family.name: family for family in listener_families("sj300_test", door.limit)}
    assert families["sj300_test_connections_evicted"].samples[0].value == 1


async def test_two_full_addresses_cannot_lock_a_third_out_of_http() -> None:
    limit = ConnectionLimit("http", 4, logging.getLogger("test.http"))  # 2 per address
    server = await serve_http(Endpoint("127.0.0.1", 0), make_registry(list), list, limit=limit)

    async def connect(source: str) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        return await asyncio.open_connection("127.0.0.1", server.port, local_addr=(source, 0))

    try:
        held = [await connect(f"127.0.0.{2 + i % 2}") for i in range(4)]
        await wait_for(lambda: limit.open == 4, "every slot held")
        reader, writer = await connect("127.0.0.4")
        writer.write(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        async with asyncio.timeout(5):
            assert (await reader.read()).startswith(b"HTTP/1.1 200")
        writer.close()
        assert (limit.evicted, limit.refused) == (1, 0)
        # The idlest connection of an address at the top was closed: the two tie, and
        # which one goes is the limit's choice (a fourth clean run saw 127.0.0.3's).
        reads = [asyncio.ensure_future(held_reader.read()) for held_reader, _ in held]
        done, pending = await asyncio.wait(reads, timeout=5, return_when="FIRST_COMPLETED")
        for read in pending:
            read.cancel()
        assert [read.result() for read in done] == [b""]
        for _, held_writer in held:
            held_writer.close()
        await wait_for(lambda: limit.open == 0, "every slot released")
    finally:
        server.close()
        await server.wait_closed()
