"""Choosing FR-700 in a bus URL or in open_bus, and the dialect the options make."""

from __future__ import annotations

import pytest

import sj300_async as sj
from sj300_async import bus as sjbus
from sj300_async.bus import make_dialect
from sj300_async.fr700 import Fr700Dialect
from sj300_async.sj300._dialect import SJ300_DIALECT


def dialect_of(url: str, protocol: str | None = None) -> object:
    return make_dialect(sjbus.parse_bus_url(url), protocol)


def test_protocol_in_the_url() -> None:
    address = sjbus.parse_bus_url("tcp://10.0.0.5:4001?protocol=FR700&terminator=crlf&ack=1")
    assert address.protocol == "fr700"
    assert address.protocol_options == {"terminator": "crlf", "ack": "1"}
    dialect = make_dialect(address)
    assert isinstance(dialect, Fr700Dialect)
    assert dialect.options.terminator == b"\r\n"
    assert dialect.send_ack
    assert dialect.options.wait_field


def test_defaults_are_the_drives_factory_settings() -> None:
    dialect = dialect_of("serial:///dev/ttyUSB0?protocol=fr700")
    assert isinstance(dialect, Fr700Dialect)
    assert dialect.options.terminator == b"\r"
    assert dialect.options.wait_field
    assert not dialect.send_ack


@pytest.mark.parametrize(
    ("query", "terminator", "wait_field"),
    [("terminator=none", b"", True), ("terminator=cr&wait_field=off", b"\r", False)],
)
def test_line_options(query: str, terminator: bytes, wait_field: bool) -> None:
    dialect = dialect_of(f"sim://?protocol=fr700&{query}")
    assert isinstance(dialect, Fr700Dialect)
    assert (dialect.options.terminator, dialect.options.wait_field) == (terminator, wait_field)


def test_sj300_remains_the_default() -> None:
    assert dialect_of("tcp://h:1") is SJ300_DIALECT
    assert dialect_of("tcp://h:1?protocol=sj300") is SJ300_DIALECT
    assert dialect_of("tcp://h:1", "sj300") is SJ300_DIALECT
    assert isinstance(dialect_of("tcp://h:1", "fr700"), Fr700Dialect)


@pytest.mark.parametrize(
    ("url", "protocol", "match"),
    [
        ("tcp://h:1?protocol=modbus", None, "unknown protocol"),
        ("tcp://h:1?protocol=fr700", "sj300", "URL says"),
        ("tcp://h:1?ack=1", None, "options of protocol fr700"),
        ("tcp://h:1?protocol=fr700&terminator=lf", None, "terminator"),
        ("tcp://h:1?protocol=fr700&ack=maybe", None, "ack"),
        ("tcp://h:1", "dnp3", "unknown protocol"),
    ],
)
def test_bad_protocol_settings(url: str, protocol: str | None, match: str) -> None:
    with pytest.raises(sj.LocalProtocolError, match=match):
        dialect_of(url, protocol)


def test_sim_nodes_are_stations_0_to_31_for_fr700() -> None:
    assert sjbus.parse_bus_url("sim://?protocol=fr700&nodes=0-3,31").nodes == (0, 1, 2, 3, 31)
    assert sjbus.parse_bus_url("sim://?protocol=fr700").nodes == tuple(range(8))
    assert sjbus.parse_bus_url("sim://?protocol=fr700").description == "sim://(stations 0-7)"
    with pytest.raises(sj.LocalProtocolError, match=r"0\.\.31"):
        sjbus.parse_bus_url("sim://?protocol=fr700&nodes=32")
    with pytest.raises(sj.LocalProtocolError, match=r"1\.\.32"):
        sjbus.parse_bus_url("sim://?nodes=0")


def test_the_protocol_argument_completes_the_url() -> None:
    address = sjbus.parse_bus_url("sim://?nodes=0-1&terminator=crlf", protocol="fr700")
    assert (address.protocol, address.nodes) == ("fr700", (0, 1))
    assert sjbus.parse_bus_url("tcp://h:1?protocol=fr700", protocol="fr700").protocol == "fr700"
    with pytest.raises(sj.LocalProtocolError, match="URL says"):
        sjbus.parse_bus_url("tcp://h:1?protocol=sj300", protocol="fr700")
    with pytest.raises(sj.LocalProtocolError, match="unknown protocol"):
        sjbus.parse_bus_url("tcp://h:1", protocol="x")


def test_node_list_range_is_a_parameter() -> None:
    assert sjbus.parse_node_list("0-2", low=0, high=31) == (0, 1, 2)
    with pytest.raises(sj.LocalProtocolError):
        sjbus.parse_node_list("0-2")


async def test_dialect_argument_must_match_the_protocol() -> None:
    with pytest.raises(sj.LocalProtocolError, match="dialect"):
        async with sj.open_bus("sim://", dialect=Fr700Dialect()):
            pass
    async with sj.open_bus(
        "sim://?protocol=fr700&nodes=1", protocol="fr700", dialect=Fr700Dialect(terminator="\r\n")
    ) as bus:
        drive = bus.drive(1)
        assert isinstance(drive, sj.Fr700Drive)
        assert not (await drive.read_status()).running
        assert bus.simulator is not None
