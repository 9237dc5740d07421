"""Trip codes: the reference's commonly published SJ300 E-codes, with their meanings, in the codec.

docs: sj300.md, "05 — trip history" ("SJ300 error codes commonly published").
"""

from __future__ import annotations

import pytest

import sj300_async.simulator.sj300 as simulator
from sj300_async.sj300 import TripCode, TripRecord, TripStatusB, TripStatusC
from sj300_async.sj300._codes import StatusA
from sj300_async.wire import TolerantIntEnum

#: The reference's list, verbatim in meaning.
REFERENCE = {
    1: "over-current at constant speed",
    2: "over-current while decelerating",
    3: "over-current while accelerating",
    4: "over-current (other)",
    5: "overload",
    6: "braking resistor overload",
    7: "over-voltage",
    8: "EEPROM error",
    9: "under-voltage",
    10: "CT error",
    11: "CPU error",
    12: "external trip",
    13: "USP (unattended start protection)",
    14: "ground fault",
    15: "input over-voltage",
    16: "momentary power failure",
    21: "thermal trip",
    23: "gate array error",
    24: "phase loss",
    30: "IGBT error",
    35: "thermistor",
    36: "brake error",
    **dict.fromkeys(range(60, 70), "option card error"),
}


def test_every_published_code_has_its_meaning() -> None:
    assert {code.value: code.description for code in TripCode} == REFERENCE
    assert all(code.known for code in TripCode)


@pytest.mark.parametrize(("value", "text"), [(1, "E01"), (7, "E07"), (21, "E21"), (69, "E69")])
def test_error_code_is_the_display_text(value: int, text: str) -> None:
    assert TripCode(value).error_code == text


@pytest.mark.parametrize("value", [0, 17, 99, 12345678])
def test_unknown_codes_are_kept_as_numbers(value: int) -> None:
    code = TripCode(value)
    assert isinstance(code, TolerantIntEnum)
    assert code == value
    assert not code.known
    assert code.name == f"UNKNOWN_{value}"
    assert code.description == "unknown trip"


def test_the_simulator_uses_the_codecs_enum() -> None:
    assert simulator.TripCode is TripCode
    assert TripCode(12) is TripCode.EXTERNAL  # what EXT rising records


def test_a_trip_record_names_its_code_and_keeps_the_number() -> None:
    record = TripRecord(
        trip_factor=7,
        status_a=StatusA.RUNNING,
        status_b=TripStatusB.OVER_VOLTAGE,
        status_c=TripStatusC.DECELERATING,
        output_frequency_hz=50.0,
        run_time_h=1,
        output_current_a=1.0,
        output_voltage_v=200.0,
        power_on_time_h=2,
    )
    assert record.trip_code is TripCode.OVER_VOLTAGE
    assert record.trip_code.description == "over-voltage"
    assert type(record.trip_factor) is int
    assert record.error_code == "E07"
