"""The FR-700 parameter catalogue and the drive's parameter methods in units.

The catalogue (:mod:`sj300_async.fr700._parameters`) scales each parameter by
its setting increment; ``read_parameter`` / ``write_parameter`` use it,
``read_parameter_raw`` / ``write_parameter_raw`` carry the integer. Every
refusal happens before anything reaches the wire.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

import pytest
from hypothesis import given
from hypothesis import strategies as st

import sj300_async as sj
from sj300_async.bus._trace import TraceRecord
from sj300_async.fr700 import (
    FR700_PARAMETERS,
    PARAMETER_RAW_MAX,
    Fr700Drive,
    Fr700NakCode,
    Fr700OperationMode,
    Fr700ParameterInfo,
    fr700_parameter_info,
    parameter_number,
)
from sj300_async.simulator.fr700 import PARAMETERS as SIM_PARAMETERS
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.simulator.fr700._parameters import UNCATALOGUED

URL = "sim://?protocol=fr700&nodes=0-1"
INFOS = list(FR700_PARAMETERS.values())
IDS = [f"Pr.{info.number}" for info in INFOS]

# -- the catalogue ----------------------------------------------------------------------


def test_the_catalogue_lists_the_reference_parameters() -> None:
    # the waiting time and CR/LF selections the reference names, station, maximum frequency
    assert {1, 7, 117, 123, 124, 337, 341} <= set(FR700_PARAMETERS)
    assert len(FR700_PARAMETERS) == 27
    for number, info in FR700_PARAMETERS.items():
        assert info.number == number
        assert info.name
        assert info.decimals in (0, 1, 2)
        assert 0 <= info.raw_minimum <= info.raw_maximum <= PARAMETER_RAW_MAX
        assert all(0 <= s <= PARAMETER_RAW_MAX for s in info.special)


def test_worked_examples() -> None:
    pr7 = fr700_parameter_info(7)
    assert (pr7.name, pr7.unit, pr7.increment) == ("acceleration time", "s", 0.1)
    assert pr7.from_raw(50) == 5.0
    assert pr7.to_raw(5.0) == 50
    pr1 = fr700_parameter_info("Pr.1")
    assert (pr1.unit, pr1.increment, pr1.scale) == ("Hz", 0.01, 100)
    assert pr1.from_raw(12000) == 120.0
    assert pr1.to_raw(60.01) == 6001
    assert fr700_parameter_info("pr 123").to_raw(150) == 150
    assert fr700_parameter_info(122).from_raw(9999) == 9999.0  # "no check", not 999.9 s
    assert fr700_parameter_info(122).to_raw(9999) == 9999
    assert fr700_parameter_info(122).to_raw(999.8) == 9998
    assert fr700_parameter_info(19).from_raw(8888) == 8888.0


@pytest.mark.parametrize("info", INFOS, ids=IDS)
def test_every_raw_value_round_trips(info: Fr700ParameterInfo) -> None:
    for raw in range(info.raw_minimum, info.raw_maximum + 1):
        if raw in info.special:
            continue
        value = info.from_raw(raw)
        assert info.minimum <= value <= info.maximum
        assert info.to_raw(value) == raw
    for raw in info.special:
        assert info.to_raw(info.from_raw(raw)) == raw


@pytest.mark.parametrize("info", INFOS, ids=IDS)
def test_the_ends_of_the_range_and_one_increment_beyond(info: Fr700ParameterInfo) -> None:
    assert info.to_raw(info.minimum) == info.raw_minimum
    assert info.to_raw(info.maximum) == info.raw_maximum
    for outside in (info.minimum - info.increment, info.maximum + info.increment):
        if round(outside * info.scale) in info.special:
            continue
        with pytest.raises(sj.LocalProtocolError, match="must be within"):
            info.to_raw(outside)


@given(data=st.data())
def test_any_value_in_range_is_sent_exactly_or_refused(data: st.DataObject) -> None:
    info = data.draw(st.sampled_from(INFOS))
    value = data.draw(st.floats(info.minimum, info.maximum))
    exact = value * info.scale
    if abs(exact - round(exact)) > 1e-9 * max(1.0, exact) or round(exact) in info.special:
        with pytest.raises(sj.LocalProtocolError, match=r"steps of|special setting"):
            info.to_raw(value)
        return
    raw = info.to_raw(value)
    assert raw == round(exact)
    assert info.from_raw(raw) == pytest.approx(value, rel=1e-9, abs=1e-9)


@given(data=st.data())
def test_a_value_on_the_increment_grid_round_trips(data: st.DataObject) -> None:
    info = data.draw(st.sampled_from(INFOS))
    raw = data.draw(st.integers(info.raw_minimum, info.raw_maximum))
    value = raw / info.scale  # what a user types: 12.34, not 1234 * 0.01
    if raw in info.special:
        with pytest.raises(sj.LocalProtocolError, match="special setting"):
            info.to_raw(value)
    else:
        assert info.to_raw(value) == raw


BAD_VALUES: list[tuple[int, object, str]] = [
    (7, -0.1, "must be within"),
    (7, 3600.1, "must be within"),
    (7, 0.05, "steps of 0.1 s"),
    (1, 60.001, "steps of 0.01 Hz"),
    (1, 120.01, "must be within"),
    (123, 9998, "must be within"),  # 9999 only: the special setting
    (19, 888.8, "special setting 8888"),
    (117, 32, "must be within"),
    (7, math.nan, "needs a number"),
    (7, math.inf, "must be within"),
    (7, True, "needs a number"),
    (7, "5", "needs a number"),
    (7, None, "needs a number"),
]


@pytest.mark.parametrize(("number", "value", "match"), BAD_VALUES)
def test_to_raw_refuses(number: int, value: object, match: str) -> None:
    with pytest.raises(sj.LocalProtocolError, match=match) as info:
        fr700_parameter_info(number).to_raw(value)  # type: ignore[arg-type]
    assert isinstance(info.value, ValueError)


def test_unknown_and_bad_numbers_are_refused() -> None:
    with pytest.raises(sj.LocalProtocolError, match="read_parameter_raw"):
        fr700_parameter_info(44)
    for bad in (1000, -1, "Pr.x", "7.5"):
        with pytest.raises(sj.LocalProtocolError):
            fr700_parameter_info(bad)
    assert parameter_number("Pr.340") == 340
    assert parameter_number(" pr.7 ") == 7


def test_the_simulator_takes_its_ranges_from_the_catalogue() -> None:
    # and has a few parameters the catalogue does not name, as a real drive has hundreds
    assert set(SIM_PARAMETERS) == set(FR700_PARAMETERS) | set(UNCATALOGUED)
    assert not set(UNCATALOGUED) & set(FR700_PARAMETERS)
    for number in UNCATALOGUED:
        assert SIM_PARAMETERS[number].accepts(0xFFFF)  # their ranges are not modelled
    for number, info in FR700_PARAMETERS.items():
        spec = SIM_PARAMETERS[number]
        assert (spec.low, spec.high, spec.extra) == (
            info.raw_minimum,
            info.raw_maximum,
            frozenset(info.special),
        )
        assert spec.accepts(spec.factory)
        assert info.accepts_raw(spec.factory)


# -- the drive, against the simulator ------------------------------------------------------


@asynccontextmanager
async def traced_bus() -> AsyncIterator[tuple[sj.Bus[Fr700Drive, None], list[bytes]]]:
    """An FR-700 bus on the simulator and the list of every frame it sends."""
    sent: list[bytes] = []

    def hook(record: TraceRecord) -> None:
        if record.direction == "tx":
            sent.append(record.data)

    async with sj.open_bus(URL, protocol="fr700", timeout=0.2) as bus:
        bus.trace = hook
        yield bus, sent


def simulator(bus: sj.Bus[Fr700Drive, None]) -> Fr700SimulatedBus:
    sim = bus.simulator
    assert isinstance(sim, Fr700SimulatedBus)
    return sim


async def test_read_and_write_in_units() -> None:
    async with traced_bus() as (bus, _sent):
        drive = bus.drive(1)
        params = simulator(bus).drives[1].parameters
        assert await drive.read_parameter(7) == 5.0  # factory raw 50
        assert await drive.read_parameter("Pr.1") == 120.0
        await drive.write_parameter(7, 2.5)
        assert params[7] == 25
        assert await drive.read_parameter(7) == 2.5
        assert await drive.read_parameter_raw(7) == 25
        await drive.write_parameter("Pr.3", 50.01)
        assert params[3] == 5001
        assert await drive.read_parameter(3) == 50.01
        await drive.write_parameter(122, 12.3)  # bank 1
        assert params[122] == 123
        assert await drive.read_parameter(122) == 12.3
        await drive.write_parameter(122, 9999)  # the special setting: no check
        assert params[122] == 9999
        assert await drive.read_parameter(122) == 9999
        assert await drive.read_parameter(123) == 9999  # the factory "9999"
        await drive.write_parameter(341, 2)  # bank 3
        assert await drive.read_parameter(341) == 2


@pytest.mark.parametrize("info", INFOS, ids=IDS)
async def test_every_parameter_reads_its_factory_value_in_units(info: Fr700ParameterInfo) -> None:
    async with traced_bus() as (bus, _sent):
        raw = simulator(bus).drives[0].parameters[info.number]
        assert await bus.drive(0).read_parameter(info.number) == info.from_raw(raw)


@pytest.mark.parametrize("info", INFOS, ids=IDS)
async def test_every_parameter_takes_its_range_ends(info: Fr700ParameterInfo) -> None:
    if info.number == 79:
        return  # the operation mode selection: Pr.79 = 7 would leave network operation
    async with traced_bus() as (bus, _sent):
        drive = bus.drive(0)
        for value in (info.maximum, info.minimum):
            await drive.write_parameter(info.number, value)
            assert await drive.read_parameter(info.number) == value


REFUSED: list[tuple[str, Callable[[Fr700Drive], Awaitable[object]], str | None]] = [
    ("out of range", lambda d: d.write_parameter(7, 3600.1), "must be within"),
    ("too fine", lambda d: d.write_parameter(7, 2.25), "steps of 0.1 s"),
    ("too fine Hz", lambda d: d.write_parameter(1, 59.995), "steps of 0.01 Hz"),
    ("bank 1 out of range", lambda d: d.write_parameter(122, 999.9), "must be within"),
    ("special collision", lambda d: d.write_parameter(19, 999.9), "special setting"),
    ("not a number", lambda d: d.write_parameter(7, math.nan), "needs a number"),
    ("unknown write", lambda d: d.write_parameter(44, 5.0), "write_parameter_raw"),
    ("unknown read", lambda d: d.read_parameter(44), "read_parameter_raw"),
    ("bad number", lambda d: d.read_parameter(1000), "0..999"),
    ("raw too big", lambda d: d.write_parameter_raw(7, 0x10000), None),
    ("raw negative", lambda d: d.write_parameter_raw(7, -1), None),
]


@pytest.mark.parametrize(("_what", "call", "match"), REFUSED, ids=[r[0] for r in REFUSED])
async def test_refusals_send_nothing(
    _what: str, call: Callable[[Fr700Drive], Awaitable[object]], match: str | None
) -> None:
    async with traced_bus() as (bus, sent):
        drive = bus.drive(1)
        before = dict(simulator(bus).drives[1].parameters)
        with pytest.raises(sj.LocalProtocolError, match=match) as info:
            await call(drive)
        assert isinstance(info.value, ValueError)
        assert sent == []  # not even the bank switch
        assert simulator(bus).drives[1].parameters == before
        assert bus.stats.transactions.requests == 0


async def test_the_raw_methods_reach_parameters_outside_the_catalogue() -> None:
    async with traced_bus() as (bus, sent):
        drive = bus.drive(1)
        with pytest.raises(sj.NakError) as info:
            await drive.read_parameter_raw(44)  # not simulated: the drive judges
        assert info.value.code is Fr700NakCode.INSTRUCTION_CODE
        assert sent  # it went out
        await drive.write_parameter_raw(7, 36000)
        assert await drive.read_parameter(7) == 3600.0


async def test_the_drive_judges_what_the_catalogue_allows() -> None:
    async with traced_bus() as (bus, _sent):
        drive = bus.drive(1)
        await drive.set_operation_mode(Fr700OperationMode.EXTERNAL)
        with pytest.raises(sj.NakError) as info:
            await drive.write_parameter(7, 1.0)  # a valid value, refused in external mode
        assert info.value.code is Fr700NakCode.MODE
