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
    parse_config,
)
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
