"""RAM versus EEPROM: 07 writes RAM, 0A stores, a power cycle forgets what was not stored."""

from __future__ import annotations

import pytest

from sj300_async import LocalProtocolError
from sj300_async.simulator.sj300 import (
    DEFAULT_EEPROM_WRITE_S,
    Country,
    SimulatedBus,
    SimulatedDrive,
)
from sj300_async.simulator.sj300._parameters_table import factory_table, value_error
from sj300_async.sj300 import parameter_info

from .simwire import ack, ack_data, exchange, nak, request


def read(bus: SimulatedBus, code: bytes, now: float = 0.0) -> bytes:
    [reply] = exchange(bus, request(b"01", b"06", code), now)
    return reply


def test_unstored_write_is_lost_in_a_power_cycle() -> None:
    bus = SimulatedBus(nodes=[1])
    assert exchange(bus, request(b"01", b"07", b"F00200001000")) == [ack(b"01")]
    assert read(bus, b"F002") == ack_data(b"01", b"00001000")
    bus.drives[1].power_cycle(now=1.0)
    assert read(bus, b"F002", 1.0) == ack_data(b"01", b"00003000")


def test_stored_write_survives_a_power_cycle() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"07", b"F00200001000"))
    assert exchange(bus, request(b"01", b"0A")) == [ack(b"01")]
    exchange(bus, request(b"01", b"07", b"F00300002000"))  # after the store: RAM only
    bus.drives[1].power_cycle(now=1.0)
    assert read(bus, b"F002", 1.0) == ack_data(b"01", b"00001000")
    assert read(bus, b"F003", 1.0) == ack_data(b"01", b"00003000")


def test_setpoint_and_run_command_are_lost_in_a_power_cycle() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"01", b"001000"))
    exchange(bus, request(b"01", b"00", b"1"))
    bus.drives[1].power_cycle(now=10.0)
    assert read(bus, b"F001", 10.0) == ack_data(b"01", b"00000000")
    [reply] = exchange(bus, request(b"01", b"04"), 10.0)
    assert reply[3:9] == b"020001"


def test_storing_one_parameter_from_outside_stores_only_that_one() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"01", b"001000"))  # F001 in RAM
    bus.drives[1].set_wait_ms(20)  # C078 in RAM and EEPROM
    bus.drives[1].power_cycle(now=1.0)
    assert read(bus, b"C078", 1.0) == ack_data(b"01", b"00000020")
    assert read(bus, b"F001", 1.0) == ack_data(b"01", b"00000000")


def test_09_says_not_allowed_while_an_eeprom_write_is_in_progress() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"0A"), 5.0)
    assert exchange(bus, request(b"01", b"09"), 5.0) == [ack_data(b"01", b"00")]
    done = 5.0 + DEFAULT_EEPROM_WRITE_S
    assert exchange(bus, request(b"01", b"09"), done) == [ack_data(b"01", b"01")]


def test_broadcast_store_stores_every_drive() -> None:
    bus = SimulatedBus(nodes=[1, 2])
    exchange(bus, request(b"FF", b"07", b"C07800000020"))
    assert exchange(bus, request(b"FF", b"0A")) == []
    for drive in bus.drives.values():
        drive.power_cycle(now=1.0)
        assert drive.parameters["C078"] == 20


def test_initialization_is_persistent() -> None:
    bus = SimulatedBus(nodes=[1])
    exchange(bus, request(b"01", b"07", b"B08400000001"))
    exchange(bus, request(b"01", b"08"))
    bus.drives[1].power_cycle(now=1.0)
    # true factory values: serial run refused
    assert exchange(bus, request(b"01", b"00", b"1"), 1.0) == [nak(b"01", b"13")]


def test_initialization_keeps_the_node_and_line_settings() -> None:
    bus = SimulatedBus(nodes=[7])
    drive = bus.drives[7]
    drive.set_parameter("C071", 6)
    drive.set_parameter("C078", 100)
    drive.set_parameter("B084", 1)
    exchange(bus, request(b"07", b"08"))
    assert drive.parameters["C072"] == 7
    assert drive.parameters["C071"] == 6
    assert drive.parameters["C078"] == 0  # not a line setting: back to factory


def test_node_address_cannot_be_changed() -> None:
    bus = SimulatedBus(nodes=[3])
    assert exchange(bus, request(b"03", b"07", b"C07200000004")) == [nak(b"03", b"16")]
    assert exchange(bus, request(b"03", b"07", b"C07200000003")) == [ack(b"03")]


def test_set_parameter_outside_the_line() -> None:
    drive = SimulatedDrive(1)
    drive.set_wait_ms(250)
    assert drive.parameters["C078"] == drive.stored_parameters["C078"] == 250
    assert drive.reply_delay_s == pytest.approx(0.25 + drive.processing_s)
    with pytest.raises(LocalProtocolError):
        drive.set_wait_ms(1001)
    with pytest.raises(LocalProtocolError):
        drive.set_parameter("A999", 1)


@pytest.mark.parametrize("country", list(Country))
def test_every_factory_value_is_one_the_drive_accepts(country: Country) -> None:
    table = factory_table(country, 5)
    for code, raw in table.items():
        assert value_error(code, raw, table) is None, (code, raw)


def test_the_drive_knows_every_catalogued_parameter() -> None:
    from sj300_async.sj300 import PARAMETERS

    table = factory_table(Country.EUROPE, 1)
    assert set(PARAMETERS) == set(table)  # the catalogue is the one list of codes
    # and the catalogue's scale matches the values we chose (50.0 Hz, 30.00 s)
    assert parameter_info("A004").from_raw(table["A004"]) == 50.0
    assert parameter_info("F002").from_raw(table["F002"]) == 30.0


def test_drive_node_must_be_1_to_32() -> None:
    with pytest.raises(LocalProtocolError):
        SimulatedDrive(0)
    with pytest.raises(LocalProtocolError):
        SimulatedDrive(33)
    with pytest.raises(LocalProtocolError):
        SimulatedBus(nodes=[1, 1])
