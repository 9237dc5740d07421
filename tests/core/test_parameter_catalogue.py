"""The SJ300 function-code table (``sj300_async.sj300.PARAMETERS``): its extent and its rules."""

from __future__ import annotations

import pytest

from sj300_async import InputTerminal
from sj300_async.sj300 import PARAMETERS, ParameterInfo, parameter_info
from sj300_async.sj300._parameters import DEFAULT_SCALE, GROUPS, RAW_VALUE_MAX

#: Codes per group, as the module docstring's table has them.
GROUP_SIZES = {"F": 8, "A": 107, "B": 79, "C": 68, "H": 43, "P": 30}

#: Entries the seeds and the earlier catalogue fixed: (name, scale, unit, minimum, maximum).
PINNED = {
    "F001": ("output frequency setting", 100, "Hz", 0.0, 400.0),
    "F002": ("acceleration time 1", 100, "s", 0.01, 3600.0),
    "A003": ("base frequency", 10, "Hz", 30.0, 400.0),
    "A004": ("maximum frequency", 10, "Hz", 30.0, 400.0),
    "A082": ("AVR voltage", 1, "V", 200, 480),
    "B012": ("electronic thermal level", 10, "A", 0.0, 9999.9),
    "C078": ("communication wait time", 1, "ms", 0, 1000),
    "H003": ("motor capacity (code)", 1, "", 0, 21),
}


def test_every_group_of_the_function_list_is_there() -> None:
    assert {letter: len(codes) for letter, codes in GROUPS.items()} == GROUP_SIZES
    assert len(PARAMETERS) == sum(GROUP_SIZES.values())
    for letter, codes in GROUPS.items():
        assert all(p.code.startswith(letter) for p in codes), letter


def test_pinned_entries() -> None:
    for code, entry in PINNED.items():
        info = PARAMETERS[code]
        assert (info.name, info.scale, info.unit, info.minimum, info.maximum) == entry, code


def test_second_and_third_motor_copies_follow_the_first() -> None:
    codes = list(PARAMETERS)
    assert codes[codes.index("F002") : codes.index("F002") + 3] == ["F002", "F202", "F302"]
    assert PARAMETERS["A292"].name == "acceleration time 2, 2nd motor"
    assert PARAMETERS["A392"].scale == PARAMETERS["A092"].scale == 100
    assert PARAMETERS["H206"].name == "motor stabilization constant, 2nd motor"


@pytest.mark.parametrize("info", list(PARAMETERS.values()), ids=list(PARAMETERS))
def test_entry_is_consistent(info: ParameterInfo) -> None:
    assert parameter_info(info.code) is info
    assert info.scale in (1, 10, 100, 1000)
    assert 0 <= info.minimum <= info.maximum  # the eight digits carry no sign
    assert info.to_raw(info.maximum) <= RAW_VALUE_MAX
    assert info.name
    assert info.name != "unknown parameter"
    if info.default is not None:
        assert info.minimum <= info.default <= info.maximum
        assert info.from_raw(info.to_raw(info.default)) == pytest.approx(info.default)


def test_factory_terminal_functions_are_command_02_bit_numbers() -> None:
    factory = (
        InputTerminal.RS,
        InputTerminal.AT,
        InputTerminal.JG,
        InputTerminal.FRS,
        InputTerminal.TWO_CH,
        InputTerminal.CF2,
        InputTerminal.CF1,
        InputTerminal.RV,
    )
    for i, terminal in enumerate(factory, 1):
        assert PARAMETERS[f"C00{i}"].default == terminal.bit_length() - 1


@pytest.mark.parametrize("code", ["A999", "P050", "H099", "C010", "F005"])
def test_a_code_outside_the_table_reads_at_the_default_scale(code: str) -> None:
    assert code not in PARAMETERS
    info = parameter_info(code)
    assert (info.scale, info.unit, info.name) == (DEFAULT_SCALE, "", "unknown parameter")
