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
    WriteResult,
    parameter_request,
)
from sj300_async.gateway._parameter_values import raw_refusal
from sj300_async.profiles import get_profile
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


@pytest.mark.parametrize(
    ("value", "text", "sentence"),
    [
        (1e308, "1e308", "A004 (maximum frequency) must be within 30..400 Hz, got 1e+308"),
        (math.inf, "1e400", "1e400 is no value of A004"),
        (math.nan, "nan", "nan is no value of A004"),
        (60.01, "60.01", "A004 has a resolution of 0.1 Hz: 60.01 cannot be sent exactly"),
        (20.0, "20", "must be within 30..400 Hz"),
    ],
)
def test_a_parameter_value_is_never_rounded_to_what_the_drive_holds(
    value: float, text: str, sentence: str
) -> None:
    # The controller's judgement of a ParameterValue (MQTT, Sparkplug, OPC UA, the API's
    # value), in the catalogue's words.
    result = parameter_request(get_profile("sj300"), "A004", value, text)
    assert isinstance(result, WriteResult)
    assert result.refusal is Refusal.INVALID_VALUE
    assert sentence in str(result)
    assert parameter_request(get_profile("sj300"), "A004", 60.0, "60") == ParameterWrite(
        "A004", 600
    )


def test_a_raw_integer_is_refused_outside_the_range_but_a_special_setting_is_not() -> None:
    sj300, fr700 = get_profile("sj300"), get_profile("fr700")
    refused = raw_refusal(sj300, ParameterWrite("A004", 4010))  # 401 Hz
    assert refused is not None
    assert refused.refusal is Refusal.INVALID_VALUE
    assert "raw 4010" in str(refused)
    assert raw_refusal(sj300, ParameterWrite("A004", 600)) is None
    assert raw_refusal(fr700, ParameterWrite("Pr.122", 9999)) is None  # no communication check
    assert raw_refusal(fr700, ParameterWrite("Pr.122", 10000)) is not None
