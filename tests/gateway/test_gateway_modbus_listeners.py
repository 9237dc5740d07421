"""Modbus listeners of their own for groups of lines, each with its own unit ids (issue 30).

A Modbus server addresses at most 247 units; a plant of more drives gives
groups of lines listeners of their own (``[[modbus.listeners]]``). Unit ids
are unique within a listener, not across them, and ``[modbus] listen``
serves the lines no listener names.
"""

from __future__ import annotations

import textwrap

import pytest
from pymodbus.client import AsyncModbusTcpClient
from waiting import wait_for

from sj300_async.gateway import Gateway, GatewayConfigError, parse_config
from sj300_async.gateway.modbus import ModbusConfig
from sj300_async.gateway.modbus._northbound import ModbusNorthbound

#: Two lines whose drives have the same unit ids: 1 and 2 (an SJ300 line, an FR-700 one).
TWO_LINES = """
    [[lines]]
    name = "sj"
    url = "sim://?nodes=1-2"
    nodes = "1-2"
    interval_s = 0.05
    [[lines]]
    name = "fr"
    url = "sim://?protocol=fr700&nodes=1-2"
    protocol = "fr700"
    nodes = "1-2"
    unit_offset = 0
    interval_s = 0.05
    """


def parse(text: str) -> ModbusConfig:
    config = parse_config(textwrap.dedent(text), "gateway.toml").northbounds["modbus"]
    assert isinstance(config, ModbusConfig)
    return config


def refusal(text: str) -> str:
    with pytest.raises(GatewayConfigError) as caught:
        parse_config(textwrap.dedent(text), "gateway.toml")
    return str(caught.value)


def test_each_listener_has_unit_ids_of_its_own() -> None:
    config = parse(
        """
        [[modbus.listeners]]
        listen = "127.0.0.1:5021"
        lines = ["sj"]
        [[modbus.listeners]]
        listen = "127.0.0.1:5022"
        lines = ["fr"]
        """
        + TWO_LINES
    )
    assert config.listen is None  # every line has a listener
    assert [sorted(listener.lines) for listener in config.listeners] == [["sj"], ["fr"]]


def test_the_same_unit_ids_on_one_listener_are_refused_naming_it() -> None:
    message = refusal(
        """
        [[modbus.listeners]]
        listen = "127.0.0.1:5021"
        lines = ["sj", "fr"]
        """
        + TWO_LINES
    )
    assert message == (
        "gateway.toml:16: lines[1].unit_offset: Modbus unit 1 on modbus.listeners[0] "
        "(station 1) is also line sj's (node 1): set unit_offset on one of them"
    )


@pytest.mark.parametrize(
    ("section", "expected"),
    [
        (
            '[[modbus.listeners]]\nlisten = "127.0.0.1:5021"\nlines = ["sj", "nowhere"]\n',
            "modbus.listeners[0].lines: no line named 'nowhere'",
        ),
        (
            '[[modbus.listeners]]\nlisten = "127.0.0.1:5021"\nlines = []\n',
            "modbus.listeners[0].lines: name the lines this listener serves",
        ),
        (
            '[[modbus.listeners]]\nlisten = "127.0.0.1:5021"\nlines = ["sj"]\n'
            '[[modbus.listeners]]\nlisten = "127.0.0.1:5022"\nlines = ["sj"]\n',
            "modbus.listeners[1].lines: line 'sj' is also modbus.listeners[0]'s",
        ),
        (
            '[modbus]\nlisten = "127.0.0.1:5021"\n'
            '[[modbus.listeners]]\nlisten = "127.0.0.1:5021"\nlines = ["fr"]\n',
            "modbus.listeners[0].listen: modbus.listen already listens on 127.0.0.1:5021",
        ),
        ("[modbus]\n", "modbus.listen: missing required key 'listen'"),
    ],
)
def test_a_bad_listener_is_one_line_naming_the_key(section: str, expected: str) -> None:
    message = refusal(section + TWO_LINES)
    assert expected in message
    assert "\n" not in message


async def _protocol_of(port: int, unit: int) -> int:
    """Register 2 of *unit* on the server at *port*: 1 SJ300, 2 FR-700."""
    client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=5, retries=0)
    assert await client.connect()
    try:
        response = await client.read_holding_registers(2, count=1, device_id=unit)
        assert not response.isError(), response
        return int(response.registers[0])
    finally:
        client.close()


async def test_the_same_unit_on_two_listeners_is_two_drives() -> None:
    text = (
        """
        [modbus]
        listen = "127.0.0.1:0"
        [[modbus.listeners]]
        listen = "127.0.0.1:0"
        lines = ["fr"]
        """
        + TWO_LINES
    )
    async with Gateway(parse_config(textwrap.dedent(text), "gateway.toml")) as gateway:
        northbound = gateway.northbounds["modbus"]
        assert isinstance(northbound, ModbusNorthbound)
        await wait_for(lambda: all(d.snapshot.available for d in gateway.drives), "samples")
        (_, first), (_, second) = northbound.servers
        assert sorted(first.units) == sorted(second.units) == [1, 2]
        assert [await _protocol_of(first.port, 1), await _protocol_of(second.port, 1)] == [1, 2]
        announced = str(northbound.announce()).splitlines()
        assert announced == [
            f"modbus on 127.0.0.1:{first.port}",
            f"modbus on 127.0.0.1:{second.port} (modbus.listeners[0]: fr)",
        ]
        assert first.limit is second.limit  # max_connections is for them all
