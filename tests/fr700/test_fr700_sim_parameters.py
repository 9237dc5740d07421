"""The simulated FR-700's parameters as a backup walks them: every bank, raw bytes in and out.

What ``sj300 params`` relies on: each number 0..999 is reached through
the link-parameter extension (HFF bank, then offset H00..H63 / H80..HE3);
a number the drive lacks is NAK B in every bank; parameters the catalogue
does not name answer like the others; the bias/gain parameters answer the
half the second-parameter switch (H6C / HEC) selects; Pr.77 = 1 refuses
every parameter write but its own.
"""

from __future__ import annotations

import pytest

from sj300_async import LocalProtocolError
from sj300_async.fr700 import FR700_PARAMETERS
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.simulator.fr700._parameters import UNCATALOGUED

from .fr700wire import ack, data_reply, nak, request


def exchange(bus: Fr700SimulatedBus, raw: bytes) -> list[bytes]:
    return [t.data for t in bus.receive(raw, 0.0)]


def read(bus: Fr700SimulatedBus, number: int) -> bytes:
    """Pr.*number*'s reply at station 1: the bank selected, then the read."""
    assert exchange(bus, request(1, 0xFF, b"%02X" % (number // 100))) == [ack(1)]
    (reply,) = exchange(bus, request(1, number % 100))
    return reply


def write(bus: Fr700SimulatedBus, number: int, raw: int) -> bytes:
    """Pr.*number* = *raw* at station 1: the bank selected, then the write."""
    assert exchange(bus, request(1, 0xFF, b"%02X" % (number // 100))) == [ack(1)]
    (reply,) = exchange(bus, request(1, 0x80 + number % 100, b"%04X" % raw))
    return reply


@pytest.fixture
def bus() -> Fr700SimulatedBus:
    return Fr700SimulatedBus(stations=[1])


def test_a_walk_of_every_bank_finds_exactly_the_drives_parameters(
    bus: Fr700SimulatedBus,
) -> None:
    found = {}
    for number in range(1000):
        reply = read(bus, number)
        if reply != nak(1, b"B"):
            found[number] = int(reply[3:7], 16)
    assert found == dict(bus.drives[1].parameters)
    assert set(found) == set(FR700_PARAMETERS) | set(UNCATALOGUED)
    assert found[117] == 1  # the station number
    assert (found[18], found[903]) == (12000, 6000)  # uncatalogued: raw integers


def test_the_second_parameter_switch_selects_the_half_of_a_bias_gain_parameter(
    bus: Fr700SimulatedBus,
) -> None:
    assert read(bus, 903) == data_reply(1, b"1770")  # switch H00: 60.00 Hz
    assert exchange(bus, request(1, 0xEC, b"01")) == [ack(1)]
    assert read(bus, 903) == data_reply(1, b"03E8")  # switch H01: 100.0 %
    assert read(bus, 904) == data_reply(1, b"00C8")  # 20.0 % (4 mA)
    assert read(bus, 7) == data_reply(1, b"0032")  # other parameters: one value
    assert write(bus, 903, 950) == ack(1)
    assert write(bus, 903, 3001) == nak(1, b"C")  # above 300 %
    assert exchange(bus, request(1, 0xEC, b"00")) == [ack(1)]
    assert read(bus, 903) == data_reply(1, b"1770")  # the frequency is untouched
    drive = bus.drives[1]
    assert (drive.parameters[903], drive.bias_gain_analog[903]) == (6000, 950)
    assert exchange(bus, request(1, 0xFC, b"9696")) == [ack(1)]  # parameter clear
    assert drive.bias_gain_analog[903] == 1000


def test_pr77_1_refuses_every_parameter_write_but_its_own(bus: Fr700SimulatedBus) -> None:
    assert write(bus, 77, 1) == ack(1)
    assert write(bus, 7, 100) == nak(1, b"A")
    assert write(bus, 18, 6000) == nak(1, b"A")
    assert write(bus, 200, 0) == nak(1, b"B")  # no such parameter: B before A
    assert read(bus, 7) == data_reply(1, b"0032")  # reads are unaffected
    assert exchange(bus, request(1, 0xED, b"0BB8")) == [ack(1)]  # so is the set frequency
    assert write(bus, 77, 0) == ack(1)
    assert write(bus, 7, 100) == ack(1)
    assert bus.drives[1].parameters[7] == 100


def test_set_parameter_is_the_operation_panel(bus: Fr700SimulatedBus) -> None:
    drive = bus.drives[1]
    drive.set_parameter(77, 1)  # whatever Pr.77 says, as at the panel
    drive.set_parameter(7, 125)
    drive.set_parameter(13, 70)  # uncatalogued: any four-digit value
    assert read(bus, 7) == data_reply(1, b"007D")
    assert read(bus, 13) == data_reply(1, b"0046")
    assert exchange(bus, request(1, 0xEC, b"01")) == [ack(1)]
    drive.set_parameter(902, 55)  # the half the switch selects
    assert (drive.parameters[902], drive.bias_gain_analog[902]) == (0, 55)
    for number, raw in ((14, 0), (7, 36001), (902, 3001)):
        with pytest.raises(LocalProtocolError):
            drive.set_parameter(number, raw)
