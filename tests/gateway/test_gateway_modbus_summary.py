"""Unit 255, a listener's summary: each drive's record side by side, seen by mbpoll and pymodbus.

A simulated line of four drives over TCP behind a running gateway: the
records must say what each drive's own unit says, a read must go on
answering for every drive while one of them is silent, and the summary
must refuse writes and reads past its last record.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from waiting import wait_for

from sj300_async.gateway import GatewayDrive, Lease, LineConfig
from sj300_async.gateway.modbus import (
    SUMMARY_RECORD,
    SUMMARY_SLOTS,
    SUMMARY_UNIT,
    Exc,
    Summary,
    SummaryBits,
    SummaryField,
)
from sj300_async.profiles import get_profile

from .conftest import SimLine, gateway_toml, modbus_client, modbus_port, polled, running_gateway
from .test_gateway_mbpoll import mbpoll

FRESH = SummaryBits.PRESENT | SummaryBits.ONLINE | SummaryBits.STATUS | SummaryBits.MONITOR


def _slot(words: list[int], unit: int) -> list[int]:
    """Unit *unit*'s record out of a read that began at register 0."""
    return words[SUMMARY_RECORD * unit : SUMMARY_RECORD * (unit + 1)]


async def test_mbpoll_reads_each_record_as_the_drive_s_own_unit_says(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        port = modbus_port(gateway)
        # The drives stand still: their values do not change between the reads.
        summary, ident, monitor, status = await asyncio.gather(
            mbpoll(port, SUMMARY_UNIT, 0, count=5 * SUMMARY_RECORD),
            mbpoll(port, 3, 0, count=4),
            mbpoll(port, 3, 100, count=4),
            mbpoll(port, 3, 200, count=2),
        )
        words = summary.values(0, 5 * SUMMARY_RECORD)
        assert words[:2] == [4, 4]  # the listener: four drives, four online
        record = _slot(words, 3)
        bits = SummaryBits(record[SummaryField.BITS])
        assert FRESH in bits
        assert (SummaryBits.RUNNING in bits) == bool(status.values(200, 1)[0])
        assert (SummaryBits.TRIPPED in bits) == bool(status.values(201, 1)[0])
        assert ident.values(0, 2) == [1, record[SummaryField.AGE_S]]
        assert record[SummaryField.OUTPUT_FREQUENCY : SummaryField.DIRECTION + 1] == (
            monitor.values(100, 4)
        )
        assert record[SummaryField.TRIP] == 0
        # Every drive's record is there, and nothing else.
        for unit in range(1, 5):
            assert FRESH in SummaryBits(_slot(words, unit)[0])


async def test_a_silent_drive_leaves_the_others_readable(sim_line: SimLine) -> None:
    async with (
        running_gateway(gateway_toml(sim_line.url)) as gateway,
        modbus_client(gateway) as client,
    ):
        await polled(gateway)
        sim_line.sim.faults.silence(2)
        await wait_for(lambda: not gateway.drives[1].snapshot.online, "drive 2 polled offline")
        answer = await client.read_holding_registers(0, count=40, device_id=SUMMARY_UNIT)
        assert not answer.isError(), answer
        words = list(answer.registers)
        assert words[:2] == [4, 3]
        gone = SummaryBits(_slot(words, 2)[0])
        assert SummaryBits.PRESENT in gone
        assert SummaryBits.ONLINE not in gone
        for unit in (1, 3, 4):
            assert FRESH in SummaryBits(_slot(words, unit)[0])
        # Its own unit still says why: register 0 (online) reads 0.
        own = await client.read_holding_registers(0, count=1, device_id=2)
        assert own.registers == [0]


async def test_the_summary_refuses_writes_and_reads_past_its_last_record(
    sim_line: SimLine,
) -> None:
    async with (
        running_gateway(gateway_toml(sim_line.url)) as gateway,
        modbus_client(gateway) as client,
    ):
        await polled(gateway)
        last = SUMMARY_RECORD * SUMMARY_SLOTS
        whole = await client.read_holding_registers(last - 125, count=125, device_id=SUMMARY_UNIT)
        assert whole.registers == [0] * 125  # unit ids with no drive: empty records
        past = await client.read_holding_registers(last - 1, count=2, device_id=SUMMARY_UNIT)
        assert past.isError()
        assert past.exception_code == Exc.ILLEGAL_ADDRESS
        write = await client.write_register(SUMMARY_RECORD + 2, 5000, device_id=SUMMARY_UNIT)
        assert write.isError()
        assert write.exception_code == Exc.ILLEGAL_FUNCTION
        other = await client.read_holding_registers(0, count=1, device_id=254)
        assert other.isError()
        assert other.exception_code == Exc.PATH_UNAVAILABLE
        port = modbus_port(gateway)
        (await mbpoll(port, SUMMARY_UNIT, 8, 1)).assert_refused("Illegal function")


# -- sans-IO: any read is the slice of the whole table ------------------------------------


def _drives() -> dict[int, GatewayDrive]:
    line = LineConfig("l", "sim://", "sj300", (1, 2, 3), unit_offset=0)
    profile = get_profile("sj300")
    return {unit: GatewayDrive(line, unit, profile, Lease(5.0)) for unit in (1, 2, 3)}


SUMMARY = Summary(_drives())
TABLE = SUMMARY.read(0, 125, 0.0, 5.0)


@settings(max_examples=300)
@given(st.integers(0, SUMMARY_RECORD * SUMMARY_SLOTS - 1), st.integers(1, 125))
def test_any_read_is_its_slice_of_the_table(address: int, count: int) -> None:
    end = SUMMARY_RECORD * SUMMARY_SLOTS
    got = SUMMARY.read(address, count, 0.0, 5.0)
    if address + count > end:
        assert got == Exc.ILLEGAL_ADDRESS
        return
    whole: list[int] = []
    for first in range(0, end, 125):
        part = SUMMARY.read(first, min(125, end - first), 0.0, 5.0)
        assert isinstance(part, list)
        whole += part
    assert got == whole[address : address + count]


def test_a_drive_never_read_is_present_and_nothing_else() -> None:
    assert isinstance(TABLE, list)
    assert TABLE[:2] == [3, 0]  # three drives, none online yet
    for unit in (1, 2, 3):
        assert _slot(TABLE, unit) == [int(SummaryBits.PRESENT), 65535, 0, 0, 0, 0, 0, 0]
    assert _slot(TABLE, 4) == [0] * SUMMARY_RECORD


@pytest.mark.parametrize(("value", "word"), [(655.36, 65535), (-1.0, 0), (float("nan"), 0)])
def test_values_saturate_and_unknown_reads_zero(value: float, word: int) -> None:
    drives = _drives()
    drive = drives[1]
    drive.snapshot = replace(drive.snapshot, monitor_at=0.0, output_frequency_hz=value)
    record = Summary(drives).read(SUMMARY_RECORD, SUMMARY_RECORD, 1.0, 5.0)
    assert isinstance(record, list)
    assert SummaryBits.MONITOR in SummaryBits(record[SummaryField.BITS])
    assert record[SummaryField.OUTPUT_FREQUENCY] == word
