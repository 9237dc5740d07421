"""The controller judges every write once, whichever door it came by (gateway/_control.py).

The order: the configuration's grants, the value (a number, within 0..the
drive's maximum, on the 0.01 Hz step), then for all but a stop the drive
offline (refused unsent), then the lease. Each door only parses and words
the verdict (issue 42: NaN was ``malformed`` on two doors and
``BadOutOfRange`` on a third; 30.005 Hz without the lease was
``no_lease`` on one door and ``invalid_value`` on another).
"""

from __future__ import annotations

import asyncio
import math
import textwrap

import pytest
from waiting import wait_for

from sj300_async.gateway import (
    Gateway,
    GatewayDrive,
    Heartbeat,
    ParameterWrite,
    Refusal,
    RunCommand,
    SetFrequency,
)
from sj300_async.wire import Direction

from .conftest import drive_of, polled, running_gateway

CLIENT = "10.0.0.9"
TOML = textwrap.dedent(
    """
    [[lines]]
    name = "hall"
    url = "sim://?nodes=1-2"
    nodes = "1-2"
    interval_s = 0.05
    parameters = ["F001", "A004", "F002"]
    [[lines.writes]]
    nodes = "1-2"
    control = true
    parameters = ["F002"]
    """
)


def _sim_running(gateway: Gateway, node: int) -> bool:
    simulator = gateway.lines[0].bus.simulator
    assert simulator is not None
    return bool(simulator.drives[node].state(asyncio.get_running_loop().time()).outputting)


@pytest.mark.parametrize("hz", [math.nan, math.inf, -math.inf, -1.0, 30.005, 10.001, 1000.0, 1e308])
async def test_a_bad_frequency_is_an_invalid_value_before_the_lease_is_looked_at(
    hz: float,
) -> None:
    async with running_gateway(TOML) as gateway:
        await polled(gateway)
        drive = drive_of(gateway, "hall", 1)
        result = await gateway.write(CLIENT, drive, SetFrequency(hz))  # no lease taken
        assert result.refusal == Refusal.INVALID_VALUE, result
        assert (await gateway.write(CLIENT, drive, SetFrequency(30.01))).refusal == (
            Refusal.NO_LEASE
        )


async def _offline(gateway: Gateway, node: int) -> GatewayDrive:
    simulator = gateway.lines[0].bus.simulator
    assert simulator is not None
    simulator.faults.silence(node)
    drive = drive_of(gateway, "hall", node)
    await wait_for(lambda: not drive.snapshot.online, f"drive {node} offline", timeout=15)
    return drive


async def test_a_drive_held_offline_gets_no_run_frequency_or_parameter_but_a_stop() -> None:
    async with running_gateway(TOML) as gateway:
        await polled(gateway)
        drive = await _offline(gateway, 2)
        # The lease can be taken (a SCADA takes it before the drive is back).
        assert (await gateway.write(CLIENT, drive, Heartbeat())).ok
        refused = [
            await gateway.write(CLIENT, drive, request)
            for request in (
                RunCommand(Direction.FORWARD),
                SetFrequency(12.5),
                ParameterWrite("F002", 1000),
            )
        ]
        assert [r.refusal for r in refused] == [Refusal.NO_ANSWER] * 3
        assert all(r.detail == "the drive is offline: nothing was sent" for r in refused)
        # The stop is tried: it goes to the wire, where the silent drive does not answer.
        stop = await gateway.write(CLIENT, drive, RunCommand(Direction.STOP))
        assert stop.refusal == Refusal.NO_ANSWER
        assert "offline" not in stop.detail, stop
        assert not _sim_running(gateway, 2)
        offline = [e for e in gateway.audit.recent if e.get("detail") == refused[0].detail]
        assert len(offline) == 3  # each refusal audited, once
