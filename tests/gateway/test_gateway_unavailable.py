"""A polled parameter the drive refuses: 0x0B on its registers, null on MQTT, the drive online.

The simulated drive withholds the parameter (NAK 16 to its reads, as a
firmware without it answers), while the gateway polls it.
"""

from __future__ import annotations

import json

from pymodbus.pdu import ModbusPDU
from waiting import wait_for

from sj300_async.gateway.mqtt import state_message

from .conftest import SimLine, drive_of, gateway_toml, modbus_client, polled, running_gateway


def _code(response: ModbusPDU) -> int | None:
    return int(response.exception_code) if response.isError() else None


async def test_a_refused_parameter_answers_0x0b_and_the_drive_stays_online(
    sim_line: SimLine,
) -> None:
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        drive = drive_of(gateway, "hall", 2)
        async with modbus_client(gateway) as client:
            f002 = await client.read_holding_registers(10004, count=2, device_id=2)
            assert f002.registers == [0, 3000]  # 30.00 s, read while the drive gave it

            sim_line.sim.drives[2].withheld_parameters.add("F002")
            await wait_for(
                lambda: "F002" in drive.snapshot.unavailable_parameters, "F002 unavailable"
            )
            f002 = await client.read_holding_registers(10004, count=2, device_id=2)
            assert _code(f002) == 0x0B  # no value: not the last one, not 0
            # Everything else of the drive keeps being served, and fresh.
            assert (await client.read_holding_registers(0, count=1, device_id=2)).registers == [1]
            for address, count in ((100, 4), (200, 2), (12008, 2), (10002, 2)):
                read = await client.read_holding_registers(address, count=count, device_id=2)
                assert not read.isError(), (address, read)
            monitor_at = drive.readings.monitor_at
            await wait_for(lambda: drive.readings.monitor_at > monitor_at, "a later monitor")
            assert drive.snapshot.online
            (line,) = gateway.lines
            assert line.poller.health(line.bus, 2).failures == 0

            state = state_message("gw", drive.served)
            parameters = json.loads(state.to_json())["parameters"]
            assert parameters == {"F001": 0.0, "A004": 50.0, "F002": None}

            sim_line.sim.drives[2].withheld_parameters.clear()
            await wait_for(lambda: "F002" in drive.snapshot.parameters, "F002 read again")
            assert drive.snapshot.unavailable_parameters == frozenset()
            f002 = await client.read_holding_registers(10004, count=2, device_id=2)
            assert f002.registers == [0, 3000]
