"""The typed FR-700 Drive API against the in-memory simulator (``sim://?protocol=fr700``)."""

from __future__ import annotations

import asyncio
from contextlib import AbstractAsyncContextManager

import pytest
from waiting import wait_for

import sj300_async as sj
import sj300_async.bus as sjbus
from sj300_async.fr700 import (
    Fr700Drive,
    Fr700Monitor,
    Fr700MultiReceive,
    Fr700NakCode,
    Fr700OperationMode,
    Fr700StatusBits,
)
from sj300_async.fr700._drive import BANK_TRUST_S
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.simulator.sj300 import SimulatedBus

URL = "sim://?protocol=fr700&nodes=0-3"


def fr700_bus(
    url: str = URL,
    *,
    timeout: float | None = None,
    retries: int = 2,
    read_only: bool = False,
) -> AbstractAsyncContextManager[sj.Bus[Fr700Drive, None]]:
    return sj.open_bus(url, protocol="fr700", timeout=timeout, retries=retries, read_only=read_only)


async def quick_ramps(drive: Fr700Drive) -> None:
    await drive.write_parameter_raw(7, 0)  # 0 s: the output steps to the set frequency
    await drive.write_parameter_raw(8, 0)


async def test_bus_hands_out_fr700_drives_on_stations_0_to_31() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(0)
        assert isinstance(drive, Fr700Drive)
        assert bus.drive(0) is drive
        assert (drive.station, drive.node) == (0, 0)
        assert bus.drive(31).station == 31
        with pytest.raises(sj.LocalProtocolError, match=r"0\.\.31"):
            bus.drive(32)
        with pytest.raises(sj.LocalProtocolError, match="broadcast"):
            _ = bus.broadcast
        assert bus.dialect.name == "fr700"
        assert isinstance(bus.simulator, Fr700SimulatedBus)
        assert repr(drive) == "<Fr700Drive 00 on sim://(stations 0-3)>"


async def test_url_alone_selects_the_protocol_of_the_neutral_open_bus() -> None:
    # sj300_async.bus.open_bus is typed Bus[Any, Any]: the URL may name the protocol alone.
    async with sjbus.open_bus("sim://?protocol=fr700&nodes=5") as bus:
        drive = bus.drive(5)
        assert isinstance(drive, Fr700Drive)
        assert not (await drive.read_status()).running


async def test_run_ramp_status_and_monitors() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        await quick_ramps(drive)
        await drive.set_frequency(50.0)
        assert await drive.read_set_frequency() == 50.0
        await drive.run_forward()
        status = await drive.read_status()
        assert status.running
        assert status.forward
        assert status.up_to_frequency
        assert not status.extended
        assert not status.tripped
        monitor = await drive.read_monitor()
        assert isinstance(monitor, Fr700Monitor)
        assert monitor.output_frequency_hz == 50.0
        assert monitor.output_current_a > 0
        assert monitor.output_voltage_v > 0
        assert await drive.read_output_frequency() == 50.0
        await drive.run_reverse()
        assert (await drive.read_extended_status()).reverse
        await drive.stop()
        status = await drive.read_status()
        assert not status.running
        assert status.bits == Fr700StatusBits(0)


async def test_the_ramp_takes_time() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        await drive.write_parameter_raw(7, 5)  # 0.5 s from 0 to 60 Hz (Pr.20)
        await drive.set_frequency(60.0)
        await drive.run_forward()
        first = await drive.read_output_frequency()
        assert 0 <= first < 60
        assert not (await drive.read_status()).up_to_frequency
        await asyncio.sleep(0.6)
        assert await drive.read_output_frequency() == 60.0


async def test_ram_and_eeprom_frequency() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(2)
        await drive.set_frequency(30.0)
        assert (await drive.read_set_frequency(), await drive.read_set_frequency(eeprom=True)) == (
            30.0,
            0.0,
        )
        await drive.set_frequency(40.0, eeprom=True)
        assert await drive.read_set_frequency(eeprom=True) == 40.0
        await drive.set_frequency(10.0)
        await drive.reset()  # RAM reloads from EEPROM
        assert await drive.read_set_frequency() == 40.0


async def test_frequency_above_maximum_is_nak_c() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(0)
        with pytest.raises(sj.NakError) as info:
            await drive.set_frequency(120.01)  # Pr.1 = 120 Hz
        assert (info.value.node, info.value.code) == (0, Fr700NakCode.DATA_RANGE)
        assert bus.stats.transactions.retries == 0  # the drive's verdict: not retried
        await drive.write_parameter_raw(1, 6000)
        with pytest.raises(sj.NakError):
            await drive.set_frequency(60.01)


async def test_operation_mode_and_mode_errors() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(3)
        assert await drive.read_operation_mode() is Fr700OperationMode.NETWORK
        await drive.set_operation_mode(Fr700OperationMode.EXTERNAL)
        assert await drive.read_operation_mode() is Fr700OperationMode.EXTERNAL
        for write in (drive.run_forward(), drive.set_frequency(5), drive.write_parameter_raw(7, 1)):
            with pytest.raises(sj.NakError) as info:
                await write
            assert info.value.code is Fr700NakCode.MODE
        await drive.set_operation_mode(Fr700OperationMode.NETWORK)
        await quick_ramps(drive)
        await drive.set_frequency(5)
        await drive.run_forward()
        with pytest.raises(sj.NakError) as info:
            await drive.set_operation_mode(Fr700OperationMode.PU)  # not while running
        assert info.value.code is Fr700NakCode.MODE


async def test_factory_defaults_start_in_external_mode() -> None:
    async with fr700_bus("sim://?protocol=fr700&nodes=0&factory_defaults=1") as bus:
        assert await bus.drive(0).read_operation_mode() is Fr700OperationMode.EXTERNAL


async def test_parameters_through_the_link_extension() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        await drive.write_parameter_raw(7, 123)
        await drive.write_parameter_raw(123, 0)  # bank 1
        await drive.write_parameter_raw("Pr.340", 1)  # bank 3
        assert await drive.read_parameter_raw(7) == 123
        assert await drive.read_parameter_raw(123) == 0
        assert await drive.read_parameter_raw("pr.340") == 1
        assert sim.drives[1].parameters[7] == 123
        assert sim.drives[1].parameters[123] == 0
        with pytest.raises(sj.NakError) as info:
            await drive.read_parameter_raw(555)  # no such parameter
        assert info.value.code is Fr700NakCode.INSTRUCTION_CODE
        with pytest.raises(sj.NakError) as info:
            await drive.write_parameter_raw(7, 40000)
        assert info.value.code is Fr700NakCode.DATA_RANGE


async def test_the_bank_is_written_only_when_it_changes() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        sent: list[bytes] = []
        bus.trace = lambda record: sent.append(record.data) if record.direction == "tx" else None
        await drive.read_parameter_raw(7)
        await drive.read_parameter_raw(8)
        await drive.read_parameter_raw(117)
        await drive.read_parameter_raw(118)
        codes = [frame[3:5] for frame in sent]
        assert codes == [b"FF", b"07", b"08", b"FF", b"11", b"12"]


async def test_a_refusal_keeps_the_bank_and_another_error_forgets_it() -> None:
    async with fr700_bus(timeout=0.05, retries=0) as bus:
        drive = bus.drive(1)
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        sent: list[bytes] = []
        bus.trace = lambda record: sent.append(record.data) if record.direction == "tx" else None
        for number in (23, 24, 25):  # none of them on the simulated drive: NAK B each
            with pytest.raises(sj.NakError):
                await drive.read_parameter_raw(number)
        with pytest.raises(sj.NakError):
            await drive.write_parameter_raw(7, 40000)  # NAK C
        assert await drive.read_parameter_raw(7) == 50
        # A write writes its bank first, whatever was written before.
        assert [frame[3:5] for frame in sent] == [b"FF", b"17", b"18", b"19", b"FF", b"87", b"07"]
        sent.clear()
        sim.faults.drop_next(1)  # a time-out may hide a restart: the bank is unknown
        with pytest.raises(sj.ReplyTimeoutError):
            await drive.read_parameter_raw(8)
        assert await drive.read_parameter_raw(8) == 50
        codes = [frame[3:5] for frame in sent]
        assert codes[0] == b"08"
        assert codes[-2:] == [b"FF", b"08"]  # written again


async def test_concurrent_parameter_reads_never_mix_banks() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(2)
        await drive.write_parameter_raw(7, 77)
        await drive.write_parameter_raw(117, 2)

        async def read(number: int) -> list[int]:
            return [await drive.read_parameter_raw(number) for _ in range(10)]

        low, high = await asyncio.gather(read(7), read(117))
        assert low == [77] * 10
        assert high == [2] * 10


async def test_an_inverter_reset_is_not_answered_and_forgets_the_bank() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(0)
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        await drive.read_parameter_raw(117)  # bank 1
        sim.drives[0].trip(now=asyncio.get_running_loop().time())
        assert (await drive.read_status()).tripped
        await drive.reset()
        assert bus.stats.transactions.timeouts == 0
        assert not (await drive.read_status()).tripped
        assert sim.drives[0].parameter_bank == 0
        assert await drive.read_parameter_raw(118) == 192  # the bank is written again


async def test_multi_command() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        await quick_ramps(drive)
        reply = await drive.multi_command(sj.Direction.FORWARD, 25.0)
        assert reply.ok
        assert reply.status.running
        assert reply.status.extended
        assert reply.value == 25.0
        reply = await drive.multi_command(
            sj.Direction.FORWARD, 25.0, receive=Fr700MultiReceive.OUTPUT_VOLTAGE
        )
        assert reply.receive_type is Fr700MultiReceive.OUTPUT_VOLTAGE
        assert reply.value == (await drive.read_monitor()).output_voltage_v
        # a range error of the frequency half is reported, the run half is done
        reply = await drive.multi_command(sj.Direction.REVERSE, 300.0)
        assert reply.frequency_error is Fr700NakCode.DATA_RANGE
        assert reply.run_error is Fr700NakCode.NO_ERROR
        assert not reply.ok
        assert (await drive.read_status()).reverse


async def test_raw_read_and_write() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        await drive.write(0xED, 0x1388)
        assert await drive.read(0x6D) == 0x1388
        assert await drive.read("H6D") == 0x1388
        assert await drive.read_data(0x7A) == b"00"
        await drive.write("HF3", 2)  # special monitor: current
        assert await drive.read(0x73) == 2
        with pytest.raises(sj.NakError) as info:
            await drive.read(0x78)
        assert info.value.code is Fr700NakCode.INSTRUCTION_CODE
        with pytest.raises(sj.LocalProtocolError):
            await drive.read(0xED)
        with pytest.raises(sj.LocalProtocolError):
            await drive.write(0x6D, 1)


async def test_fault_history() -> None:
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        now = asyncio.get_running_loop().time()
        sim.drives[1].trip(0x10, now=now)
        await drive.reset()
        await drive.read_status()  # the reset has no reply: a round trip shows it is done
        sim.drives[1].trip(0x90, now=now)
        assert await drive.read(0x74) == 0x1090  # latest in the low byte
        await drive.reset()
        await drive.write(0xF4, 0x9696)
        assert await drive.read(0x74) == 0


async def test_read_only_bus_reads_parameters_but_refuses_writes() -> None:
    async with fr700_bus(read_only=True) as bus:
        drive = bus.drive(1)
        assert await drive.read_parameter_raw(118) == 192  # the bank switch is allowed
        for write in (
            drive.write_parameter_raw(7, 1),
            drive.set_frequency(1),
            drive.run_forward(),
            drive.reset(),
            drive.write(0xFB, 0),
            drive.multi_command(0, 0),
        ):
            with pytest.raises(sj.ReadOnlyError):
                await write


async def test_absent_station_times_out() -> None:
    async with fr700_bus(timeout=0.05, retries=1) as bus:
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(9).read_status()
        assert bus.drive(9).stats.timeouts == 2


async def test_protocol_mismatch_is_refused() -> None:
    with pytest.raises(sj.LocalProtocolError, match="URL says"):
        async with sjbus.open_bus("sim://?protocol=fr700", protocol="sj300"):
            pass
    with pytest.raises(sj.LocalProtocolError, match="pass protocol='fr700'"):
        async with sj.open_bus("sim://?protocol=fr700", protocol="sj300"):
            pass
    with pytest.raises(sj.LocalProtocolError, match="options of protocol fr700"):
        async with sj.open_bus("sim://?terminator=cr"):
            pass
    with pytest.raises(sj.LocalProtocolError, match="does not speak"):
        async with sj.open_bus("sim://?protocol=fr700", protocol="fr700", simulator=SimulatedBus()):
            pass


@pytest.mark.parametrize(
    "query",
    [
        "terminator=none",
        "terminator=crlf",
        "wait_field=0",
        "ack=1",
        "terminator=none&wait_field=0&ack=1",
    ],
)
async def test_every_line_option_works_end_to_end(query: str) -> None:
    async with fr700_bus(f"sim://?protocol=fr700&nodes=0-1&{query}") as bus:
        drive = bus.drive(1)
        await quick_ramps(drive)
        await drive.set_frequency(12.34)
        await drive.run_forward()
        assert await drive.read_output_frequency() == 12.34
        assert await drive.read_parameter_raw(123) == (0 if "wait_field=0" in query else 9999)
        assert bus.stats.transactions.timeouts == 0
        assert bus.stats.bad_frames == 0
        await drive.read_status()
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        # every data reply but the last is acknowledged by now (the last one's
        # ACK may still be on its way)
        assert sim.stats.host_acks >= (2 if "ack=1" in query else 0)
        assert sim.stats.host_acks <= (3 if "ack=1" in query else 0)


async def test_a_restart_hidden_by_a_retry_never_writes_the_hundred_below() -> None:
    # The drive restarts (bank 0) and the host sees no error; a write's first attempt
    # then goes unanswered and its retry is answered. Trusting the bank last written,
    # that retry changed Pr.20 for "Pr.120" (a review set Pr.8 to 60 s writing "Pr.108").
    async with fr700_bus(timeout=0.05, retries=3) as bus:
        drive = bus.drive(1)
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        simulated = sim.drives[1]
        assert await drive.read_parameter_raw(118) == simulated.parameters[118]  # bank 1
        before = dict(simulated.parameters)
        simulated.power_cycle(asyncio.get_running_loop().time())  # bank 0, unseen
        sim.faults.silence(1)
        writing = asyncio.create_task(drive.write_parameter_raw(120, 1))
        await wait_for(lambda: drive.stats.timeouts >= 1, "an attempt unanswered")
        sim.faults.silence(1, False)
        await writing
        assert simulated.parameter_bank == 1
        assert simulated.parameters[120] == 1
        assert {n: v for n, v in simulated.parameters.items() if n != 120} == {
            n: v for n, v in before.items() if n != 120
        }


async def test_a_read_after_a_pause_writes_its_bank_again() -> None:
    # A restart in a pause with no request in flight shows nowhere: a read more than
    # BANK_TRUST_S after the drive's last answer writes its bank first.
    async with fr700_bus() as bus:
        drive = bus.drive(1)
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        simulated = sim.drives[1]
        sent: list[bytes] = []
        bus.trace = lambda record: sent.append(record.data) if record.direction == "tx" else None
        await drive.read_parameter_raw(118)
        loop = asyncio.get_running_loop()
        simulated.power_cycle(loop.time())  # back in bank 0
        paused_until = loop.time() + BANK_TRUST_S * 1.5
        await wait_for(lambda: loop.time() >= paused_until, "a pause past BANK_TRUST_S")
        assert await drive.read_parameter_raw(119) == simulated.parameters[119]
        assert [frame[3:5] for frame in sent] == [b"FF", b"12", b"FF", b"13"]
