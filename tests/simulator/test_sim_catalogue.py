"""A simulated drive knows exactly the catalogue's codes, each at its factory value."""

from __future__ import annotations

import pytest

from sj300_async.simulator.sj300 import Country, SimulatedBus
from sj300_async.simulator.sj300._parameters_table import factory_table
from sj300_async.sj300 import PARAMETERS

from .simwire import ack, ack_data, exchange, request


def test_every_catalogued_code_answers_its_factory_value() -> None:
    bus = SimulatedBus(nodes=[1], factory_defaults=True)
    table = factory_table(Country.EUROPE, 1)
    for code in PARAMETERS:
        expected = ack_data(b"01", b"%08d" % table[code])
        assert exchange(bus, request(b"01", b"06", code.encode())) == [expected], code


def test_catalogue_defaults_are_the_factory_values() -> None:
    table = factory_table(Country.USA, 3)
    for code, info in PARAMETERS.items():
        if info.default is not None and code not in ("C072", "B085"):
            assert table[code] == info.to_raw(info.default), code
    assert (table["C072"], table["B085"]) == (3, Country.USA)
    # what depends on the drive comes from the model: a 5.5 kW 400 V drive, US: 60 Hz, 460 V
    assert (table["H003"], table["B012"], table["A082"], table["A204"]) == (11, 120, 460, 600)
    assert table["H020"] == 1  # no default, 0 outside the range: the lowest raw value


@pytest.mark.parametrize("code", ["B113", "P049", "H234", "C123"])
def test_an_uncommon_code_is_written_and_read_back(code: str) -> None:
    bus = SimulatedBus(nodes=[2])
    info = PARAMETERS[code]
    raw = round(info.maximum * info.scale)
    frame = request(b"02", b"07", code.encode() + b"%08d" % raw)
    assert exchange(bus, frame) == [ack(b"02")]
    assert bus.drives[2].parameters[code] == raw
