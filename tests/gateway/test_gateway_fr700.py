"""An FR-700 line through the gateway: ``sim://?nodes=0-3&protocol=fr700``, pymodbus's client.

Station s is Modbus unit 100 + s; the identity block says protocol 2; the monitor
registers come from the FR-700 monitor (H6F, H70, H71) and register 202 holds its status
bits (H7A); a polled parameter sits at 30000 + 2 x number in its own increment; control
needs the lease and is confirmed by a read-back of the drive's own set frequency (H6D).
"""

from __future__ import annotations

import asyncio
import logging
import textwrap

import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.pdu import ModbusPDU
from waiting import wait_for

from sj300_async.fr700 import Fr700Monitor, Fr700StatusBits
from sj300_async.gateway import Gateway, GatewayConfigError, parse_config
from sj300_async.simulator import RunState
from sj300_async.simulator.fr700 import Fr700SimulatedBus

from .conftest import drive_of, modbus_client, polled, running_gateway

URL = "sim://?nodes=0-3&protocol=fr700"
CONFIG = textwrap.dedent(
    f"""
    [modbus]
    listen = "127.0.0.1:0"
    [[lines]]
    name = "press"
    url = "{URL}"
    nodes = "0-3"
    interval_s = 0.05
    parameters = ["Pr.7", "Pr.1"]
    [[lines.writes]]
    nodes = "1"
    parameters = ["Pr.7"]
    control = true
    """
)


def _code(response: ModbusPDU) -> int | None:
    return int(response.exception_code) if response.isError() else None


async def _read(client: AsyncModbusTcpClient, unit: int, address: int, count: int = 1) -> ModbusPDU:
    return await client.read_holding_registers(address, count=count, device_id=unit)


async def _ok(client: AsyncModbusTcpClient, unit: int, address: int, *values: int) -> None:
    if len(values) == 1:
        response = await client.write_register(address, values[0], device_id=unit)
    else:
        response = await client.write_registers(address, list(values), device_id=unit)
    assert not response.isError(), (unit, address, values, response)


def _simulator(gateway: Gateway) -> Fr700SimulatedBus:
    simulator = gateway.lines[0].bus.simulator
    assert isinstance(simulator, Fr700SimulatedBus)
    return simulator


async def test_fr700_stations_are_units_100_up_with_their_identity_and_data() -> None:
    async with running_gateway(CONFIG) as gateway:
        assert sorted(drive.unit for drive in gateway.drives) == [100, 101, 102, 103]
        await polled(gateway)
        async with modbus_client(gateway) as client:
            for station in range(4):
                ident = await _read(client, 100 + station, 0, 4)
                assert ident.registers == [1, 0, 2, station]  # online, fresh, FR-700, station
            for unit in (0, 1, 3, 104):  # an SJ300 line's units are not this line's
                assert _code(await _read(client, unit, 0)) == 0x0A
            assert (await _read(client, 102, 100, 4)).registers == [0, 0, 0, 0]  # stopped
            assert (await _read(client, 102, 200, 3)).registers == [0, 0, 0]
            assert (await _read(client, 102, 30014, 2)).registers == [0, 50]  # Pr.7 = 5.0 s
            assert (await _read(client, 102, 30002, 2)).registers == [0, 12000]  # Pr.1 120 Hz
            assert _code(await _read(client, 102, 204)) == 0x02  # SJ300's status C: none here
            assert _code(await _read(client, 102, 300)) == 0x02  # nor its trip count
            assert _code(await _read(client, 102, 30016, 2)) == 0x02  # Pr.8: not polled


async def test_fr700_fault_history_on_its_trip_registers_and_in_the_snapshot() -> None:
    text = CONFIG.replace("interval_s = 0.05", "interval_s = 0.05\ntrips_interval_s = 0.2")
    async with running_gateway(text) as gateway:
        await polled(gateway)
        drive = _simulator(gateway).drives[2]
        assert drive.trip(0x30, now=asyncio.get_running_loop().time())  # E.THT
        gateway_drive = drive_of(gateway, "press", 2)
        await wait_for(
            lambda: gateway_drive.snapshot.trip is not None, "the trip named from its history"
        )
        trip = gateway_drive.snapshot.trip
        assert trip is not None
        assert (trip.code, trip.meaning) == (
            "E.THT",
            "inverter overload trip (electronic thermal relay)",
        )
        async with modbus_client(gateway) as client:
            # 301: trips recorded; 302..309: their fault codes, newest first (0: empty).
            registers = (await _read(client, 102, 301, 9)).registers
            assert registers == [1, 0x30, 0, 0, 0, 0, 0, 0, 0]


async def test_fr700_control_with_the_lease_and_read_back(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="sj300_async.gateway.audit")
    async with running_gateway(CONFIG) as gateway:
        await polled(gateway)
        sim = _simulator(gateway)
        drive = sim.drives[1]
        state = drive_of(gateway, "press", 1).readings
        async with modbus_client(gateway) as client:
            # Not granted: station 2; without the lease: station 1's control registers.
            assert _code(await client.write_register(1000, 1, device_id=102)) == 0x01
            assert _code(await client.write_register(1003, 3000, device_id=101)) == 0x01
            await _ok(client, 101, 30014, 0, 0)  # Pr.7 = 0 s: a step to the set frequency
            assert drive.parameters[7] == 0
            assert (await _read(client, 101, 30014, 2)).registers == [0, 0]
            await _ok(client, 101, 1000, 1)  # the lease
            assert (await _read(client, 101, 1000, 2)).registers[0] == 1
            assert _code(await client.write_register(1003, 12001, device_id=101)) == 0x03  # > Pr.1
            audit = [r.getMessage() for r in caplog.records if r.name.endswith(".audit")]
            assert audit[-1].endswith(
                "120.01 Hz is outside 0..120 Hz (the drive's maximum frequency, Pr.1)"
            ), audit
            await _ok(client, 101, 1003, 3000)  # 30.00 Hz, read back from the drive (H6D)
            assert drive.set_frequency_hz == 30.0
            assert (await _read(client, 101, 1003)).registers == [3000]
            assert state.set_frequency_hz == 30.0
            await _ok(client, 101, 1002, 1)  # run forward
            loop = asyncio.get_running_loop()
            assert drive.state(loop.time()) is RunState.CONSTANT_SPEED

            def at_speed() -> bool:
                m = state.monitor
                return isinstance(m, Fr700Monitor) and m.output_frequency_hz == 30.0

            await wait_for(at_speed, "a poll of station 1 at 30 Hz")
            # 30 Hz of a 60 Hz base: 100.0 V; 9.60 A rated (Pr.9) x (0.3 + 0.7 x 30 %) = 4.9 A.
            assert (await _read(client, 101, 100, 4)).registers == [3000, 49, 1000, 1]
            running = Fr700StatusBits.RUN | Fr700StatusBits.FORWARD
            bits = running | Fr700StatusBits.SU | Fr700StatusBits.FU
            await wait_for(
                lambda: state.status_view is not None and state.status_view.running,
                "a status poll while running",
            )
            assert (await _read(client, 101, 200, 3)).registers == [1, 0, int(bits)]
            await _ok(client, 101, 1002, 0)  # stop
            assert drive.state(loop.time()) is RunState.DECELERATING  # Pr.8 = 5.0 s
            await _ok(client, 101, 1003, 0)
            assert drive.set_frequency_hz == 0.0


def test_broadcast_stop_is_refused_for_an_fr700_url() -> None:
    """The protocol named only by the URL (test_gateway_config names it with the key)."""
    text = CONFIG.replace("interval_s = 0.05", 'interval_s = 0.05\non_lapse = "broadcast_stop"')
    with pytest.raises(GatewayConfigError) as caught:
        parse_config(text, "gateway.toml")
    assert str(caught.value) == (
        "gateway.toml:9: lines[0].on_lapse: broadcast_stop needs a broadcast, which fr700 has not"
    )
