"""The pieces behind the output: JSON conversion, plain tables, units; and the demo driver."""

from __future__ import annotations

import asyncio
import math
from types import MappingProxyType

import pytest

import sj300_async as sj
from sj300_async import InverterStatus, StatusA, StatusB, StatusC, TripStatusB
from sj300_async import sj300 as sj3
from sj300_async.cli._demo import run_demo
from sj300_async.cli._output import Column, format_raw, human, jsonable, plain_lines
from sj300_async.simulator import RunState


def test_jsonable_names_enums_and_keeps_flags_as_numbers() -> None:
    status = InverterStatus(StatusA.RUNNING, StatusB.RUNNING, StatusC(42))
    assert jsonable(status) == {"a": "RUNNING", "b": "RUNNING", "c": "UNKNOWN_42"}
    flags = TripStatusB.THERMAL | TripStatusB.OVER_VOLTAGE
    assert jsonable({"b": flags, "t": (1.5, math.nan)}) == {"b": 24, "t": [1.5, None]}
    assert jsonable(MappingProxyType({"F001": 50.0})) == {"F001": 50.0}


def test_human_names() -> None:
    assert human(StatusC.CONSTANT_SPEED) == "constant speed"
    assert human(TripStatusB.THERMAL | TripStatusB.OVER_VOLTAGE) == "OVER_VOLTAGE|THERMAL"
    assert human(TripStatusB(0)) == "-"


def test_format_raw_uses_the_resolution_and_unit() -> None:
    assert format_raw(sj3.parameter_info("F002"), 3000) == "30.00 s"
    assert format_raw(sj3.parameter_info("A004"), 600) == "60.0 Hz"
    assert format_raw(sj3.parameter_info("C078"), 40) == "40 ms"
    assert format_raw(sj3.parameter_info("A001"), 3) == "3"
    assert format_raw(sj3.parameter_info("P123"), 15) == "1.5"  # unknown: x 10


def test_plain_lines_align_columns() -> None:
    lines = plain_lines(
        (Column("code"), Column("value", "right")), [("F002", "30.00 s"), ("C078", "0 ms")]
    )
    assert lines == ["code    value", "F002  30.00 s", "C078     0 ms"]
    assert plain_lines((Column("a"),), [("x",)], show_header=False) == ["x"]


async def test_demo_runs_reverses_trips_and_resets() -> None:
    async with sj.open_bus("sim://?nodes=1-8") as bus:
        sim = bus.simulator
        assert sim is not None
        loop = asyncio.get_running_loop()
        task = asyncio.create_task(
            run_demo(bus, trip_every_s=0.3, tripped_s=0.2, tick_s=0.02, seed=7)
        )
        states: dict[int, set[RunState]] = {n: set() for n in sim.drives}
        directions: set[sj.Direction] = set()
        try:
            for _ in range(60):
                await asyncio.sleep(0.025)
                for node, drive in sim.drives.items():
                    states[node].add(drive.state(loop.time()))
                    directions.add(drive.monitor(loop.time()).direction)
        finally:
            task.cancel()
            await asyncio.wait([task])
        tripped = [n for n, seen in states.items() if RunState.TRIPPED in seen]
        assert tripped, states
        assert sum(d.trip_history().total_count for d in sim.drives.values()) >= 2
        # A tripped drive is reset and started again.
        assert any(RunState.ACCELERATING in states[n] for n in tripped)
        assert not all(d.tripped for d in sim.drives.values())
        assert {sj.Direction.FORWARD, sj.Direction.REVERSE} <= directions
        assert len({d.parameters["F002"] for d in sim.drives.values()}) > 1  # varied ramps


async def test_demo_needs_a_simulator() -> None:
    async with sj.open_bus("sim://") as bus:
        bus.simulator = None
        with pytest.raises(sj.LocalProtocolError):
            await run_demo(bus)
