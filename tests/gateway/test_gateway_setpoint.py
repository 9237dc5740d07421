"""The set frequency without configuration (issue 27): read beside the poll, on register 1003.

SCADA screens show the setpoint next to the output frequency. The gateway
reads it every ``setpoint_interval_s`` (SJ300: F001) unless the line polls it
as a parameter; a drive that refuses to give it is counted, not asked every
cycle, and stays online.
"""

from __future__ import annotations

import itertools
import textwrap

import pytest
from waiting import wait_for

from sj300_async.gateway import GatewayConfigError, parse_config

from .conftest import SimLine, drive_of, modbus_client, polled, running_gateway


def _toml(url: str, line_extra: str = "") -> str:
    return textwrap.dedent(
        f"""
        [modbus]
        listen = "127.0.0.1:0"
        [[lines]]
        name = "hall"
        url = "{url}"
        nodes = "1-4"
        interval_s = 0.05
        setpoint_interval_s = 0.2
        """
    ) + textwrap.dedent(line_extra)


async def test_register_1003_has_the_set_frequency_with_no_parameter_polled(
    sim_line: SimLine,
) -> None:
    sim_line.sim.drives[2].set_parameter("F001", 3725)  # 37.25 Hz
    async with running_gateway(_toml(sim_line.url)) as gateway:
        await polled(gateway)
        drive = drive_of(gateway, "hall", 2)
        await wait_for(lambda: drive.readings.set_frequency_hz == 37.25, "the setpoint read")
        assert drive.snapshot.set_frequency_hz == 37.25
        async with modbus_client(gateway) as scada:
            reply = await scada.read_holding_registers(1003, count=1, device_id=2)
            assert not reply.isError(), reply
            assert reply.registers == [3725]
        # Not polled as a parameter: read beside the poll, a few times in all.
        reads = [r for r in sim_line.log.requests() if r.node == 2 and r.data == b"F001"]
        assert 1 <= len(reads) <= 5, len(reads)


async def test_a_drive_refusing_its_setpoint_is_counted_and_not_asked_every_cycle(
    sim_line: SimLine,
) -> None:
    sim_line.sim.drives[3].withheld_parameters.add("F001")
    async with running_gateway(_toml(sim_line.url)) as gateway:
        await polled(gateway)
        drive = drive_of(gateway, "hall", 3)
        await wait_for(lambda: gateway.read_errors.get(("hall", "setpoint"), 0) >= 3, "3 refusals")
        assert drive.readings.online
        assert drive.readings.set_frequency_hz is None
        samples = {
            tuple(s.labels.values()): s.value
            for m in gateway.metrics()
            if m.name == "sj300_gateway_read_errors"
            for s in m.samples
        }
        assert samples[("hall", "setpoint")] >= 3
        # Asked again only setpoint_interval_s (0.2 s) after a refusal, not every cycle.
        asked = [
            when
            for when, direction, node, event in sim_line.log.frames()
            if direction == "rx" and node == 3 and getattr(event, "data", b"") == b"F001"
        ]
        gaps = [later - earlier for earlier, later in itertools.pairwise(asked)]
        assert gaps, asked
        assert min(gaps) >= 0.19, gaps


def test_setpoint_interval_s_is_checked_and_0_turns_the_reads_off() -> None:
    text = _toml("sim://?nodes=1-4")
    assert parse_config(text, "plant.toml").lines[0].setpoint_interval_s == 0.2
    assert parse_config(text.replace("0.2", "0"), "plant.toml").lines[0].setpoint_interval_s == 0
    with pytest.raises(GatewayConfigError) as caught:
        parse_config(text.replace("0.2", "-1"), "plant.toml")
    assert str(caught.value).startswith("plant.toml:9: lines[0].setpoint_interval_s: "), caught


async def test_the_setpoint_is_read_often_enough_never_to_go_stale(sim_line: SimLine) -> None:
    # setpoint_interval_s far past stale_after_s: read every stale_after_s / 2 all the same,
    # so register 1003 never answers 0x0B between two reads (a reviewer's 9600-baud line
    # of 8 drives: 11 of 294 samples stale with 5 s and 5 s).
    text = "[gateway]\nstale_after_s = 0.6\n" + _toml(sim_line.url).replace(
        "setpoint_interval_s = 0.2", "setpoint_interval_s = 3600"
    )
    async with running_gateway(text) as gateway:
        await polled(gateway)

        def reads() -> int:
            return sum(r.node == 2 and r.data == b"F001" for r in sim_line.log.requests())

        await wait_for(lambda: reads() >= 4, "four setpoint reads, each within 0.3 s of the last")
        assert drive_of(gateway, "hall", 2).readings.set_frequency_hz is not None


def test_the_default_setpoint_cadence_keeps_it_fresh() -> None:
    config = parse_config(_toml("sim://").replace("setpoint_interval_s = 0.2\n", ""), "p.toml")
    assert config.lines[0].setpoint_interval_s == 2.0
    assert config.lines[0].setpoint_interval_s <= config.stale_after_s / 2
