"""The gateway's Modbus TCP server, with pymodbus's client, against the simulator over TCP.

Every refusal with its exact exception code; reads from the poll cache;
writes through the same arbiter as the polls, confirmed by a read-back and
audited; the control lease; and the simulator's line log, which shows one
master: never a request before the previous one's answer.
"""

from __future__ import annotations

import asyncio
import logging
import math

import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.pdu import ModbusPDU
from waiting import wait_for

from sj300_async import sj300 as sj3

from .conftest import SimLine, drive_of, gateway_toml, modbus_client, polled, running_gateway

WRITES = """
    [[lines.writes]]
    nodes = "1-2"
    parameters = ["A004", "F002"]
    control = true
    """


def _code(response: ModbusPDU) -> int | None:
    """The exception code of *response*, None when it is not an exception."""
    return int(response.exception_code) if response.isError() else None


async def _read(client: AsyncModbusTcpClient, unit: int, address: int, count: int = 1) -> ModbusPDU:
    return await client.read_holding_registers(address, count=count, device_id=unit)


async def test_reads_come_from_the_poll_cache_in_documented_units(sim_line: SimLine) -> None:
    sim_line.sim.drives[3].set_parameter("F002", 1234)  # 12.34 s
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        requests_before = len(sim_line.log.requests())
        async with modbus_client(gateway) as client:
            ident = await _read(client, 3, 0, 4)
            assert ident.registers == [1, 0, 1, 3]  # online, fresh, SJ300, node 3
            f002 = await _read(client, 3, 10004, 2)  # F002 at 10000 + 2 * 2
            assert f002.registers == [0, 1234]
            a004 = await _read(client, 3, 12008, 2)
            assert a004.registers == [0, 500]  # 50.0 Hz counted in 0.1 Hz
            status = await _read(client, 3, 200, 5)
            assert status.registers[:2] == [0, 0]  # not running, not tripped
            monitor = await _read(client, 3, 100, 14)
            assert not monitor.isError()
            for _ in range(50):
                await _read(client, 3, 100, 4)
        # Fifty-odd Modbus reads added nothing to the line beyond the poll plan:
        # the polls in the meantime are all reads of the plan's shape.
        plan = {
            sj3.Command.READ_STATUS,
            sj3.Command.READ_MONITOR,
            sj3.Command.READ_PARAMETER,
            sj3.Command.READ_TRIP_HISTORY,
        }
        assert {r.command for r in sim_line.log.requests()[requests_before:]} <= plan


async def test_every_read_refusal_has_its_code(sim_line: SimLine) -> None:
    text = gateway_toml(sim_line.url, extra="[gateway]\nstale_after_s = 0.5\n")
    async with running_gateway(text) as gateway:
        await polled(gateway)
        async with modbus_client(gateway) as client:
            assert _code(await _read(client, 1, 5000)) == 0x02  # no such register
            assert _code(await _read(client, 1, 99, 2)) == 0x02  # one of them unknown
            assert _code(await _read(client, 1, 14004, 2)) == 0x02  # B002: not polled
            assert _code(await _read(client, 9, 0)) == 0x0A  # no drive behind unit 9
            coils = await client.read_coils(0, count=1, device_id=1)
            assert _code(coils) == 0x01
            sim_line.sim.faults.silence(2)
            state = drive_of(gateway, "hall", 2).readings
            loop = asyncio.get_running_loop()
            silenced_at = loop.time()
            await wait_for(lambda: loop.time() - state.monitor_at > 0.5, "node 2's data to age")
            assert _code(await _read(client, 2, 100)) == 0x0B  # stale
            assert _code(await _read(client, 2, 200)) == 0x0B
            # The identity block is always served: the SCADA can see why.
            await wait_for(lambda: not state.online, "node 2 offline")
            ident = await _read(client, 2, 0, 2)
            assert ident.registers[0] == 0
            assert ident.registers[1] >= math.floor(loop.time() - silenced_at) - 1
            assert not (await _read(client, 1, 100)).isError()  # the others are fresh


async def test_a_read_only_line_refuses_every_write(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        async with modbus_client(gateway) as client:
            assert _code(await client.write_registers(12008, [0, 600], device_id=1)) == 0x01
            assert _code(await client.write_register(1000, 1, device_id=1)) == 0x01
            assert _code(await client.write_register(1002, 1, device_id=1)) == 0x01
            assert _code(await client.write_register(100, 1, device_id=1)) == 0x01  # read-only
            assert _code(await client.write_register(5000, 1, device_id=1)) == 0x02
    assert sim_line.sim.drives[1].parameters["A004"] == 500
    assert not any(r.command in sj3.MUTATING_COMMANDS for r in sim_line.log.requests())


async def test_parameter_writes_follow_the_allow_list(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="sj300_async.gateway.audit")
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        async with modbus_client(gateway) as client:
            ok = await client.write_registers(12008, [0, 600], device_id=1)  # A004 = 60.0 Hz
            assert not ok.isError()
            assert sim_line.sim.drives[1].parameters["A004"] == 600
            assert (await _read(client, 1, 12008, 2)).registers == [0, 600]  # read back
            assert _code(await client.write_registers(12008, [0, 600], device_id=3)) == 0x01
            assert _code(await client.write_registers(10002, [0, 100], device_id=1)) == 0x01
            assert _code(await client.write_register(12009, 600, device_id=1)) == 0x03  # half
            assert _code(await client.write_registers(12008, [0, 9999], device_id=1)) == 0x03
    assert sim_line.sim.drives[1].parameters["A004"] == 600
    audit = [r.getMessage() for r in caplog.records if r.name == "sj300_async.gateway.audit"]
    assert "client 127.0.0.1 line hall node 1 (unit 1): parameter A004 50.0 -> 60.0: ok" in audit
    assert any("node 3" in line and "refused: not_allowed: " in line for line in audit)
    assert any("999.9: refused: invalid_value: " in line for line in audit)
    # What the Modbus server refuses itself (half a value) is audited too, neutrally.
    half = [line for line in audit if "register 12009" in line]
    assert len(half) == 1, audit
    assert "[600]: refused: malformed: a write covers one value whole" in half[0]


async def test_control_needs_the_lease_and_one_holder(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        async with modbus_client(gateway) as scada, modbus_client(gateway, "127.0.0.2") as hmi:
            assert _code(await scada.write_register(1002, 1, device_id=1)) == 0x01  # no lease
            assert _code(await scada.write_register(1003, 2500, device_id=1)) == 0x01
            assert not (await scada.write_register(1000, 1, device_id=1)).isError()
            assert _code(await hmi.write_register(1000, 1, device_id=1)) == 0x06  # busy
            assert _code(await hmi.write_register(1002, 1, device_id=1)) == 0x06
            assert _code(await scada.write_register(1002, 7, device_id=1)) == 0x03
            assert _code(await scada.write_register(1003, 50000, device_id=1)) == 0x03  # 500 Hz
            assert _code(await scada.write_register(1003, 5001, device_id=1)) == 0x03  # > A004
            assert not (await scada.write_register(1003, 2500, device_id=1)).isError()
            assert not (await scada.write_register(1002, 1, device_id=1)).isError()
            drive = sim_line.sim.drives[1]
            assert drive.parameters["F001"] == 2500
            assert (await _read(scada, 1, 1003)).registers == [2500]
            assert (await _read(scada, 1, 1000, 2)).registers[0] == 1
            assert not (await scada.write_register(1002, 0, device_id=1)).isError()
            # Unit 3 is not granted control: even its heartbeat is refused.
            assert _code(await scada.write_register(1000, 1, device_id=3)) == 0x01
    assert sim_line.log.interleaved() == []
