"""Unit 255, a listener's summary: each drive's record side by side, seen by mbpoll and pymodbus.

A simulated line of four drives over TCP behind a running gateway: the
records must say what each drive's own unit says, a read must go on
answering for every drive while one of them is silent, and the summary
must refuse writes and reads past its last record.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from waiting import wait_for

from sj300_async.gateway import GatewayDrive, Lease, LineConfig, ServedDrive
from sj300_async.gateway.modbus import (
    SUMMARY_RECORD,
    SUMMARY_SLOTS,
    SUMMARY_UNIT,
    Exc,
    RegisterMap,
    Summary,
    SummaryBits,
    SummaryField,
)
from sj300_async.profiles import DriveSnapshot, Trip, get_profile
from sj300_async.wire import Direction

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

STALE_S = 5.0


def _serve(drive: GatewayDrive, snapshot: DriveSnapshot) -> ServedDrive:
    """*snapshot* as *drive*'s latest, served as the gateway serves it (stale after 5 s)."""
    drive.snapshot = snapshot
    drive.served = ServedDrive(snapshot, stale_after_s=STALE_S, lease=drive.lease)
    return drive.served


def _drives() -> dict[int, GatewayDrive]:
    line = LineConfig("l", "sim://", "sj300", (1, 2, 3), unit_offset=0)
    profile = get_profile("sj300")
    return {unit: GatewayDrive(line, unit, profile, Lease(5.0)) for unit in (1, 2, 3)}


SUMMARY = Summary(_drives())
TABLE = SUMMARY.read(0, 125, 0.0)


@settings(max_examples=300)
@given(st.integers(0, SUMMARY_RECORD * SUMMARY_SLOTS - 1), st.integers(1, 125))
def test_any_read_is_its_slice_of_the_table(address: int, count: int) -> None:
    end = SUMMARY_RECORD * SUMMARY_SLOTS
    got = SUMMARY.read(address, count, 0.0)
    if address + count > end:
        assert got == Exc.ILLEGAL_ADDRESS
        return
    whole: list[int] = []
    for first in range(0, end, 125):
        part = SUMMARY.read(first, min(125, end - first), 0.0)
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
    _serve(drive, replace(drive.snapshot, monitor_at=0.0, output_frequency_hz=value))
    record = Summary(drives).read(SUMMARY_RECORD, SUMMARY_RECORD, 1.0)
    assert isinstance(record, list)
    assert SummaryBits.MONITOR in SummaryBits(record[SummaryField.BITS])
    assert record[SummaryField.OUTPUT_FREQUENCY] == word


# -- each field against the drive's own unit (an oracle test written in review) -----------

SJ300 = get_profile("sj300")
UNIT_MAP = RegisterMap(SJ300)
AGES = st.sampled_from([0.0, 0.4, 1.7, 4.99, 5.0, 5.01, 80.0, math.inf])
VALUES = st.floats(0, 700, allow_nan=False)


@settings(max_examples=400)
@given(
    AGES, AGES, AGES, AGES, VALUES, VALUES, VALUES, VALUES,
    st.booleans(), st.booleans(), st.sampled_from(list(Direction)), st.booleans(),
)  # fmt: skip
def test_a_record_says_what_the_drive_s_own_unit_says(
    status_age: float,
    monitor_age: float,
    direction_age: float,
    set_age: float,
    frequency: float,
    current: float,
    voltage: float,
    set_frequency: float,
    running: bool,
    tripped: bool,
    direction: Direction,
    leased: bool,
) -> None:
    """Fresh or stale on either side of its served deadline, every value and bit of drive
    2's record is what its unit's registers say (0x0B there: the bit clear and 0 here), and
    both are what the drive as served says."""
    now = 100.0
    line = LineConfig("l", "sim://", "sj300", (1, 2), unit_offset=0)
    drive, other = (GatewayDrive(line, node, SJ300, Lease(5.0)) for node in (2, 1))
    if leased:
        drive.lease.holder, drive.lease.expires_at = "client", now + 1
    served = _serve(
        drive,
        replace(
            drive.snapshot,
            online=True,
            last_ok=now - min(status_age, 80.0),
            status_at=now - status_age,
            running=running,
            tripped=tripped,
            monitor_at=now - monitor_age,
            output_frequency_hz=frequency,
            output_current_a=current,
            output_voltage_v=voltage,
            direction=direction,
            direction_at=now - direction_age,
            set_frequency_hz=set_frequency,
            set_frequency_at=now - set_age,
            trip=Trip("E07", 7, None, "over-voltage") if tripped else None,
        ),
    )
    record = Summary({1: other, 2: drive}).read(2 * SUMMARY_RECORD, SUMMARY_RECORD, now)
    assert isinstance(record, list)
    bits = SummaryBits(record[SummaryField.BITS])

    def unit(address: int, count: int) -> list[int] | None:
        words = UNIT_MAP.read(served, address, count, now)
        return words if isinstance(words, list) else None

    status = unit(200, 2)
    assert (SummaryBits.STATUS in bits) == (status is not None) == served.fresh("status", now)
    if status is not None:
        assert status == [int(SummaryBits.RUNNING in bits), int(SummaryBits.TRIPPED in bits)]
        assert record[SummaryField.TRIP] == (7 if tripped else 0)
    else:
        assert not bits & (SummaryBits.RUNNING | SummaryBits.TRIPPED)
        assert record[SummaryField.TRIP] == 0
    monitor = unit(100, 3)
    assert (SummaryBits.MONITOR in bits) == (monitor is not None) == served.fresh("monitor", now)
    first, last = SummaryField.OUTPUT_FREQUENCY, SummaryField.OUTPUT_VOLTAGE
    assert record[first : last + 1] == (monitor or [0, 0, 0])
    turning = unit(103, 1)
    assert (
        (SummaryBits.DIRECTION in bits) == (turning is not None) == served.fresh("direction", now)
    )
    assert record[SummaryField.DIRECTION] == (turning or [0])[0]
    setpoint = unit(1003, 1)
    assert (
        (SummaryBits.SET_FREQUENCY in bits)
        == (setpoint is not None)
        == served.fresh("set_frequency", now)
    )
    assert record[SummaryField.SET_FREQUENCY] == (setpoint or [0])[0]
    assert [record[SummaryField.AGE_S]] == unit(1, 1)
    assert [int(SummaryBits.LEASED in bits)] == unit(1000, 1)
    assert (SummaryBits.LEASED in bits) == (served.lease_holder(now) is not None) == leased


def test_a_unit_id_the_summary_could_not_hold_is_refused() -> None:
    """255 would hide the summary; 248..254 have no record (parse_config refuses them too)."""
    drive = _drives()[1]
    for unit in (0, 248, 255):
        with pytest.raises(ValueError, match=f"outside 1..247: \\[{unit}\\]"):
            Summary({unit: drive})
