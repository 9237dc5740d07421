"""The listeners' limits (gateway/_listeners.py): configuration, the HTTP cap, the log."""

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


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("max_connections = 0", "test.toml:3: modbus.max_connections: must be >= 1, got 0"),
        ("max_connections = 1.5", "test.toml:3: modbus.max_connections: expected an integer"),
        ("idle_timeout_s = 0", "test.toml:3: modbus.idle_timeout_s: must be > 0, got 0"),
        ('idle_timeout_s = "1"', "test.toml:3: modbus.idle_timeout_s: expected a number"),
    ],
)
def test_a_bad_limit_names_file_line_and_key(line: str, message: str) -> None:
    with pytest.raises(GatewayConfigError) as raised:
        parse_config(_config(f'[modbus]\nlisten = "127.0.0.1:1502"\n{line}\n'), "test.toml")
    assert str(raised.value).startswith(message), str(raised.value)


async def test_the_http_listener_refuses_past_its_cap() -> None:
    limit = ConnectionLimit("http", 2, logging.getLogger("test.http"))
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
